#include "exocet_mosaic/sim/debris_field.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

#include "exocet_mosaic/sim/procedural_seabed.h"
#include "exocet_mosaic/sim/random.h"

namespace exocet_mosaic {
namespace sim {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr uint64_t kObjectCells = 0x6465627269730001ULL;  // "debris" + stream number
constexpr uint64_t kSiteField = 0x6465627269730002ULL;
constexpr uint64_t kEncrustation = 0x6465627269730003ULL;
constexpr double kCellSize_m = 2.0;     // cells of the hashed grid, wider than any object's reach
constexpr double kMaxSemiAxis_m = 0.8;  // no object's outline reaches further from its centre
constexpr double kGrid_m = 0.01;        // spacing of the height patches (a steep side spans ~10 samples)

/// Smooth value noise in [0, 1] on a lattice of `size_m`.
double siteField(double x_m, double y_m, double size_m, uint64_t key) {
  const double fx = x_m / size_m, fy = y_m / size_m;
  const double ix = std::floor(fx), iy = std::floor(fy);
  const auto value = [&](double i, double j) {
    return toUnit(hashKeys(key, static_cast<uint64_t>(static_cast<int64_t>(i)),
                           static_cast<uint64_t>(static_cast<int64_t>(j))));
  };
  const auto smooth = [](double t) { return t * t * (3.0 - 2.0 * t); };
  const double sx = smooth(fx - ix), sy = smooth(fy - iy);
  const double top = value(ix, iy) * (1.0 - sx) + value(ix + 1, iy) * sx;
  const double bottom = value(ix, iy + 1) * (1.0 - sx) + value(ix + 1, iy + 1) * sx;
  return top * (1.0 - sy) + bottom * sy;
}

/// Elliptical radius q (1 on the outline) of (x, y) for `o`.
double ellipticalRadius(const DebrisObject& o, double x_m, double y_m) {
  const double dx = x_m - o.x_m, dy = y_m - o.y_m;
  const double c = std::cos(o.yaw_rad), s = std::sin(o.yaw_rad);
  const double u = (c * dx + s * dy) / o.half_length_m, v = (-s * dx + c * dy) / o.half_width_m;
  return std::sqrt(u * u + v * v);
}

/// g(q) = min((1 - q^m)^(1/m), k (1 - q)) for q < 1: |g'| <= k where the ramp is not active (see the header), so the
/// world slope is at most H k / half_width = max_slope.
double profile(double q, double m, double k) {
  if (q >= 1.0) return -1.0;
  const double top = std::pow(std::max(0.0, 1.0 - std::pow(q, m)), 1.0 / m);
  return std::min(top, k * (1.0 - q));
}

}  // namespace

// ---- Configuration ------------------------------------------------------------------------------------------------

std::string DebrisFieldConfig::validate() const {
  std::ostringstream err;
  const auto range = [&err](const char* name, double v, double lo, double hi) {
    if (!(v >= lo && v <= hi) || !std::isfinite(v))
      err << "seabed.objects_" << name << " " << v << " out of range [" << lo << ", " << hi << "]; ";
  };
  if (preset != "wreck" && preset != "boulders")
    err << "seabed.objects '" << preset << "' is not one of wreck, boulders; ";
  range("density_per_m2", density_per_m2, 0.0, 5.0);
  range("site_size_m", site_size_m, 1.0, 100.0);
  range("min_height_m", min_height_m, 1e-3, 2.0);
  range("max_height_m", max_height_m, min_height_m, 2.0);
  range("max_slope", max_slope, 0.5, 10.0);
  range("embed_m", embed_m, 0.0, 0.2);
  std::string s = err.str();
  if (s.size() >= 2) s.resize(s.size() - 2);
  return s;
}

DebrisFieldConfig DebrisFieldConfig::fromPreset(const std::string& name, uint64_t seed) {
  DebrisFieldConfig c;
  c.seed = seed;
  if (name == "wreck") {
    c.preset = "wreck";
    c.density_per_m2 = 0.5;
  } else if (name == "boulders") {
    c.preset = "boulders";
    c.density_per_m2 = 0.35;
  } else {
    throw std::invalid_argument("seabed.objects '" + name + "' is not one of none, wreck, boulders");
  }
  return c;
}

double DebrisObject::insideness(double x, double y) const { return 1.0 - ellipticalRadius(*this, x, y); }

double DebrisObject::profileHeight_m(double x, double y) const {
  const double g = profile(ellipticalRadius(*this, x, y), top_exponent, ramp);
  return g < 0.0 ? -1.0 : nominal_height_m * g;
}

// ---- Relief -------------------------------------------------------------------------------------------------------

struct DebrisRelief::Generator {
  DebrisFieldConfig c;
  const SeabedRelief* base = nullptr;

  /// The objects of cell (cx, cy): a Poisson count modulated by the site field (piles and bare sand).
  void cell(int64_t cx, int64_t cy, std::vector<DebrisObject>* out) const {
    const double x0 = static_cast<double>(cx) * kCellSize_m, y0 = static_cast<double>(cy) * kCellSize_m;
    const double site = siteField(x0 + 0.5 * kCellSize_m, y0 + 0.5 * kCellSize_m, c.site_size_m,
                                  hashKeys(c.seed, kSiteField));
    // Site field in [0, 1] -> density multiplier in [0, 2] (mean 1), zero on the barest third.
    const double multiplier = std::max(0.0, 3.0 * site - 1.0);
    RandomStream rs(hashKeys(c.seed, kObjectCells), static_cast<uint64_t>(cx), static_cast<uint64_t>(cy));
    const int n = rs.poisson(c.density_per_m2 * kCellSize_m * kCellSize_m * multiplier);
    for (int i = 0; i < n; ++i) {
      DebrisObject o;
      o.x_m = x0 + rs.uniform() * kCellSize_m;
      o.y_m = y0 + rs.uniform() * kCellSize_m;
      o.yaw_rad = rs.uniform(0.0, kPi);
      o.nominal_height_m = rs.uniform(c.min_height_m, c.max_height_m);
      const bool pile = c.preset == "wreck" ? rs.chance(0.8) : false;
      o.kind = pile ? DebrisObject::Kind::kPile : DebrisObject::Kind::kBlock;
      // Half-width at least H / max_slope so that the slope cap leaves the drawn height (the top reaches H).
      const double min_half_width = o.nominal_height_m / c.max_slope;
      if (pile) {
        o.half_width_m = std::clamp(rs.uniform(0.2, 0.35), min_half_width, kMaxSemiAxis_m);
        o.half_length_m = std::min(kMaxSemiAxis_m, o.half_width_m * rs.uniform(1.6, 2.4));
        o.top_exponent = 2.0;
        o.tint = cv::Vec3f(1.45f, 0.85f, 0.6f) * static_cast<float>(rs.uniform(0.8, 1.1));  // terracotta
        o.band_period_m = rs.uniform(0.18, 0.26);                                           // one jar's width
      } else {
        o.half_width_m = std::clamp(rs.uniform(0.2, 0.45), min_half_width, kMaxSemiAxis_m);
        o.half_length_m = std::min(kMaxSemiAxis_m, o.half_width_m * rs.uniform(1.0, 1.4));
        o.top_exponent = 4.0;
        const float grey = static_cast<float>(rs.uniform(0.7, 1.2));
        o.tint = cv::Vec3f(0.95f, 1.0f, 1.05f) * grey;
      }
      o.ramp = c.max_slope * o.half_width_m / o.nominal_height_m;
      o.foot_m = base->heightAt_m(o.x_m, o.y_m) - c.embed_m;
      o.top_height_m = o.nominal_height_m * std::min(1.0, o.ramp) - c.embed_m;
      out->push_back(o);
    }
  }

  std::vector<DebrisObject> objects(const WorldRect& a) const {
    std::vector<DebrisObject> out;
    if (c.density_per_m2 <= 0.0) return out;
    const int64_t cx0 = static_cast<int64_t>(std::floor((a.x_min_m - kMaxSemiAxis_m) / kCellSize_m));
    const int64_t cx1 = static_cast<int64_t>(std::floor((a.x_max_m + kMaxSemiAxis_m) / kCellSize_m));
    const int64_t cy0 = static_cast<int64_t>(std::floor((a.y_min_m - kMaxSemiAxis_m) / kCellSize_m));
    const int64_t cy1 = static_cast<int64_t>(std::floor((a.y_max_m + kMaxSemiAxis_m) / kCellSize_m));
    std::vector<DebrisObject> cell_objects;
    for (int64_t cy = cy0; cy <= cy1; ++cy)
      for (int64_t cx = cx0; cx <= cx1; ++cx) {
        cell_objects.clear();
        cell(cx, cy, &cell_objects);
        for (const DebrisObject& o : cell_objects) {
          const double reach = o.half_length_m;
          if (o.x_m + reach < a.x_min_m || o.x_m - reach > a.x_max_m || o.y_m + reach < a.y_min_m ||
              o.y_m - reach > a.y_max_m)
            continue;
          out.push_back(o);
        }
      }
    return out;
  }
};

DebrisRelief::DebrisRelief(const DebrisFieldConfig& config, std::unique_ptr<SeabedRelief> base)
    : config_(config), base_(std::move(base)), generator_(std::make_unique<Generator>()) {
  if (!base_) throw std::invalid_argument("DebrisRelief: no base relief");
  const std::string problem = config_.validate();
  if (!problem.empty()) throw std::invalid_argument(problem);
  generator_->c = config_;
  generator_->base = base_.get();
}

DebrisRelief::~DebrisRelief() = default;

double DebrisRelief::maxHeight_m() const { return base_->maxHeight_m() + config_.max_height_m; }
double DebrisRelief::minHeight_m() const { return base_->minHeight_m(); }
// The larger of the base's slope and the objects' cap, with a margin: where the rounded top meets the ramp its slope
// exceeds the ramp's by a few per cent (measured up to 6 %), and a foot follows the base at its centre only.
double DebrisRelief::maxSlope() const { return 1.2 * std::max(base_->maxSlope(), config_.max_slope); }
double DebrisRelief::gridSpacing_m() const { return base_->isFlat() ? kGrid_m : std::min(kGrid_m, base_->gridSpacing_m()); }

std::vector<DebrisObject> DebrisRelief::objects(const WorldRect& area) const { return generator_->objects(area); }

int DebrisRelief::topObject(const std::vector<DebrisObject>& objects, double x, double y, double base_height_m,
                            double* height_m) const {
  int best = -1;
  double best_h = base_height_m;
  for (size_t i = 0; i < objects.size(); ++i) {
    const DebrisObject& o = objects[i];
    if (std::abs(x - o.x_m) > o.half_length_m || std::abs(y - o.y_m) > o.half_length_m) continue;
    const double p = o.profileHeight_m(x, y);
    if (p < 0.0) continue;
    const double h = o.foot_m + p;
    if (h > best_h) {
      best_h = h;
      best = static_cast<int>(i);
    }
  }
  if (height_m) *height_m = best_h;
  return best;
}

double DebrisRelief::heightAt_m(double x, double y) const {
  const std::vector<DebrisObject> near = objects(WorldRect{x, y, x, y});
  double h = 0.0;
  topObject(near, x, y, base_->heightAt_m(x, y), &h);
  return h;
}

TexturePatch<float> DebrisRelief::heightPatch(const WorldRect& area) {
  if (!(area.x_max_m >= area.x_min_m && area.y_max_m >= area.y_min_m) || !std::isfinite(area.x_min_m) ||
      !std::isfinite(area.x_max_m) || !std::isfinite(area.y_min_m) || !std::isfinite(area.y_max_m))
    throw std::invalid_argument("DebrisRelief::heightPatch: empty or non-finite area");
  const double g = gridSpacing_m();
  const int64_t i0 = static_cast<int64_t>(std::floor(area.x_min_m / g)) - 1;
  const int64_t i1 = static_cast<int64_t>(std::ceil(area.x_max_m / g)) + 1;
  const int64_t j0 = static_cast<int64_t>(std::floor(area.y_min_m / g)) - 1;
  const int64_t j1 = static_cast<int64_t>(std::ceil(area.y_max_m / g)) + 1;
  const int64_t cols = i1 - i0 + 1, rows = j1 - j0 + 1;
  if (cols * rows > (int64_t(1) << 26))
    throw std::invalid_argument("DebrisRelief::heightPatch: " + std::to_string(cols) + " x " + std::to_string(rows) +
                                " samples exceeds 64 Msamples");
  TexturePatch<float> patch;
  patch.texel_m = g;
  patch.x0_m = static_cast<double>(i0) * g;
  patch.y0_m = static_cast<double>(j0) * g;
  patch.texels.create(static_cast<int>(rows), static_cast<int>(cols));
  // The base, sampled exactly at the nodes (bilinear from its own patch when it is not flat).
  const WorldRect covered{patch.x0_m, patch.y0_m, patch.x0_m + (cols - 1) * g, patch.y0_m + (rows - 1) * g};
  TexturePatch<float> base_patch = base_->heightPatch(covered);
  for (int j = 0; j < rows; ++j) {
    float* row = patch.texels[j];
    for (int i = 0; i < cols; ++i) row[i] = base_patch.sample(patch.x0_m + i * g, patch.y0_m + j * g);
  }
  // Each object raises the nodes inside its bounding box (the larger of the base and every object wins).
  for (const DebrisObject& o : objects(covered)) {
    const double r = o.half_length_m;
    const int ia = std::max(0, static_cast<int>(std::floor((o.x_m - r - patch.x0_m) / g)));
    const int ib = std::min<int>(static_cast<int>(cols) - 1, static_cast<int>(std::ceil((o.x_m + r - patch.x0_m) / g)));
    const int ja = std::max(0, static_cast<int>(std::floor((o.y_m - r - patch.y0_m) / g)));
    const int jb = std::min<int>(static_cast<int>(rows) - 1, static_cast<int>(std::ceil((o.y_m + r - patch.y0_m) / g)));
    for (int j = ja; j <= jb; ++j) {
      float* row = patch.texels[j];
      for (int i = ia; i <= ib; ++i) {
        const double p = o.profileHeight_m(patch.x0_m + i * g, patch.y0_m + j * g);
        if (p < 0.0) continue;
        row[i] = std::max(row[i], static_cast<float>(o.foot_m + p));
      }
    }
  }
  return patch;
}

// ---- Texture ------------------------------------------------------------------------------------------------------

DebrisTexture::DebrisTexture(std::unique_ptr<SeabedTexture> base, DebrisRelief* relief, uint64_t seed)
    : base_(std::move(base)), relief_(relief) {
  if (!base_ || !relief_) throw std::invalid_argument("DebrisTexture: no base texture or relief");
  // Encrusted surfaces: strong fine grain and shells, no ripples or rocks; the same texel grid as the base.
  ProceduralSeabedConfig e;
  e.seed = hashKeys(seed, kEncrustation);
  e.base_texel_m = base_->baseTexelSize_m();
  e.max_level = base_->maxLevel();
  e.cache_budget_mb = 128;
  e.sediment_contrast = 0.4;
  e.grain_contrast = 0.35;
  e.ripple_coverage = 0.0;
  e.rock_density_per_m2 = 0.0;
  e.shell_density_per_m2 = 30.0;
  e.burrow_density_per_m2 = 10.0;
  encrustation_ = std::make_unique<ProceduralSeabedTexture>(e);
}

DebrisTexture::~DebrisTexture() = default;

double DebrisTexture::baseTexelSize_m() const { return base_->baseTexelSize_m(); }
int DebrisTexture::maxLevel() const { return base_->maxLevel(); }

TexturePatch<cv::Vec3f> DebrisTexture::albedoPatch(int level, const WorldRect& area) {
  TexturePatch<cv::Vec3f> patch = base_->albedoPatch(level, area);
  const double w = patch.texel_m;
  const WorldRect covered{patch.x0_m, patch.y0_m, patch.x0_m + (patch.texels.cols - 1) * w,
                          patch.y0_m + (patch.texels.rows - 1) * w};
  const std::vector<DebrisObject> objects = relief_->objects(covered);
  if (objects.empty()) return patch;
  const TexturePatch<cv::Vec3f> crust = encrustation_->albedoPatch(level, covered);
  const TexturePatch<float> base_heights = relief_->base().heightPatch(covered);
  for (int j = 0; j < patch.texels.rows; ++j) {
    const double y = patch.y0_m + j * w;
    cv::Vec3f* row = patch.texels[j];
    for (int i = 0; i < patch.texels.cols; ++i) {
      const double x = patch.x0_m + i * w;
      double h = 0.0;
      const int top = relief_->topObject(objects, x, y, base_heights.sample(x, y), &h);
      if (top < 0) continue;
      const DebrisObject& o = objects[static_cast<size_t>(top)];
      cv::Vec3f albedo = crust.sample(x, y).mul(o.tint);
      if (o.band_period_m > 0.0) {
        // Darker seams between the jars of a pile, across its long axis (anti-aliased by the texel size).
        const double u = std::cos(o.yaw_rad) * (x - o.x_m) + std::sin(o.yaw_rad) * (y - o.y_m);
        const double phase = u / o.band_period_m - std::floor(u / o.band_period_m);
        const double to_seam_m = (0.5 - std::abs(phase - 0.5)) * o.band_period_m;
        const double darkness = std::clamp(1.0 - to_seam_m / std::max(0.015, w), 0.0, 1.0);
        albedo *= static_cast<float>(1.0 - 0.55 * darkness);
      }
      // Blend into the base over about one texel at the outline.
      const double edge = std::clamp(o.insideness(x, y) * o.half_width_m / w, 0.0, 1.0);
      row[i] = row[i] * static_cast<float>(1.0 - edge) + albedo * static_cast<float>(edge);
    }
  }
  return patch;
}

}  // namespace sim
}  // namespace exocet_mosaic
