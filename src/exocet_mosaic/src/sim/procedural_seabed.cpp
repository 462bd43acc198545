#include "exocet_mosaic/sim/procedural_seabed.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <list>
#include <mutex>
#include <sstream>
#include <stdexcept>
#include <unordered_map>
#include <utility>

#include <opencv2/core/utility.hpp>

#include "exocet_mosaic/sim/random.h"

// Bit-identical texels between the tile path and albedoTexel() need the same machine code for the float
// arithmetic (an inlined copy may contract a*b+c into an FMA differently): the per-texel functions stay out of line.
#if defined(__GNUC__)
#define EXOCET_NOINLINE __attribute__((noinline))
#else
#define EXOCET_NOINLINE
#endif

namespace exocet_mosaic {
namespace sim {
namespace {

constexpr double kTwoPi = 6.283185307179586476925;
constexpr double kDegToRad = 0.017453292519943295769;
constexpr int kGrainOctaves = 8;       // lattice 2, 4, ... 256 base texels (4 mm .. 0.5 m by default)
constexpr float kPerlinSd = 0.2155f;   // standard deviation of gradientNoise() (measured)
constexpr float kBsplineSd = 0.2768f;  // of bsplineNoise() with uniform lattice values: sqrt(1/3) * 151/315
constexpr double kShellCell_m = 0.25;
constexpr double kShellMinLength_m = 0.005;
constexpr double kShellMaxLength_m = 0.03;
constexpr double kBurrowMinLength_m = 0.004;
constexpr double kBurrowMaxLength_m = 0.015;
// Grain octave amplitudes, finest first: sand is grainier than it is cloudy.
constexpr float kOctaveAmplitude[8] = {1.3f, 1.2f, 1.05f, 0.9f, 0.75f, 0.6f, 0.5f, 0.45f};
constexpr double kRimStrength = 0.6;             // albedo loss at a rock's foot (ambient occlusion)
constexpr double kRockProfileSlope = 1.5;        // max |P'| of the dome profile P(rho) = 1 - 3 rho^2 + 2 rho^3
constexpr double kRockProfileCurv = 6.0;         // max |P''| and |P'/rho| of that profile
constexpr double kReliefInterpError_m = 0.0016;  // bilinear error budget of a rock dome on the relief grid
constexpr double kRippleProfileNorm = 1.1006;    // max of sin(p) + 0.25 sin(2p)
constexpr double kRippleProfileSlope = 1.5 / kRippleProfileNorm;
constexpr size_t kMaxPatchTexels = size_t(1) << 26;
constexpr size_t kTileOverheadBytes = 256;  // Mat header, shared_ptr, list and map nodes

// Field identifiers: each is hashed with the seed so that every noise field has its own lattice.
enum FieldId : uint64_t {
  kGrainField = 1,
  kGrainRotation,
  kSandMudField,
  kShellySandField,
  kLuminanceField,
  kRippleMaskField,
  kRippleMaskField2,
  kWarpField,
  kWarpField2,
  kMoundField,
  kMoundField2,
  kRockClusterField,
  kRockCells,
  kShellCells,
  kBurrowCells,
};

const float kGradients[16][2] = {
    {0.980785280f, 0.195090322f},   {0.831469612f, 0.555570233f},   {0.555570233f, 0.831469612f},
    {0.195090322f, 0.980785280f},   {-0.195090322f, 0.980785280f},  {-0.555570233f, 0.831469612f},
    {-0.831469612f, 0.555570233f},  {-0.980785280f, 0.195090322f},  {-0.980785280f, -0.195090322f},
    {-0.831469612f, -0.555570233f}, {-0.555570233f, -0.831469612f}, {-0.195090322f, -0.980785280f},
    {0.195090322f, -0.980785280f},  {0.555570233f, -0.831469612f},  {0.831469612f, -0.555570233f},
    {0.980785280f, -0.195090322f}};

inline int64_t floorDiv(int64_t a, int64_t b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

inline uint64_t latticeHash(int64_t ix, int64_t iy, uint64_t key) {
  return mix64(key + static_cast<uint64_t>(ix) * 0x9E3779B97F4A7C15ULL +
               static_cast<uint64_t>(iy) * 0xC2B2AE3D27D4EB4FULL);
}

inline float fade(float t) { return t * t * t * (t * (t * 6.f - 15.f) + 10.f); }

/// 2D gradient (Perlin) noise in lattice units; mean 0, sd kPerlinSd, |n| < 0.71.
inline float gradientNoise(double x, double y, uint64_t key) {
  const double fx = std::floor(x), fy = std::floor(y);
  const int64_t ix = static_cast<int64_t>(fx), iy = static_cast<int64_t>(fy);
  const float u = static_cast<float>(x - fx), v = static_cast<float>(y - fy);
  const float* g00 = kGradients[latticeHash(ix, iy, key) >> 60];
  const float* g10 = kGradients[latticeHash(ix + 1, iy, key) >> 60];
  const float* g01 = kGradients[latticeHash(ix, iy + 1, key) >> 60];
  const float* g11 = kGradients[latticeHash(ix + 1, iy + 1, key) >> 60];
  const float n00 = g00[0] * u + g00[1] * v;
  const float n10 = g10[0] * (u - 1.f) + g10[1] * v;
  const float n01 = g01[0] * u + g01[1] * (v - 1.f);
  const float n11 = g11[0] * (u - 1.f) + g11[1] * (v - 1.f);
  const float su = fade(u), sv = fade(v);
  const float a = n00 + su * (n10 - n00);
  const float b = n01 + su * (n11 - n01);
  return a + sv * (b - a);
}

inline void bsplineWeights(float t, float w[4]) {
  const float s = 1.f - t, t2 = t * t, t3 = t2 * t;
  w[0] = s * s * s * (1.f / 6.f);
  w[1] = (3.f * t3 - 6.f * t2 + 4.f) * (1.f / 6.f);
  w[2] = (-3.f * t3 + 3.f * t2 + 3.f * t + 1.f) * (1.f / 6.f);
  w[3] = t3 * (1.f / 6.f);
}

/**
 * Cubic B-spline value noise in lattice units, lattice values in [-1, 1] (or exactly +-1 if `binary`). Unlike
 * gradient noise it has simple exact bounds, which the relief needs: |n| <= 1 and |dn/dx|, |dn/dy| <= 1.5
 * (sum over i of |B'(t - i)| peaks at 1.5, and the weights of the other axis sum to 1).
 */
inline float bsplineNoise(double x, double y, uint64_t key, bool binary = false) {
  const double fx = std::floor(x), fy = std::floor(y);
  const int64_t ix = static_cast<int64_t>(fx) - 1, iy = static_cast<int64_t>(fy) - 1;
  float wx[4], wy[4];
  bsplineWeights(static_cast<float>(x - fx), wx);
  bsplineWeights(static_cast<float>(y - fy), wy);
  float sum = 0.f;
  for (int b = 0; b < 4; ++b) {
    float row = 0.f;
    for (int a = 0; a < 4; ++a) {
      const uint64_t h = latticeHash(ix + a, iy + b, key);
      const float v = binary ? ((h >> 63) ? 1.f : -1.f) : static_cast<float>(toUnit(h) * 2.0 - 1.0);
      row += wx[a] * v;
    }
    sum += wy[b] * row;
  }
  return sum;
}

/// sin and cos of p in [0, 2 pi) by polynomials (|error| < 1e-6): libm's may differ between CPUs and versions.
inline void sinCos(float p, float* s, float* c) {
  const auto sinHalfPi = [](float x) {  // x in [-pi/2, pi/2], Taylor to x^11
    const float x2 = x * x;
    return x * (1.f + x2 * (-1.f / 6.f + x2 * (1.f / 120.f + x2 * (-1.f / 5040.f +
                                                                   x2 * (1.f / 362880.f + x2 * (-1.f / 39916800.f))))));
  };
  const float kPi = 3.14159265f, kHalfPi = 1.57079633f;
  // sin: fold [0, 2 pi) onto [-pi/2, pi/2].
  float x = p;
  if (x > kHalfPi && x <= 3.f * kHalfPi)
    x = kPi - x;
  else if (x > 3.f * kHalfPi)
    x = x - 2.f * kPi;
  *s = sinHalfPi(x);
  // cos(p) = sin(p + pi/2), folded the same way.
  float y = p + kHalfPi;
  if (y > 2.f * kPi) y -= 2.f * kPi;
  if (y > kHalfPi && y <= 3.f * kHalfPi)
    y = kPi - y;
  else if (y > 3.f * kHalfPi)
    y = y - 2.f * kPi;
  *c = sinHalfPi(y);
}

inline float clampf(float v, float lo, float hi) { return v < lo ? lo : (v > hi ? hi : v); }

inline float smoothstepf(float e0, float e1, float x) {
  const float t = clampf((x - e0) / (e1 - e0), 0.f, 1.f);
  return t * t * (3.f - 2.f * t);
}

/// Quantile of the standard normal distribution, by bisection (construction time only).
double normalQuantile(double p) {
  double lo = -8.0, hi = 8.0;
  for (int i = 0; i < 100; ++i) {
    const double mid = 0.5 * (lo + hi);
    if (0.5 * std::erfc(-mid / std::sqrt(2.0)) < p)
      lo = mid;
    else
      hi = mid;
  }
  return 0.5 * (lo + hi);
}

/// Polynomial smooth maximum: a convex combination of the gradients (keeps the Lipschitz bound), <= max + k/4.
inline double smoothMax(double a, double b, double k) {
  if (k <= 0.0) return std::max(a, b);
  const double h = std::max(k - std::abs(a - b), 0.0) / k;
  return std::max(a, b) + h * h * k * 0.25;
}

/// Fraction of a disc's area kept when its edge is spread over a linear ramp of width `ramp` (area-preserving AA).
inline float rampNormalisation(float radius, float ramp) {
  if (radius >= 0.5f * ramp) return radius * radius / (radius * radius + ramp * ramp * (1.f / 12.f));
  const float b = radius + 0.5f * ramp;
  return 3.f * ramp * radius * radius / (b * b * b);
}

/// Per-point low-frequency fields of the albedo (smooth over decimetres to metres).
struct LowFreq {
  float r = 0.f, g = 0.f, b = 0.f;  // sediment colour (linear RGB)
  float mask = 0.f;                 // ripple presence [0, 1]
  float warp = 0.f;                 // ripple domain warp along the ripple direction (metres)
};

struct Rock {
  double x = 0.0, y = 0.0;  // centre (m)
  float r0 = 0.f;           // nominal radius (m)
  float outline_max = 0.f;  // largest outline radius (m)
  float reach = 0.f;        // outline + shadow rim (m)
  float rim = 0.f;          // shadow rim width (m)
  // Outline harmonics 2..5 (relative to r0).
  float ca[4] = {0.f, 0.f, 0.f, 0.f}, sa[4] = {0.f, 0.f, 0.f, 0.f};
  float height = 0.f;  // dome height in the relief (m)
  float colour[3] = {0.f, 0.f, 0.f};
  float priority = 0.f;  // overlap resolution: the larger rock wins
  uint64_t key = 0;      // noise key of its mottle
};

/// A shell (bright) or a burrow opening (dark): small ellipses on the sediment.
struct Shell {
  double x = 0.0, y = 0.0;
  bool dark = false;
  float a = 0.f, b = 0.f;    // semi-axes (m)
  float cs = 1.f, sn = 0.f;  // major axis direction
  float reach = 0.f;
  float colour[3] = {0.f, 0.f, 0.f};
  float rib_k = 0.f;  // rib spatial frequency (rad/m), 0 if smooth
};

/// Outline radius of a rock in the direction (c, s) = (cos, sin) of the polar angle.
inline float rockOutline(const Rock& r, float c, float s) {
  const float c2 = c * c - s * s, s2 = 2.f * c * s;
  const float c3 = c2 * c - s2 * s, s3 = s2 * c + c2 * s;
  const float c4 = c2 * c2 - s2 * s2, s4 = 2.f * s2 * c2;
  const float c5 = c4 * c - s4 * s, s5 = s4 * c + c4 * s;
  return r.r0 * (1.f + r.ca[0] * c2 + r.sa[0] * s2 + r.ca[1] * c3 + r.sa[1] * s3 + r.ca[2] * c4 + r.sa[2] * s4 +
                 r.ca[3] * c5 + r.sa[3] * s5);
}

/// Sampling parameters of one albedo level.
struct LevelParams {
  int level = 0;
  double texel_m = 0.0;
  int sub = 1;  // sub x sub samples per texel for object edges
  double sub_offset_m[2] = {0.0, 0.0};
  float ramp_m = 0.f;    // anti-aliasing ramp of object edges
  double touch_m = 0.0;  // how far beyond its reach an object can still affect the texel
  float octave_weight[kGrainOctaves] = {};
  int first_octave = 0;
  float ripple_att1 = 0.f, ripple_att2 = 0.f;
  float lum_weight = 1.f;       // of the decimetre luminance field, faded out at the coarsest levels
  bool ripples = true;          // ripples visible at all (else the mask and warp are not evaluated)
  bool shells_as_mean = false;  // shells far below the texel: their expected contribution instead
  int node_step = 1;            // low-frequency fields are interpolated between nodes this many texels apart
  int bin_texels = 16;          // object bins of the tile
};

/// Lists of object indices per square bin of a tile (CSR), each list in canonical object order.
struct ObjectBins {
  int bin = 16, nbx = 0;
  std::vector<int> start, items;

  template <typename Obj>
  void build(const std::vector<Obj>& objs, double x_origin, double y_origin, double spacing, int n, int bin_size,
             double extra_m) {
    bin = bin_size;
    nbx = (n + bin - 1) / bin;
    const int nbins = nbx * nbx;
    start.assign(nbins + 1, 0);
    std::vector<int> lo_x(objs.size()), hi_x(objs.size()), lo_y(objs.size()), hi_y(objs.size());
    for (size_t k = 0; k < objs.size(); ++k) {
      const double r = objs[k].reach + extra_m;
      const auto toBin = [&](double v, double origin) {
        const double t = std::floor((v - origin) / spacing);
        return static_cast<int>(std::min<double>(std::max<double>(t, -1.0), n));
      };
      lo_x[k] = std::max(0, toBin(objs[k].x - r, x_origin) / bin);
      hi_x[k] = std::min(nbx - 1, (toBin(objs[k].x + r, x_origin) + 1) / bin);
      lo_y[k] = std::max(0, toBin(objs[k].y - r, y_origin) / bin);
      hi_y[k] = std::min(nbx - 1, (toBin(objs[k].y + r, y_origin) + 1) / bin);
      for (int by = lo_y[k]; by <= hi_y[k]; ++by)
        for (int bx = lo_x[k]; bx <= hi_x[k]; ++bx) ++start[by * nbx + bx + 1];
    }
    for (int i = 0; i < nbins; ++i) start[i + 1] += start[i];
    items.resize(start[nbins]);
    std::vector<int> fill(start.begin(), start.end() - 1);
    for (size_t k = 0; k < objs.size(); ++k)
      for (int by = lo_y[k]; by <= hi_y[k]; ++by)
        for (int bx = lo_x[k]; bx <= hi_x[k]; ++bx) items[fill[by * nbx + bx]++] = static_cast<int>(k);
  }
  const int* begin(int i, int j) const { return items.data() + start[(j / bin) * nbx + i / bin]; }
  const int* end(int i, int j) const { return items.data() + start[(j / bin) * nbx + i / bin + 1]; }
};

/**
 * The seabed as pure functions of the world position: shared by the texture, the relief and proceduralRocks().
 */
class SeabedModel {
 public:
  explicit SeabedModel(const ProceduralSeabedConfig& config);

  const ProceduralSeabedConfig& config() const { return c_; }
  const LevelParams& levelParams(int level) const { return levels_[level]; }
  double rockReachMax_m() const { return rock_reach_max_; }
  double shellReachMax_m() const { return shell_reach_max_; }

  // --- Fields ---
  EXOCET_NOINLINE LowFreq lowFreq(double x, double y, const LevelParams& lp) const;
  float rippleMask(double x, double y) const;
  float rippleWarp_m(double x, double y) const;

  // --- Objects, in canonical order (cell row, cell column, index in cell) ---
  void gatherRocks(double x_min, double y_min, double x_max, double y_max, std::vector<Rock>* out) const;
  void gatherShells(double x_min, double y_min, double x_max, double y_max, std::vector<Shell>* out) const;

  // --- Albedo ---
  /// Node of the low-frequency grid of `lp` with global index (nx, ny).
  LowFreq node(const LevelParams& lp, int64_t nx, int64_t ny) const {
    return lowFreq((static_cast<double>(nx * lp.node_step) + 0.5) * lp.texel_m,
                   (static_cast<double>(ny * lp.node_step) + 0.5) * lp.texel_m, lp);
  }
  /// The texel centred on (x, y), given the four surrounding nodes and the objects touching its footprint.
  EXOCET_NOINLINE cv::Vec3f shadeTexel(const LevelParams& lp, double x, double y, const LowFreq& n00,
                                       const LowFreq& n10, const LowFreq& n01, const LowFreq& n11, float fx, float fy,
                                       const Rock* const* rocks, int n_rocks, const Shell* const* shells,
                                       int n_shells) const;

  // --- Relief ---
  bool reliefEnabled() const { return c_.relief_enabled; }
  /// Height at (x, y) given the rocks (with height > 0) whose outline may contain it.
  double height(double x, double y, const Rock* const* rocks, int n_rocks) const;
  /// Range of the regional slope term over a rectangle (monotonic along the slope: the corners bound it).
  void regionalRange(const WorldRect& a, double* lo, double* hi) const {
    *lo = std::numeric_limits<double>::infinity();
    *hi = -*lo;
    for (const double x : {a.x_min_m, a.x_max_m})
      for (const double y : {a.y_min_m, a.y_max_m}) {
        const double v = regionalHeight(x, y);
        *lo = std::min(*lo, v);
        *hi = std::max(*hi, v);
      }
  }
  double regionalHeight(double x, double y) const {
    const double L = c_.regional_slope_extent_m;
    return c_.regional_slope * L * std::tanh((slope_dx_ * x + slope_dy_ * y) / L);
  }
  double regionalExtent() const { return c_.regional_slope * c_.regional_slope_extent_m; }
  double maxHeight() const { return max_height_; }
  double minHeight() const { return min_height_; }
  double maxSlope() const { return max_slope_; }

 private:
  void rockCandidates(int64_t cx, int64_t cy, std::vector<Rock>* out) const;
  void shellsInCell(int64_t cx, int64_t cy, std::vector<Shell>* out) const;
  float rippleProfile(double x, double y, float warp_m, float att1, float att2) const;

  ProceduralSeabedConfig c_;
  std::vector<LevelParams> levels_;
  // Grain octaves: lattice spacing, rotation and offset (so that octaves do not share lattice lines).
  double octave_spacing_m_[kGrainOctaves];
  double octave_cos_[kGrainOctaves], octave_sin_[kGrainOctaves], octave_off_[kGrainOctaves];
  uint64_t octave_key_[kGrainOctaves];
  float grain_norm_ = 1.f;
  uint64_t key_sand_mud_, key_shelly_, key_lum_, key_mask1_, key_mask2_, key_warp1_, key_warp2_, key_mound1_,
      key_mound2_, key_cluster_, key_rock_cells_, key_shell_cells_, key_burrow_cells_;
  // Ripples.
  double ripple_dx_ = 1.0, ripple_dy_ = 0.0, ripple_k_ = 1.0;
  float mask_threshold_ = 0.f;
  int mask_mode_ = 0;  // -1 never, 0 patches, 1 everywhere
  float mask_nm_sd_ = 1.f;
  // Rocks and shells.
  double rock_cell_m_ = 1.0, rock_mean_per_cell_ = 0.0, rock_reach_max_ = 0.0, rock_slope_cap_ = 0.8;
  double shell_mean_per_cell_ = 0.0, shell_reach_max_ = 0.0;
  double burrow_mean_per_cell_ = 0.0;
  float small_cover_ = 0.f;                       // expected fraction of the area under shells and burrows
  float small_mean_albedo_[3] = {0.f, 0.f, 0.f};  // their expected albedo (area-weighted)
  // Relief.
  double ripple_amp_m_ = 0.0, smooth_k_m_ = 0.0, slope_dx_ = 1.0, slope_dy_ = 0.0;
  double max_height_ = 0.0, min_height_ = 0.0, max_slope_ = 0.0;
};

SeabedModel::SeabedModel(const ProceduralSeabedConfig& config) : c_(config) {
  const std::string problem = c_.validate();
  if (!problem.empty()) throw std::invalid_argument("ProceduralSeabedConfig: " + problem);
  const uint64_t seed = c_.seed;
  key_sand_mud_ = hashKeys(seed, kSandMudField);
  key_shelly_ = hashKeys(seed, kShellySandField);
  key_lum_ = hashKeys(seed, kLuminanceField);
  key_mask1_ = hashKeys(seed, kRippleMaskField);
  key_mask2_ = hashKeys(seed, kRippleMaskField2);
  key_warp1_ = hashKeys(seed, kWarpField);
  key_warp2_ = hashKeys(seed, kWarpField2);
  key_mound1_ = hashKeys(seed, kMoundField);
  key_mound2_ = hashKeys(seed, kMoundField2);
  key_cluster_ = hashKeys(seed, kRockClusterField);
  key_rock_cells_ = hashKeys(seed, kRockCells);
  key_shell_cells_ = hashKeys(seed, kShellCells);
  key_burrow_cells_ = hashKeys(seed, kBurrowCells);

  double weight_sq = 0.0;
  for (int k = 0; k < kGrainOctaves; ++k) {
    octave_spacing_m_[k] = 2.0 * c_.base_texel_m * std::ldexp(1.0, k);
    const double angle = kTwoPi * toUnit(hashKeys(seed, kGrainRotation, k));
    octave_cos_[k] = std::cos(angle);
    octave_sin_[k] = std::sin(angle);
    octave_off_[k] = 1000.0 * toUnit(hashKeys(seed, kGrainRotation, k, 1));
    octave_key_[k] = hashKeys(seed, kGrainField, k);
    weight_sq += kOctaveAmplitude[k] * kOctaveAmplitude[k];
  }
  grain_norm_ = static_cast<float>(1.0 / (kPerlinSd * std::sqrt(weight_sq)));

  // Ripples.
  const double rdir = c_.ripple_direction_deg * kDegToRad;
  ripple_dx_ = std::cos(rdir);
  ripple_dy_ = std::sin(rdir);
  ripple_k_ = kTwoPi / c_.ripple_wavelength_m;
  mask_nm_sd_ = kBsplineSd * std::sqrt(1.25f);
  if (c_.ripple_coverage <= 0.0) {
    mask_mode_ = -1;
  } else if (c_.ripple_coverage >= 1.0) {
    mask_mode_ = 1;
  } else {
    mask_threshold_ = static_cast<float>(normalQuantile(1.0 - c_.ripple_coverage));
  }

  for (int L = 0; L <= c_.max_level; ++L) {
    LevelParams lp;
    lp.level = L;
    lp.texel_m = c_.base_texel_m * std::ldexp(1.0, L);
    const double w = lp.texel_m;
    lp.sub = L == 0 ? 1 : 2;
    for (int s = 0; s < lp.sub; ++s) lp.sub_offset_m[s] = ((s + 0.5) / lp.sub - 0.5) * w;
    lp.ramp_m = static_cast<float>(w / lp.sub);
    // An object can reach a texel's samples from its reach plus the footprint's half diagonal plus its edge ramp
    // (half a ramp, stretched by up to 1 / 0.45 along a shell's major axis).
    lp.touch_m = w * 0.7072 + 1.2 * lp.ramp_m;
    lp.first_octave = kGrainOctaves;
    for (int k = 0; k < kGrainOctaves; ++k) {
      // An octave of lattice spacing s carries wavelengths down to ~s: full weight from s >= 2 texels, none at 1.
      lp.octave_weight[k] =
          kOctaveAmplitude[k] * static_cast<float>(std::min(1.0, std::max(0.0, octave_spacing_m_[k] / w - 1.0)));
      if (lp.octave_weight[k] > 0.f && lp.first_octave == kGrainOctaves) lp.first_octave = k;
    }
    // Ripples: Gaussian approximation of the cascade of 2x2 box filters of the coarser levels.
    const double kw = ripple_k_ * w;
    lp.ripple_att1 = static_cast<float>(std::exp(-kw * kw / 12.0));
    lp.ripple_att2 = static_cast<float>(std::exp(-4.0 * kw * kw / 12.0));
    if (lp.ripple_att1 < 1e-3f) lp.ripple_att1 = 0.f;
    if (lp.ripple_att2 < 1e-3f) lp.ripple_att2 = 0.f;
    lp.ripples = lp.ripple_att1 > 0.f && mask_mode_ >= 0 && c_.ripple_contrast > 0.0;
    lp.lum_weight = static_cast<float>(std::min(1.0, std::max(0.0, 0.6 / w - 1.0)));
    // A 30 mm shell covers under 6 % of a 128 mm texel: from there on, only its share of the mean matters.
    lp.shells_as_mean = w / lp.sub >= 2.0 * kShellMaxLength_m;
    // Nodes ~4 cm apart (at least 2 texels): the warp's interpolation error stays under 1 % of a wavelength.
    int step = 2;
    while (step < 16 && (2 * step) * w <= 0.04 + 1e-12) step *= 2;
    lp.node_step = std::min(step, c_.tile_texels);
    int bin = 1;
    while (bin < 16 && (2 * bin) * w <= 0.08 + 1e-12) bin *= 2;
    lp.bin_texels = std::min(bin, c_.tile_texels);
    levels_.push_back(lp);
  }

  // Rocks: cells at least 3.3 radii wide, so that a rock's reach (< 1.61 radii + 4 mm) and its overlap checks
  // (< 2.77 radii) stay within 3x3 cells.
  rock_cell_m_ = std::max(1.0, 3.3 * c_.rock_radius_max_m + 0.01);
  rock_mean_per_cell_ = c_.rock_density_per_m2 * rock_cell_m_ * rock_cell_m_;
  rock_reach_max_ = c_.rock_radius_max_m * (1.38 * 1.001 + 0.22) + 0.004;
  shell_mean_per_cell_ = c_.shell_density_per_m2 * kShellCell_m * kShellCell_m;
  burrow_mean_per_cell_ = c_.burrow_density_per_m2 * kShellCell_m * kShellCell_m;
  shell_reach_max_ = 0.5 * kShellMaxLength_m;
  // Expectations under shellsInCell()'s draws, for the levels that only keep their mean. Area pi/4 L^2 b/a with
  // E[L^2] = L0 L1 for a 1/L^2 length law. Shells: E[b/a] 0.625, lightness 0.625, crown shading 0.875, ribs
  // (half of them) 0.94, tints weighted 0.5 / 0.35 / 0.15. Burrows: E[b/a] 0.875, lightness 0.055, shading 0.8.
  const double shell_cover = c_.shell_density_per_m2 * kTwoPi / 8.0 * 0.625 * kShellMinLength_m * kShellMaxLength_m;
  const double burrow_cover = c_.burrow_density_per_m2 * kTwoPi / 8.0 * 0.875 * kBurrowMinLength_m * kBurrowMaxLength_m;
  const double shell_tint[3] = {1.0, 0.5 * 0.95 + 0.35 * 1.0 + 0.15 * 0.87, 0.5 * 0.85 + 0.35 * 0.97 + 0.15 * 0.8};
  const double burrow_tint[3] = {1.0, 0.95, 0.85};
  small_cover_ = static_cast<float>(std::min(1.0, shell_cover + burrow_cover));
  for (int i = 0; i < 3; ++i) {
    const double sum = shell_cover * 0.625 * 0.875 * 0.94 * shell_tint[i] + burrow_cover * 0.055 * 0.8 * burrow_tint[i];
    small_mean_albedo_[i] = small_cover_ > 0.f ? static_cast<float>(sum / (shell_cover + burrow_cover)) : 0.f;
  }

  // Relief bounds. Every slope bound below is a bound of |grad| of its term; see the header.
  const double mound_slope =
      c_.mound_amplitude_m * 1.5 * std::sqrt(2.0) * (1.0 / c_.mound_size_m + 0.4 * 2.7 / c_.mound_size_m) / 1.4;
  const double base_slope = c_.regional_slope + mound_slope;
  ripple_amp_m_ = 0.5 * c_.ripple_height_m;
  if (mask_mode_ == -1) ripple_amp_m_ = 0.0;
  smooth_k_m_ = 0.5 * ripple_amp_m_;
  const double nm_grad = 1.5 * std::sqrt(2.0) * (1.0 / 4.0 + 0.5 / 1.3) / mask_nm_sd_;
  const double mask_grad = mask_mode_ == 0 ? 1.5 / 0.8 * nm_grad : 0.0;
  const double warp_grad = 1.5 * std::sqrt(2.0) * (1.0 / 3.0 + 0.15 / 0.8);
  const double ripple_slope = ripple_amp_m_ * (mask_grad + kRippleProfileSlope * ripple_k_ * (1.0 + warp_grad));
  // Rocks share the slope budget of 1 with the ground, with a floor so that they stay bumps on steep ground.
  rock_slope_cap_ = std::max(0.4, 1.0 - base_slope - ripple_amp_m_ * mask_grad);
  const double rock_slope = rock_slope_cap_ + ripple_amp_m_ * mask_grad;
  const double rock_height_max =
      std::min(1.25 * c_.rock_height_scale * c_.rock_radius_max_m, rock_slope_cap_ * c_.rock_radius_max_m);
  const double slope_extent = c_.regional_slope * c_.regional_slope_extent_m;
  const double sdir = c_.regional_slope_direction_deg * kDegToRad;
  slope_dx_ = std::cos(sdir);
  slope_dy_ = std::sin(sdir);
  // 1 % and 1 mm margins cover float rounding of the noise.
  max_slope_ = 1.01 * (base_slope + std::max(ripple_slope, rock_slope));
  max_height_ = slope_extent + c_.mound_amplitude_m * 1.01 + std::max(ripple_amp_m_, rock_height_max) +
                0.25 * smooth_k_m_ + 0.001;
  min_height_ = -slope_extent - c_.mound_amplitude_m * 1.01 - ripple_amp_m_ - 0.001;
}

LowFreq SeabedModel::lowFreq(double x, double y, const LevelParams& lp) const {
  static const float kSand[3] = {0.42f, 0.35f, 0.23f};
  static const float kMud[3] = {0.19f, 0.17f, 0.12f};
  static const float kShelly[3] = {0.52f, 0.49f, 0.41f};
  const float s = static_cast<float>(c_.sediment_contrast);
  const float n1 = bsplineNoise(x / 5.0, y / 5.0, key_sand_mud_) / kBsplineSd;
  const float n2 = bsplineNoise(x / 1.7, y / 1.7, key_shelly_) / kBsplineSd;
  const float n3 = lp.lum_weight > 0.f ? lp.lum_weight * bsplineNoise(x / 0.6, y / 0.6, key_lum_) / kBsplineSd : 0.f;
  const float t1 = clampf(0.5f + 0.5f * s * n1, 0.f, 1.f);
  const float t2 = clampf(0.8f * s * (n2 - 1.f), 0.f, 1.f);
  const float lum = 1.f + 0.15f * s * n3;
  LowFreq f;
  float rgb[3];
  for (int i = 0; i < 3; ++i) {
    const float a = kSand[i] + t1 * (kMud[i] - kSand[i]);
    rgb[i] = (a + t2 * (kShelly[i] - a)) * lum;
  }
  f.r = rgb[0];
  f.g = rgb[1];
  f.b = rgb[2];
  if (lp.ripples) {
    f.mask = rippleMask(x, y);
    f.warp = rippleWarp_m(x, y);
  }
  return f;
}

float SeabedModel::rippleMask(double x, double y) const {
  if (mask_mode_ != 0) return mask_mode_ > 0 ? 1.f : 0.f;
  const float nm =
      (bsplineNoise(x / 4.0, y / 4.0, key_mask1_) + 0.5f * bsplineNoise(x / 1.3, y / 1.3, key_mask2_)) / mask_nm_sd_;
  return smoothstepf(mask_threshold_ - 0.4f, mask_threshold_ + 0.4f, nm);
}

float SeabedModel::rippleWarp_m(double x, double y) const {
  // Bends the crests by ~10 degrees over metres, with wiggles over decimetres.
  return 1.0f * bsplineNoise(x / 3.0, y / 3.0, key_warp1_) + 0.15f * bsplineNoise(x / 0.8, y / 0.8, key_warp2_);
}

float SeabedModel::rippleProfile(double x, double y, float warp_m, float att1, float att2) const {
  double phase = ripple_k_ * (ripple_dx_ * x + ripple_dy_ * y + warp_m);
  phase -= kTwoPi * std::floor(phase / kTwoPi);
  float s1, c1;
  sinCos(static_cast<float>(phase), &s1, &c1);
  return (att1 * s1 + 0.25f * att2 * 2.f * s1 * c1) * static_cast<float>(1.0 / kRippleProfileNorm);
}

void SeabedModel::rockCandidates(int64_t cx, int64_t cy, std::vector<Rock>* out) const {
  if (rock_mean_per_cell_ <= 0.0) return;
  // Rocks gather in patches: the cell's mean count follows a noise field of ~6 m.
  const double cxm = (static_cast<double>(cx) + 0.5) * rock_cell_m_,
               cym = (static_cast<double>(cy) + 0.5) * rock_cell_m_;
  const double cluster =
      std::min(3.0, std::max(0.0, 1.0 + 0.9 * bsplineNoise(cxm / 6.0, cym / 6.0, key_cluster_) / kBsplineSd));
  RandomStream rs(key_rock_cells_, static_cast<uint64_t>(cx), static_cast<uint64_t>(cy));
  const int n = rs.poisson(rock_mean_per_cell_ * cluster);
  const double alpha = 2.2;  // power law of the radii: many pebbles, few boulders
  const double a0 = std::pow(c_.rock_radius_min_m, 1.0 - alpha), a1 = std::pow(c_.rock_radius_max_m, 1.0 - alpha);
  const double g2 = c_.relief_grid_m * c_.relief_grid_m;
  for (int i = 0; i < n; ++i) {
    Rock r;
    r.x = (static_cast<double>(cx) + rs.uniform()) * rock_cell_m_;
    r.y = (static_cast<double>(cy) + rs.uniform()) * rock_cell_m_;
    const double r0 = std::pow(a0 + rs.uniform() * (a1 - a0), 1.0 / (1.0 - alpha));
    const double amp[4] = {rs.uniform(0.04, 0.22), rs.uniform(0.0, 0.08), rs.uniform(0.0, 0.05), rs.uniform(0.0, 0.03)};
    double amp_sum = 0.0, kamp_sum = 0.0;
    for (int h = 0; h < 4; ++h) {
      const double ph = rs.uniform(0.0, kTwoPi);
      r.ca[h] = static_cast<float>(amp[h] * std::cos(ph));
      r.sa[h] = static_cast<float>(amp[h] * std::sin(ph));
      amp_sum += amp[h];
      kamp_sum += (h + 2) * amp[h];
    }
    r.r0 = static_cast<float>(r0);
    r.outline_max = static_cast<float>(r0 * (1.0 + amp_sum) * 1.001);
    r.rim = static_cast<float>(0.22 * r0 + 0.004);
    r.reach = r.outline_max + r.rim;
    // Grey to brown, darker than the sediment.
    const double lum = rs.uniform(0.05, 0.15), warm = rs.uniform(0.2, 1.0);
    r.colour[0] = static_cast<float>(lum * (1.0 + 0.35 * warm));
    r.colour[1] = static_cast<float>(lum * (1.0 + 0.12 * warm));
    r.colour[2] = static_cast<float>(lum * (1.0 - 0.3 * warm));
    r.key = rs.next();
    r.priority = static_cast<float>(r0) + static_cast<float>(1e-6 * toUnit(r.key));
    // Dome height: the nominal scale, capped so that the rock's slope and its bilinear error on the relief grid
    // stay within budget. |grad rho| <= sqrt(1 + (R'/R)^2) / R_min with rho = r / R(theta).
    const double r_min = r0 * (1.0 - amp_sum);
    const double q = kamp_sum / (1.0 - amp_sum);
    const double grad_rho = std::sqrt(1.0 + q * q) / r_min;
    const double scale = c_.rock_height_scale * rs.uniform(0.75, 1.25);
    double h = std::min(scale * r0, rock_slope_cap_ / (kRockProfileSlope * grad_rho) - ripple_amp_m_);
    h = std::min(h, kReliefInterpError_m * 8.0 / (2.0 * kRockProfileCurv * g2 * grad_rho * grad_rho) - ripple_amp_m_);
    r.height = h > 0.0005 ? static_cast<float>(h) : 0.f;
    out->push_back(r);
  }
}

void SeabedModel::gatherRocks(double x_min, double y_min, double x_max, double y_max, std::vector<Rock>* out) const {
  out->clear();
  if (rock_mean_per_cell_ <= 0.0) return;
  const int64_t cx0 = static_cast<int64_t>(std::floor((x_min - rock_reach_max_) / rock_cell_m_));
  const int64_t cx1 = static_cast<int64_t>(std::floor((x_max + rock_reach_max_) / rock_cell_m_));
  const int64_t cy0 = static_cast<int64_t>(std::floor((y_min - rock_reach_max_) / rock_cell_m_));
  const int64_t cy1 = static_cast<int64_t>(std::floor((y_max + rock_reach_max_) / rock_cell_m_));
  // Candidates of the cells and a ring around them, for the overlap checks.
  const int64_t nx = cx1 - cx0 + 3, ny = cy1 - cy0 + 3;
  std::vector<std::vector<Rock>> cand(static_cast<size_t>(nx * ny));
  for (int64_t j = 0; j < ny; ++j)
    for (int64_t i = 0; i < nx; ++i) rockCandidates(cx0 - 1 + i, cy0 - 1 + j, &cand[j * nx + i]);
  // A rock is dropped if it overlaps a rock of higher priority (whether or not that one survives): a pure
  // function of the neighbourhood, so every area agrees on it; non-overlapping rocks keep the relief simple.
  for (int64_t j = 1; j < ny - 1; ++j) {
    for (int64_t i = 1; i < nx - 1; ++i) {
      for (const Rock& r : cand[j * nx + i]) {
        bool keep = true;
        for (int64_t dj = -1; dj <= 1 && keep; ++dj) {
          for (int64_t di = -1; di <= 1 && keep; ++di) {
            for (const Rock& o : cand[(j + dj) * nx + i + di]) {
              const bool outranks = o.priority > r.priority || (o.priority == r.priority && o.key > r.key);
              if (&o == &r || !outranks) continue;
              const double dx = o.x - r.x, dy = o.y - r.y;
              const double d = static_cast<double>(o.outline_max) + r.outline_max;
              if (dx * dx + dy * dy < d * d) {
                keep = false;
                break;
              }
            }
          }
        }
        if (keep) out->push_back(r);
      }
    }
  }
}

void SeabedModel::shellsInCell(int64_t cx, int64_t cy, std::vector<Shell>* out) const {
  RandomStream rs(key_shell_cells_, static_cast<uint64_t>(cx), static_cast<uint64_t>(cy));
  const int n = rs.poisson(shell_mean_per_cell_);
  const double alpha = 2.0;
  const double a0 = std::pow(kShellMinLength_m, 1.0 - alpha), a1 = std::pow(kShellMaxLength_m, 1.0 - alpha);
  for (int i = 0; i < n; ++i) {
    Shell s;
    s.x = (static_cast<double>(cx) + rs.uniform()) * kShellCell_m;
    s.y = (static_cast<double>(cy) + rs.uniform()) * kShellCell_m;
    const double length = std::pow(a0 + rs.uniform() * (a1 - a0), 1.0 / (1.0 - alpha));
    s.a = static_cast<float>(0.5 * length);
    s.b = static_cast<float>(0.5 * length * rs.uniform(0.45, 0.8));
    const double angle = rs.uniform(0.0, kTwoPi);
    s.cs = static_cast<float>(std::cos(angle));
    s.sn = static_cast<float>(std::sin(angle));
    s.reach = s.a;
    const double lum = rs.uniform(0.45, 0.8), tint = rs.uniform();
    const double rgb[3][3] = {{1.0, 0.95, 0.85}, {1.0, 1.0, 0.97}, {1.0, 0.87, 0.8}};  // cream, white, pink
    const int t = tint < 0.5 ? 0 : (tint < 0.85 ? 1 : 2);
    for (int c = 0; c < 3; ++c) s.colour[c] = static_cast<float>(lum * rgb[t][c]);
    s.rib_k = rs.chance(0.5) ? static_cast<float>(kTwoPi / (s.b * rs.uniform(0.25, 0.45))) : 0.f;
    out->push_back(s);
  }
  // Burrow openings: dark, nearly round pits.
  RandomStream rb(key_burrow_cells_, static_cast<uint64_t>(cx), static_cast<uint64_t>(cy));
  const int nb = rb.poisson(burrow_mean_per_cell_);
  const double b0 = 1.0 / kBurrowMinLength_m, b1 = 1.0 / kBurrowMaxLength_m;
  for (int i = 0; i < nb; ++i) {
    Shell s;
    s.dark = true;
    s.x = (static_cast<double>(cx) + rb.uniform()) * kShellCell_m;
    s.y = (static_cast<double>(cy) + rb.uniform()) * kShellCell_m;
    const double length = 1.0 / (b0 + rb.uniform() * (b1 - b0));
    s.a = static_cast<float>(0.5 * length);
    s.b = static_cast<float>(0.5 * length * rb.uniform(0.75, 1.0));
    const double angle = rb.uniform(0.0, kTwoPi);
    s.cs = static_cast<float>(std::cos(angle));
    s.sn = static_cast<float>(std::sin(angle));
    s.reach = s.a;
    const double lum = rb.uniform(0.03, 0.08);
    s.colour[0] = static_cast<float>(lum);
    s.colour[1] = static_cast<float>(lum * 0.95);
    s.colour[2] = static_cast<float>(lum * 0.85);
    out->push_back(s);
  }
}

void SeabedModel::gatherShells(double x_min, double y_min, double x_max, double y_max, std::vector<Shell>* out) const {
  out->clear();
  if (shell_mean_per_cell_ <= 0.0 && burrow_mean_per_cell_ <= 0.0) return;
  const int64_t cx0 = static_cast<int64_t>(std::floor((x_min - shell_reach_max_) / kShellCell_m));
  const int64_t cx1 = static_cast<int64_t>(std::floor((x_max + shell_reach_max_) / kShellCell_m));
  const int64_t cy0 = static_cast<int64_t>(std::floor((y_min - shell_reach_max_) / kShellCell_m));
  const int64_t cy1 = static_cast<int64_t>(std::floor((y_max + shell_reach_max_) / kShellCell_m));
  for (int64_t cy = cy0; cy <= cy1; ++cy)
    for (int64_t cx = cx0; cx <= cx1; ++cx) shellsInCell(cx, cy, out);
}

cv::Vec3f SeabedModel::shadeTexel(const LevelParams& lp, double x, double y, const LowFreq& n00, const LowFreq& n10,
                                  const LowFreq& n01, const LowFreq& n11, float fx, float fy, const Rock* const* rocks,
                                  int n_rocks, const Shell* const* shells, int n_shells) const {
  const float w00 = (1.f - fx) * (1.f - fy), w10 = fx * (1.f - fy), w01 = (1.f - fx) * fy, w11 = fx * fy;
  const float sed_r = w00 * n00.r + w10 * n10.r + w01 * n01.r + w11 * n11.r;
  const float sed_g = w00 * n00.g + w10 * n10.g + w01 * n01.g + w11 * n11.g;
  const float sed_b = w00 * n00.b + w10 * n10.b + w01 * n01.b + w11 * n11.b;
  const float mask = w00 * n00.mask + w10 * n10.mask + w01 * n01.mask + w11 * n11.mask;
  const float warp = w00 * n00.warp + w10 * n10.warp + w01 * n01.warp + w11 * n11.warp;

  float grain = 0.f;
  for (int k = lp.first_octave; k < kGrainOctaves; ++k) {
    const double inv = 1.0 / octave_spacing_m_[k];
    const double u = (octave_cos_[k] * x - octave_sin_[k] * y) * inv + octave_off_[k];
    const double v = (octave_sin_[k] * x + octave_cos_[k] * y) * inv;
    grain += lp.octave_weight[k] * gradientNoise(u, v, octave_key_[k]);
  }
  grain *= grain_norm_;
  float ripple = 0.f;
  if (mask > 0.f && lp.ripple_att1 > 0.f)
    ripple = static_cast<float>(c_.ripple_contrast) * mask * rippleProfile(x, y, warp, lp.ripple_att1, lp.ripple_att2);
  const float gain = (1.f + static_cast<float>(c_.grain_contrast) * grain) * (1.f + ripple);
  cv::Vec3f ground(sed_r * gain, sed_g * gain, sed_b * gain);
  if (lp.shells_as_mean)
    for (int c = 0; c < 3; ++c) ground[c] += small_cover_ * (small_mean_albedo_[c] - ground[c]);

  cv::Vec3f out = ground;
  if (n_rocks > 0 || n_shells > 0) {
    // Objects: sub x sub samples of the footprint, each with an area-preserving edge ramp.
    cv::Vec3f acc(0.f, 0.f, 0.f);
    cv::Vec3f rock_albedo[8];
    bool rock_albedo_done[8] = {false, false, false, false, false, false, false, false};
    for (int sy = 0; sy < lp.sub; ++sy) {
      for (int sx = 0; sx < lp.sub; ++sx) {
        const double px = x + lp.sub_offset_m[sx], py = y + lp.sub_offset_m[sy];
        cv::Vec3f col = ground;
        for (int k = 0; k < n_shells; ++k) {
          const Shell& s = *shells[k];
          const float dx = static_cast<float>(px - s.x), dy = static_cast<float>(py - s.y);
          const float ramp = lp.ramp_m;
          if (dx * dx + dy * dy > (s.a + 1.2f * ramp) * (s.a + 1.2f * ramp)) continue;
          const float u = (dx * s.cs + dy * s.sn) / s.a, v = (-dx * s.sn + dy * s.cs) / s.b;
          const float q2 = u * u + v * v;
          const float q = std::sqrt(q2);
          const float edge = (1.f - q) * s.b;
          const float cov = clampf(edge / ramp + 0.5f, 0.f, 1.f) * rampNormalisation(std::sqrt(s.a * s.b), ramp);
          if (cov <= 0.f) continue;
          // Shells: brighter crown, darker rim, ribs on half of them. Burrows: darkest at the centre.
          float shade = s.dark ? 0.6f + 0.4f * std::min(q2, 1.f) : 0.75f + 0.25f * std::max(0.f, 1.f - q2);
          if (s.rib_k > 0.f) {
            double rib = std::abs(static_cast<double>(s.rib_k) * v * s.b);
            rib -= kTwoPi * std::floor(rib / kTwoPi);
            float rs, rc;
            sinCos(static_cast<float>(rib), &rs, &rc);
            shade *= 0.88f + 0.12f * rc;
          }
          for (int c = 0; c < 3; ++c) col[c] += (s.colour[c] * shade - col[c]) * cov;
        }
        for (int k = 0; k < n_rocks; ++k) {
          const Rock& r = *rocks[k];
          const float dx = static_cast<float>(px - r.x), dy = static_cast<float>(py - r.y);
          const float d2 = dx * dx + dy * dy;
          if (d2 > r.reach * r.reach) continue;
          const float dist = std::sqrt(d2);
          const float outline = dist > 0.f ? rockOutline(r, dx / dist, dy / dist) : r.r0;
          const float edge = outline - dist;
          // Soft shadow rim on the sediment around the foot.
          const float rim_t = clampf(-edge / r.rim, 0.f, 1.f);
          col *= 1.f - static_cast<float>(kRimStrength) * (1.f - rim_t) * (1.f - rim_t);
          const float ramp = std::sqrt(lp.ramp_m * lp.ramp_m + 0.0004f * r.r0 * r.r0);
          const float cov = clampf(edge / ramp + 0.5f, 0.f, 1.f) * rampNormalisation(r.r0, ramp);
          if (cov <= 0.f) continue;
          cv::Vec3f albedo;
          if (k < 8 && rock_albedo_done[k]) {
            albedo = rock_albedo[k];
          } else {
            // Rock texture at the texel centre: stronger grain and a mottle at its own scale.
            float mottle = 0.f;
            const double s1 = 0.35 * r.r0, s2 = 0.12 * r.r0;
            const float f1 = clampf(static_cast<float>(s1 / lp.texel_m) - 1.f, 0.f, 1.f);
            const float f2 = clampf(static_cast<float>(s2 / lp.texel_m) - 1.f, 0.f, 1.f);
            if (f1 > 0.f) mottle += f1 * gradientNoise(x / s1, y / s1, r.key);
            if (f2 > 0.f) mottle += 0.6f * f2 * gradientNoise(x / s2, y / s2, r.key + 1);
            // Floored so that the darkest grains do not saturate into flat black patches.
            const float rg =
                std::max(0.35f, 1.f + 1.6f * static_cast<float>(c_.grain_contrast) * grain + 1.2f * mottle);
            albedo = cv::Vec3f(r.colour[0] * rg, r.colour[1] * rg, r.colour[2] * rg);
            if (k < 8) {
              rock_albedo[k] = albedo;
              rock_albedo_done[k] = true;
            }
          }
          // Faces turn away from the vertical towards the foot.
          const float rho = dist / outline;
          albedo *= 0.78f + 0.22f * std::sqrt(std::max(0.f, 1.f - rho * rho));
          col += (albedo - col) * cov;
        }
        acc += col;
      }
    }
    out = acc * (1.f / static_cast<float>(lp.sub * lp.sub));
  }
  for (int c = 0; c < 3; ++c) out[c] = clampf(out[c], 0.02f, 0.9f);
  return out;
}

double SeabedModel::height(double x, double y, const Rock* const* rocks, int n_rocks) const {
  if (!c_.relief_enabled) return 0.0;
  double h = regionalHeight(x, y);
  const double s = c_.mound_size_m;
  h += c_.mound_amplitude_m *
       (bsplineNoise(x / s, y / s, key_mound1_, true) +
        0.4 * bsplineNoise(x * 2.7 / s, y * 2.7 / s, key_mound2_, true)) /
       1.4;
  double ripple = 0.0, mask = 0.0;
  if (ripple_amp_m_ > 0.0) {
    mask = rippleMask(x, y);
    if (mask > 0.0) ripple = ripple_amp_m_ * mask * rippleProfile(x, y, rippleWarp_m(x, y), 1.f, 1.f);
  }
  // Rock domes emerge from the ripples' troughs: -A m outside the rocks, H at their top.
  double rockfield = -ripple_amp_m_ * mask;
  for (int k = 0; k < n_rocks; ++k) {
    const Rock& r = *rocks[k];
    const double dx = x - r.x, dy = y - r.y;
    const double d2 = dx * dx + dy * dy;
    if (d2 >= static_cast<double>(r.outline_max) * r.outline_max) continue;
    const double dist = std::sqrt(d2);
    const double outline =
        dist > 0.0 ? rockOutline(r, static_cast<float>(dx / dist), static_cast<float>(dy / dist)) : r.r0;
    const double rho = dist / outline;
    if (rho >= 1.0) continue;
    const double profile = 1.0 - rho * rho * (3.0 - 2.0 * rho);
    rockfield += (r.height + ripple_amp_m_ * mask) * profile;
  }
  return h + smoothMax(ripple, rockfield, smooth_k_m_);
}

// ------------------------------------------------------------------------------------------------------------
// LRU tile cache

struct TileKey {
  int level;
  int64_t tx, ty;
  bool operator==(const TileKey& o) const { return level == o.level && tx == o.tx && ty == o.ty; }
};

struct TileKeyHash {
  size_t operator()(const TileKey& k) const {
    return static_cast<size_t>(
        hashKeys(static_cast<uint64_t>(k.level), static_cast<uint64_t>(k.tx), static_cast<uint64_t>(k.ty)));
  }
};

template <typename T>
class TileCache {
 public:
  using TilePtr = std::shared_ptr<const cv::Mat_<T>>;
  explicit TileCache(size_t budget_bytes) : budget_(budget_bytes) {}

  TilePtr find(const TileKey& key) {
    auto it = index_.find(key);
    if (it == index_.end()) return nullptr;
    lru_.splice(lru_.begin(), lru_, it->second);
    return it->second->second;
  }
  /// Inserts and evicts the least recently used tiles (possibly this one) until within budget.
  void insert(const TileKey& key, const TilePtr& tile) {
    lru_.emplace_front(key, tile);
    index_[key] = lru_.begin();
    bytes_ += tileBytes(*tile);
    while (bytes_ > budget_ && !lru_.empty()) {
      bytes_ -= tileBytes(*lru_.back().second);
      index_.erase(lru_.back().first);
      lru_.pop_back();
    }
  }
  size_t bytes() const { return bytes_; }

 private:
  static size_t tileBytes(const cv::Mat_<T>& m) { return m.total() * sizeof(T) + kTileOverheadBytes; }
  size_t budget_;
  size_t bytes_ = 0;
  std::list<std::pair<TileKey, TilePtr>> lru_;
  std::unordered_map<TileKey, typename std::list<std::pair<TileKey, TilePtr>>::iterator, TileKeyHash> index_;
};

size_t budgetBytes(const ProceduralSeabedConfig& c) { return static_cast<size_t>(c.cache_budget_mb * 1024.0 * 1024.0); }

/// Index range [lo, hi] of the samples at origin + k * spacing needed to sample [a, b] with one sample of margin.
void sampleRange(double a, double b, double origin, double spacing, int64_t* lo, int64_t* hi) {
  *lo = static_cast<int64_t>(std::floor((a - origin) / spacing)) - 1;
  *hi = static_cast<int64_t>(std::ceil((b - origin) / spacing)) + 1;
}

void checkArea(const WorldRect& area, const char* who) {
  const bool finite = std::isfinite(area.x_min_m) && std::isfinite(area.x_max_m) && std::isfinite(area.y_min_m) &&
                      std::isfinite(area.y_max_m);
  if (!finite || area.x_max_m < area.x_min_m || area.y_max_m < area.y_min_m)
    throw std::invalid_argument(std::string(who) + ": area must be finite with x_min <= x_max and y_min <= y_max");
}

/// Copies the tiles' parts into a patch of rows x cols samples whose first sample has global index (i0, j0).
template <typename T, typename GetTile>
void assemble(int tile_n, int64_t i0, int64_t j0, int cols, int rows, GetTile get_tile, cv::Mat_<T>* out) {
  out->create(rows, cols);
  const int64_t i1 = i0 + cols - 1, j1 = j0 + rows - 1;
  for (int64_t ty = floorDiv(j0, tile_n); ty <= floorDiv(j1, tile_n); ++ty) {
    for (int64_t tx = floorDiv(i0, tile_n); tx <= floorDiv(i1, tile_n); ++tx) {
      const auto tile = get_tile(tx, ty);
      const int64_t a0 = std::max(i0, tx * tile_n), a1 = std::min(i1, tx * tile_n + tile_n - 1);
      const int64_t b0 = std::max(j0, ty * tile_n), b1 = std::min(j1, ty * tile_n + tile_n - 1);
      const size_t count = static_cast<size_t>(a1 - a0 + 1);
      for (int64_t j = b0; j <= b1; ++j)
        std::copy_n((*tile)[j - ty * tile_n] + (a0 - tx * tile_n), count, (*out)[j - j0] + (a0 - i0));
    }
  }
}

}  // namespace

// --------------------------------------------------------------------------------------------------------------
// Config

std::string ProceduralSeabedConfig::validate() const {
  std::ostringstream err;
  const auto range = [&err](const char* name, double v, double lo, double hi, const char* unit = "") {
    if (!(v >= lo && v <= hi) || !std::isfinite(v))
      err << "seabed." << name << " " << v << " out of range [" << lo << ", " << hi << "]" << unit << "; ";
  };
  range("base_texel_m", base_texel_m, 0.0005, 0.05);
  if (tile_texels < 32 || tile_texels > 1024 || (tile_texels & (tile_texels - 1)) != 0)
    err << "seabed.tile_texels " << tile_texels << " must be a power of two in [32, 1024]; ";
  range("cache_budget_mb", cache_budget_mb, 0.01, 1048576.0);
  range("max_level", max_level, 0, 14);
  range("sediment_contrast", sediment_contrast, 0.0, 1.0);
  range("grain_contrast", grain_contrast, 0.0, 1.0);
  range("ripple_coverage", ripple_coverage, 0.0, 1.0);
  range("ripple_wavelength_m", ripple_wavelength_m, 0.03, 1.0);
  range("ripple_contrast", ripple_contrast, 0.0, 1.0);
  range("ripple_direction_deg", ripple_direction_deg, -360.0, 360.0);
  range("rock_density_per_m2", rock_density_per_m2, 0.0, 20.0);
  range("rock_radius_min_m", rock_radius_min_m, 0.005, 1.0);
  range("rock_radius_max_m", rock_radius_max_m, std::max(0.005, rock_radius_min_m), 1.0);
  range("shell_density_per_m2", shell_density_per_m2, 0.0, 200.0);
  range("burrow_density_per_m2", burrow_density_per_m2, 0.0, 200.0);
  range("mound_amplitude_m", mound_amplitude_m, 0.0, 5.0);
  range("mound_size_m", mound_size_m, 1.0, 1000.0);
  range("regional_slope", regional_slope, 0.0, 0.3);
  range("regional_slope_direction_deg", regional_slope_direction_deg, -360.0, 360.0);
  range("regional_slope_extent_m", regional_slope_extent_m, 10.0, 100000.0);
  range("ripple_height_m", ripple_height_m, 0.0, 0.1);
  range("rock_height_scale", rock_height_scale, 0.0, 1.0);
  range("relief_grid_m", relief_grid_m, 0.001, 0.2);
  std::string s = err.str();
  if (!s.empty()) s.resize(s.size() - 2);
  return s;
}

std::vector<SeabedRock> proceduralRocks(const ProceduralSeabedConfig& config, const WorldRect& area) {
  checkArea(area, "proceduralRocks");
  const SeabedModel model(config);
  std::vector<Rock> rocks;
  model.gatherRocks(area.x_min_m, area.y_min_m, area.x_max_m, area.y_max_m, &rocks);
  std::vector<SeabedRock> out;
  for (const Rock& r : rocks) {
    if (r.x < area.x_min_m || r.x > area.x_max_m || r.y < area.y_min_m || r.y > area.y_max_m) continue;
    SeabedRock s;
    s.x_m = r.x;
    s.y_m = r.y;
    s.radius_m = r.r0;
    s.height_m = config.relief_enabled ? r.height : 0.0;
    out.push_back(s);
  }
  return out;
}

// --------------------------------------------------------------------------------------------------------------
// Texture

struct ProceduralSeabedTexture::Impl {
  explicit Impl(const ProceduralSeabedConfig& c) : model(c), cache(budgetBytes(c)) {}

  std::shared_ptr<const cv::Mat_<cv::Vec3f>> generate(int level, int64_t tx, int64_t ty) const;
  /// Tile (tx, ty) of `level`, from the cache or generated into it. Call with `mutex` held.
  std::shared_ptr<const cv::Mat_<cv::Vec3f>> tile(int level, int64_t tx, int64_t ty);
  /// Global texel indices [i0, i1] x [j0, j1] covering `area` at `level`; throws as albedoPatch() documents.
  void texelRange(int level, const WorldRect& area, const char* who, int64_t* i0, int64_t* i1, int64_t* j0,
                  int64_t* j1) const;

  SeabedModel model;
  mutable std::mutex mutex;
  TileCache<cv::Vec3f> cache;
  size_t generated = 0;
};

std::shared_ptr<const cv::Mat_<cv::Vec3f>> ProceduralSeabedTexture::Impl::generate(int level, int64_t tx,
                                                                                   int64_t ty) const {
  const LevelParams& lp = model.levelParams(level);
  const int n = model.config().tile_texels;
  const double w = lp.texel_m;
  const int64_t i0 = tx * n, j0 = ty * n;
  const double x0 = (static_cast<double>(i0) + 0.5) * w, y0 = (static_cast<double>(j0) + 0.5) * w;
  const double x1 = (static_cast<double>(i0 + n - 1) + 0.5) * w, y1 = (static_cast<double>(j0 + n - 1) + 0.5) * w;

  // Low-frequency nodes (the tile is a whole number of node steps).
  const int step = lp.node_step, nn = n / step + 1;
  std::vector<LowFreq> nodes(static_cast<size_t>(nn * nn));
  const int64_t nx0 = i0 / step, ny0 = j0 / step;
  cv::parallel_for_(cv::Range(0, nn), [&](const cv::Range& r) {
    for (int b = r.start; b < r.end; ++b)
      for (int a = 0; a < nn; ++a) nodes[b * nn + a] = model.node(lp, nx0 + a, ny0 + b);
  });

  // Objects touching the tile, binned.
  std::vector<Rock> rocks;
  std::vector<Shell> shells;
  model.gatherRocks(x0 - lp.touch_m, y0 - lp.touch_m, x1 + lp.touch_m, y1 + lp.touch_m, &rocks);
  if (!lp.shells_as_mean)
    model.gatherShells(x0 - lp.touch_m, y0 - lp.touch_m, x1 + lp.touch_m, y1 + lp.touch_m, &shells);
  ObjectBins rock_bins, shell_bins;
  rock_bins.build(rocks, x0, y0, w, n, lp.bin_texels, lp.touch_m);
  shell_bins.build(shells, x0, y0, w, n, lp.bin_texels, lp.touch_m);

  auto tile = std::make_shared<cv::Mat_<cv::Vec3f>>(n, n);
  cv::parallel_for_(cv::Range(0, n), [&](const cv::Range& range) {
    std::vector<const Rock*> touching_rocks;
    std::vector<const Shell*> touching_shells;
    for (int j = range.start; j < range.end; ++j) {
      cv::Vec3f* row = (*tile)[j];
      const double y = (static_cast<double>(j0 + j) + 0.5) * w;
      const int nb = j / step;
      const float fy = static_cast<float>(j - nb * step) / static_cast<float>(step);
      for (int i = 0; i < n; ++i) {
        const double x = (static_cast<double>(i0 + i) + 0.5) * w;
        const int na = i / step;
        const float fx = static_cast<float>(i - na * step) / static_cast<float>(step);
        touching_rocks.clear();
        touching_shells.clear();
        for (const int* k = rock_bins.begin(i, j); k != rock_bins.end(i, j); ++k) {
          const Rock& r = rocks[*k];
          const double dx = x - r.x, dy = y - r.y, d = r.reach + lp.touch_m;
          if (dx * dx + dy * dy <= d * d) touching_rocks.push_back(&r);
        }
        for (const int* k = shell_bins.begin(i, j); k != shell_bins.end(i, j); ++k) {
          const Shell& s = shells[*k];
          const double dx = x - s.x, dy = y - s.y, d = s.reach + lp.touch_m;
          if (dx * dx + dy * dy <= d * d) touching_shells.push_back(&s);
        }
        const LowFreq* nb0 = &nodes[nb * nn + na];
        const LowFreq* nb1 = nb0 + nn;
        row[i] = model.shadeTexel(lp, x, y, nb0[0], nb0[1], nb1[0], nb1[1], fx, fy, touching_rocks.data(),
                                  static_cast<int>(touching_rocks.size()), touching_shells.data(),
                                  static_cast<int>(touching_shells.size()));
      }
    }
  });
  return tile;
}

ProceduralSeabedTexture::ProceduralSeabedTexture(const ProceduralSeabedConfig& config)
    : impl_(std::make_unique<Impl>(config)) {}

ProceduralSeabedTexture::~ProceduralSeabedTexture() = default;

double ProceduralSeabedTexture::baseTexelSize_m() const { return impl_->model.config().base_texel_m; }

int ProceduralSeabedTexture::maxLevel() const { return impl_->model.config().max_level; }

const ProceduralSeabedConfig& ProceduralSeabedTexture::config() const { return impl_->model.config(); }

std::shared_ptr<const cv::Mat_<cv::Vec3f>> ProceduralSeabedTexture::Impl::tile(int level, int64_t tx, int64_t ty) {
  const TileKey key{level, tx, ty};
  auto found = cache.find(key);
  if (!found) {
    found = generate(level, tx, ty);
    ++generated;
    cache.insert(key, found);
  }
  return found;
}

void ProceduralSeabedTexture::Impl::texelRange(int level, const WorldRect& area, const char* who, int64_t* i0,
                                               int64_t* i1, int64_t* j0, int64_t* j1) const {
  if (level < 0 || level > model.config().max_level)
    throw std::out_of_range("ProceduralSeabedTexture: level " + std::to_string(level) + " outside [0, " +
                            std::to_string(model.config().max_level) + "]");
  checkArea(area, who);
  const double w = model.levelParams(level).texel_m;
  sampleRange(area.x_min_m, area.x_max_m, 0.5 * w, w, i0, i1);
  sampleRange(area.y_min_m, area.y_max_m, 0.5 * w, w, j0, j1);
  const size_t cols = static_cast<size_t>(*i1 - *i0 + 1), rows = static_cast<size_t>(*j1 - *j0 + 1);
  if (cols * rows > kMaxPatchTexels)
    throw std::invalid_argument(std::string(who) + ": " + std::to_string(cols) + " x " + std::to_string(rows) +
                                " texels at level " + std::to_string(level) +
                                " exceeds 64 Mtexels; use a coarser level");
}

TexturePatch<cv::Vec3f> ProceduralSeabedTexture::albedoPatch(int level, const WorldRect& area) {
  int64_t i0, i1, j0, j1;
  impl_->texelRange(level, area, "ProceduralSeabedTexture::albedoPatch", &i0, &i1, &j0, &j1);
  const double w = impl_->model.levelParams(level).texel_m;
  TexturePatch<cv::Vec3f> patch;
  patch.level = level;
  patch.texel_m = w;
  patch.x0_m = (static_cast<double>(i0) + 0.5) * w;
  patch.y0_m = (static_cast<double>(j0) + 0.5) * w;
  std::lock_guard<std::mutex> lock(impl_->mutex);
  assemble<cv::Vec3f>(
      impl_->model.config().tile_texels, i0, j0, static_cast<int>(i1 - i0 + 1), static_cast<int>(j1 - j0 + 1),
      [&](int64_t tx, int64_t ty) { return impl_->tile(level, tx, ty); }, &patch.texels);
  return patch;
}

TextureWindow<cv::Vec3f> ProceduralSeabedTexture::albedoWindow(int level, const WorldRect& area) {
  int64_t i0, i1, j0, j1;
  impl_->texelRange(level, area, "ProceduralSeabedTexture::albedoWindow", &i0, &i1, &j0, &j1);
  const double w = impl_->model.levelParams(level).texel_m;
  const int n = impl_->model.config().tile_texels;
  const int64_t tx0 = floorDiv(i0, n), tx1 = floorDiv(i1, n), ty0 = floorDiv(j0, n), ty1 = floorDiv(j1, n);
  std::vector<TextureWindow<cv::Vec3f>::Tile> tiles;
  tiles.reserve(static_cast<size_t>((tx1 - tx0 + 1) * (ty1 - ty0 + 1)));
  {
    std::lock_guard<std::mutex> lock(impl_->mutex);
    for (int64_t ty = ty0; ty <= ty1; ++ty)
      for (int64_t tx = tx0; tx <= tx1; ++tx) tiles.push_back(impl_->tile(level, tx, ty));
  }
  int shift = 0;
  while ((1 << shift) < n) ++shift;  // tile_texels is a power of two (validated)
  return TextureWindow<cv::Vec3f>((static_cast<double>(i0) + 0.5) * w, (static_cast<double>(j0) + 0.5) * w, w, level,
                                  static_cast<int>(i1 - i0 + 1), static_cast<int>(j1 - j0 + 1), shift,
                                  static_cast<int>(i0 - tx0 * n), static_cast<int>(j0 - ty0 * n),
                                  static_cast<int>(tx1 - tx0 + 1), std::move(tiles));
}

cv::Vec3f ProceduralSeabedTexture::albedoTexel(int level, double x_m, double y_m) const {
  if (level < 0 || level > maxLevel())
    throw std::out_of_range("ProceduralSeabedTexture: level " + std::to_string(level) + " outside [0, " +
                            std::to_string(maxLevel()) + "]");
  const SeabedModel& model = impl_->model;
  const LevelParams& lp = model.levelParams(level);
  const double w = lp.texel_m;
  const int64_t i = static_cast<int64_t>(std::floor(x_m / w)), j = static_cast<int64_t>(std::floor(y_m / w));
  const double x = (static_cast<double>(i) + 0.5) * w, y = (static_cast<double>(j) + 0.5) * w;
  const int step = lp.node_step;
  const int64_t na = floorDiv(i, step), nb = floorDiv(j, step);
  const float fx = static_cast<float>(i - na * step) / static_cast<float>(step);
  const float fy = static_cast<float>(j - nb * step) / static_cast<float>(step);
  std::vector<Rock> rocks;
  std::vector<Shell> shells;
  model.gatherRocks(x - lp.touch_m, y - lp.touch_m, x + lp.touch_m, y + lp.touch_m, &rocks);
  if (!lp.shells_as_mean) model.gatherShells(x - lp.touch_m, y - lp.touch_m, x + lp.touch_m, y + lp.touch_m, &shells);
  std::vector<const Rock*> touching_rocks;
  std::vector<const Shell*> touching_shells;
  for (const Rock& r : rocks) {
    const double dx = x - r.x, dy = y - r.y, d = r.reach + lp.touch_m;
    if (dx * dx + dy * dy <= d * d) touching_rocks.push_back(&r);
  }
  for (const Shell& s : shells) {
    const double dx = x - s.x, dy = y - s.y, d = s.reach + lp.touch_m;
    if (dx * dx + dy * dy <= d * d) touching_shells.push_back(&s);
  }
  return model.shadeTexel(lp, x, y, model.node(lp, na, nb), model.node(lp, na + 1, nb), model.node(lp, na, nb + 1),
                          model.node(lp, na + 1, nb + 1), fx, fy, touching_rocks.data(),
                          static_cast<int>(touching_rocks.size()), touching_shells.data(),
                          static_cast<int>(touching_shells.size()));
}

size_t ProceduralSeabedTexture::cachedBytes() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->cache.bytes();
}

size_t ProceduralSeabedTexture::tilesGenerated() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->generated;
}

// --------------------------------------------------------------------------------------------------------------
// Relief

struct ProceduralRelief::Impl {
  explicit Impl(const ProceduralSeabedConfig& c) : model(c), cache(budgetBytes(c)) {}

  std::shared_ptr<const cv::Mat_<float>> generate(int64_t tx, int64_t ty) const;
  /// Rocks with a dome near the rectangle, in canonical order.
  void reliefRocks(double x_min, double y_min, double x_max, double y_max, std::vector<Rock>* out) const {
    model.gatherRocks(x_min, y_min, x_max, y_max, out);
    out->erase(std::remove_if(out->begin(), out->end(), [](const Rock& r) { return r.height <= 0.f; }), out->end());
    for (Rock& r : *out) r.reach = r.outline_max;  // the relief ends at the outline
  }

  SeabedModel model;
  mutable std::mutex mutex;
  TileCache<float> cache;
  size_t generated = 0;
};

std::shared_ptr<const cv::Mat_<float>> ProceduralRelief::Impl::generate(int64_t tx, int64_t ty) const {
  const int n = model.config().tile_texels;
  const double g = model.config().relief_grid_m;
  const int64_t i0 = tx * n, j0 = ty * n;
  const double x0 = static_cast<double>(i0) * g, y0 = static_cast<double>(j0) * g;
  std::vector<Rock> rocks;
  reliefRocks(x0, y0, static_cast<double>(i0 + n - 1) * g, static_cast<double>(j0 + n - 1) * g, &rocks);
  ObjectBins bins;
  bins.build(rocks, x0, y0, g, n, 16, 0.0);
  auto tile = std::make_shared<cv::Mat_<float>>(n, n);
  cv::parallel_for_(cv::Range(0, n), [&](const cv::Range& range) {
    std::vector<const Rock*> near;
    for (int j = range.start; j < range.end; ++j) {
      float* row = (*tile)[j];
      const double y = static_cast<double>(j0 + j) * g;
      for (int i = 0; i < n; ++i) {
        const double x = static_cast<double>(i0 + i) * g;
        near.clear();
        for (const int* k = bins.begin(i, j); k != bins.end(i, j); ++k) near.push_back(&rocks[*k]);
        row[i] = static_cast<float>(model.height(x, y, near.data(), static_cast<int>(near.size())));
      }
    }
  });
  return tile;
}

ProceduralRelief::ProceduralRelief(const ProceduralSeabedConfig& config) : impl_(std::make_unique<Impl>(config)) {}

ProceduralRelief::~ProceduralRelief() = default;

bool ProceduralRelief::isFlat() const { return !impl_->model.reliefEnabled(); }

double ProceduralRelief::maxHeight_m() const { return isFlat() ? 0.0 : impl_->model.maxHeight(); }

double ProceduralRelief::minHeight_m() const { return isFlat() ? 0.0 : impl_->model.minHeight(); }

double ProceduralRelief::maxSlope() const { return isFlat() ? 0.0 : impl_->model.maxSlope(); }

double ProceduralRelief::gridSpacing_m() const { return impl_->model.config().relief_grid_m; }

const ProceduralSeabedConfig& ProceduralRelief::config() const { return impl_->model.config(); }

TexturePatch<float> ProceduralRelief::heightPatch(const WorldRect& area) {
  checkArea(area, "ProceduralRelief::heightPatch");
  TexturePatch<float> patch;
  if (isFlat()) {
    // As FlatRelief: one 2x2 cell of zeros over the whole area.
    patch.texels = cv::Mat_<float>::zeros(2, 2);
    patch.x0_m = area.x_min_m;
    patch.y0_m = area.y_min_m;
    patch.texel_m = std::max(area.x_max_m - area.x_min_m, area.y_max_m - area.y_min_m) + 1.0;
    return patch;
  }
  const double g = gridSpacing_m();
  int64_t i0, i1, j0, j1;
  sampleRange(area.x_min_m, area.x_max_m, 0.0, g, &i0, &i1);
  sampleRange(area.y_min_m, area.y_max_m, 0.0, g, &j0, &j1);
  const size_t cols = static_cast<size_t>(i1 - i0 + 1), rows = static_cast<size_t>(j1 - j0 + 1);
  if (cols * rows > kMaxPatchTexels)
    throw std::invalid_argument("ProceduralRelief::heightPatch: " + std::to_string(cols) + " x " +
                                std::to_string(rows) + " samples exceeds 64 Msamples");
  patch.texel_m = g;
  patch.x0_m = static_cast<double>(i0) * g;
  patch.y0_m = static_cast<double>(j0) * g;
  std::lock_guard<std::mutex> lock(impl_->mutex);
  const int n = impl_->model.config().tile_texels;
  assemble<float>(
      n, i0, j0, static_cast<int>(cols), static_cast<int>(rows),
      [&](int64_t tx, int64_t ty) {
        const TileKey key{0, tx, ty};
        auto tile = impl_->cache.find(key);
        if (!tile) {
          tile = impl_->generate(tx, ty);
          ++impl_->generated;
          impl_->cache.insert(key, tile);
        }
        return tile;
      },
      &patch.texels);
  return patch;
}

double ProceduralRelief::heightAt_m(double x_m, double y_m) const {
  if (isFlat()) return 0.0;
  std::vector<Rock> rocks;
  impl_->reliefRocks(x_m, y_m, x_m, y_m, &rocks);
  std::vector<const Rock*> near;
  for (const Rock& r : rocks) near.push_back(&r);
  return impl_->model.height(x_m, y_m, near.data(), static_cast<int>(near.size()));
}

void ProceduralRelief::heightBounds_m(const WorldRect& area, double* min_m, double* max_m) const {
  checkArea(area, "ProceduralRelief::heightBounds_m");
  if (isFlat()) {
    *min_m = *max_m = 0.0;
    return;
  }
  double lo, hi;
  impl_->model.regionalRange(area, &lo, &hi);
  const double extent = impl_->model.regionalExtent();
  *min_m = impl_->model.minHeight() + extent + lo;
  *max_m = impl_->model.maxHeight() - extent + hi;
}

size_t ProceduralRelief::cachedBytes() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->cache.bytes();
}

size_t ProceduralRelief::tilesGenerated() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->generated;
}

}  // namespace sim
}  // namespace exocet_mosaic
