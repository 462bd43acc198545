#include "exocet_mosaic/sim/seabed_renderer.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "exocet_mosaic/sim/random.h"

namespace exocet_mosaic {
namespace sim {

namespace {

/// Per-frame geometry shared by the row workers.
struct FrameGeometry {
  Eigen::Matrix3f R;        ///< world from camera rotation
  Eigen::Vector3d C;        ///< camera centre, local frame
  Eigen::Vector3f lamp;     ///< lamp position relative to C
  Eigen::Vector3f lamp_axis;
  double turbidity = 1.0, light_gain = 1.0;
};

float smoothClamp(float v) { return std::max(-1.0f, std::min(1.0f, v)); }

/// Where a pixel's ray meets the seabed, and the texture levels it blends there.
struct PixelHit {
  double px = 0.0, py = 0.0;  ///< hit point (local frame)
  double t = 0.0;             ///< ray parameter of the hit (depth along the optical axis)
  Eigen::Vector3f d;          ///< ray direction (world frame): the camera ray (x, y, 1) rotated
  Eigen::Vector3f n;          ///< seabed normal at the hit
  float range = 0.0f;         ///< distance from the camera
  float footprint = 0.0f;     ///< pixel's footprint on the seabed (metres)
  int i0 = 0, i1 = 0;         ///< texture levels blended (indices into the frame's windows)
  float w1 = 0.0f;            ///< weight of level i1
};

/**
 * @brief A relief patch for ray marching: TexturePatch::sample()'s bilinear heights, with the gradient of the cell
 * (for Newton steps, at no extra sample) and the highest height over a rectangle (where marching may start).
 */
class HeightSampler {
 public:
  explicit HeightSampler(const TexturePatch<float>& patch)
      : texels_(patch.texels),
        x0_m_(patch.x0_m),
        y0_m_(patch.y0_m),
        texel_m_(patch.texel_m),
        per_m_(1.0 / patch.texel_m),
        cols_(patch.texels.cols),
        rows_(patch.texels.rows) {
    buildBlockMaxima();
  }

  float operator()(double x_m, double y_m) const {
    float gx, gy;
    return sample(x_m, y_m, &gx, &gy);
  }

  /// The height and its gradient (metres per metre) within the bilinear cell holding (x_m, y_m): the exact
  /// derivative of what operator() interpolates (0 across a clamped border).
  float sample(double x_m, double y_m, float* gx, float* gy) const {
    const auto [ix, iy, ax, ay] = bilinearCell(x_m, y_m, x0_m_, y0_m_, texel_m_, cols_, rows_);
    const float* r0 = texels_[iy] + ix;
    const float* r1 = texels_[iy + 1] + ix;
    const float per_m = static_cast<float>(per_m_);
    *gx = ((r0[1] - r0[0]) * (1.f - ay) + (r1[1] - r1[0]) * ay) * per_m;
    *gy = ((r1[0] - r0[0]) * (1.f - ax) + (r1[1] - r0[1]) * ax) * per_m;
    return (r0[0] * (1.f - ax) + r0[1] * ax) * (1.f - ay) + (r1[0] * (1.f - ax) + r1[1] * ax) * ay;
  }

  /**
   * @brief The highest height that a sample anywhere in `rect` can return: the largest texel of the cells it
   * touches (a bilinear sample is a convex combination of its cell's corners), from a table of block maxima.
   */
  float maxOver(const WorldRect& rect) const {
    const auto block = [&](double v_m, double origin_m, int blocks) {
      const double cell = std::floor((v_m - origin_m) / texel_m_);
      return static_cast<int>(std::clamp(cell, 0.0, static_cast<double>(blocks * kBlock - 1))) / kBlock;
    };
    const int bi0 = block(rect.x_min_m, x0_m_, blocks_x_), bi1 = block(rect.x_max_m, x0_m_, blocks_x_);
    const int bj0 = block(rect.y_min_m, y0_m_, blocks_y_), bj1 = block(rect.y_max_m, y0_m_, blocks_y_);
    float highest = -std::numeric_limits<float>::infinity();
    for (int bj = bj0; bj <= bj1; ++bj)
      for (int bi = bi0; bi <= bi1; ++bi) highest = std::max(highest, block_max_[bj * blocks_x_ + bi]);
    return highest;
  }

 private:
  static constexpr int kBlock = 8;  ///< cells a side of a block of the maxima table

  void buildBlockMaxima() {
    // Block (bi, bj) covers cells [bi * kBlock, (bi + 1) * kBlock) and so texels up to one beyond (the cells'
    // far corners); a clamped sample lies in a border cell, which its block covers too.
    blocks_x_ = std::max(1, (texels_.cols - 1 + kBlock - 1) / kBlock);
    blocks_y_ = std::max(1, (texels_.rows - 1 + kBlock - 1) / kBlock);
    block_max_.assign(static_cast<size_t>(blocks_x_ * blocks_y_), -std::numeric_limits<float>::infinity());
    for (int j = 0; j < texels_.rows; ++j) {
      const float* row = texels_[j];
      for (int i = 0; i < texels_.cols; ++i)
        for (int bj = std::max(0, (j - 1) / kBlock); bj <= std::min(blocks_y_ - 1, j / kBlock); ++bj)
          for (int bi = std::max(0, (i - 1) / kBlock); bi <= std::min(blocks_x_ - 1, i / kBlock); ++bi) {
            float& m = block_max_[bj * blocks_x_ + bi];
            m = std::max(m, row[i]);
          }
    }
  }

  cv::Mat_<float> texels_;
  double x0_m_, y0_m_, texel_m_, per_m_;
  int cols_, rows_;  // of the patch
  int blocks_x_ = 0, blocks_y_ = 0;
  std::vector<float> block_max_;
};

}  // namespace

bool SeabedRenderer::isSupportedEncoding(const std::string& e) {
  return e == "bgr8" || e == "rgb8" || e == "mono8" || e == "mono16" || e == "bayer_rggb8";
}

SeabedRenderer::SeabedRenderer(const exocet_common::CameraModel& camera, const ImagingConfig& imaging, SeabedTexture* texture,
                               SeabedRelief* relief, std::vector<Landmark> landmarks, uint64_t seed,
                               double reference_altitude_m)
    : camera_(camera),
      imaging_(imaging),
      texture_(texture),
      relief_(relief),
      landmarks_(std::move(landmarks)),
      seed_(seed),
      reference_altitude_m_(reference_altitude_m) {
  std::string problem = camera_.validate();
  if (problem.empty()) problem = imaging_.validate();
  if (!problem.empty()) throw std::invalid_argument(problem);
  if (!texture_ || !relief_) throw std::invalid_argument("renderer needs a texture and a relief");
  rays_ = camera_.rayMap();
  vignette_.create(camera_.height, camera_.width, CV_32F);
  pixel_angle_.create(camera_.height, camera_.width, CV_32F);
  const double f = std::sqrt(camera_.fx * camera_.fy);
  for (int v = 0; v < camera_.height; ++v)
    for (int u = 0; u < camera_.width; ++u) {
      const cv::Vec2f r = rays_.at<cv::Vec2f>(v, u);
      const double n2 = 1.0 + r[0] * r[0] + r[1] * r[1];
      const double cos4 = 1.0 / (n2 * n2);
      vignette_.at<float>(v, u) = static_cast<float>(1.0 - imaging_.vignetting * (1.0 - cos4));
      pixel_angle_.at<float>(v, u) = static_cast<float>(1.0 / (f * n2));  // ~ cos^2(theta) / f
    }
  // A table of standard normal samples: the image noise draws from it with random indices (fast, exact marginal).
  RandomStream table_rng(0x6A55u, 1);
  gaussian_table_.resize(1 << 16);
  for (float& g : gaussian_table_) g = static_cast<float>(table_rng.gaussian());
}

cv::Mat SeabedRenderer::renderRadiance(const Eigen::Isometry3d& world_from_camera, double t_s, int frame_index,
                                       cv::Mat* depth_z_m) const {
  (void)frame_index;
  const int W = camera_.width, H = camera_.height;
  FrameGeometry g;
  g.R = world_from_camera.rotation().cast<float>();
  g.C = world_from_camera.translation();
  imaging_.waterAt(t_s, &g.turbidity, &g.light_gain);
  g.lamp = g.R * Eigen::Vector3f(static_cast<float>(imaging_.light_offset_m[0]),
                                 static_cast<float>(imaging_.light_offset_m[1]),
                                 static_cast<float>(imaging_.light_offset_m[2]));
  // The lamp is aimed at the point of the reference plane the camera looks at from the nominal altitude.
  const Eigen::Vector3f aim = g.R * Eigen::Vector3f(0, 0, static_cast<float>(reference_altitude_m_));
  g.lamp_axis = (aim - g.lamp).normalized();

  const double h_max = relief_->maxHeight_m(), h_min = relief_->minHeight_m();
  if (g.C.z() <= h_max + 0.05)
    throw std::runtime_error("camera at height " + std::to_string(g.C.z()) + " m is not above the seabed (max " +
                             std::to_string(h_max) + " m)");

  // Footprint of the image on the seabed, from border rays at the highest and lowest seabed: the patches to fetch.
  WorldRect area{1e300, 1e300, -1e300, -1e300};
  double min_footprint = 1e300, max_footprint = 0.0;
  auto visit = [&](int u, int v) {
    const cv::Vec2f r = rays_.at<cv::Vec2f>(v, u);
    const Eigen::Vector3d d = (g.R * Eigen::Vector3f(r[0], r[1], 1.0f)).cast<double>();
    if (d.z() > -0.05 * d.norm())
      throw std::runtime_error("pixel (" + std::to_string(u) + ", " + std::to_string(v) +
                               ") looks at the horizon: the camera must look down at the seabed");
    for (double h : {h_min, h_max}) {
      const double t = (g.C.z() - h) / -d.z();
      const Eigen::Vector3d p = g.C + t * d;
      area.x_min_m = std::min(area.x_min_m, p.x());
      area.x_max_m = std::max(area.x_max_m, p.x());
      area.y_min_m = std::min(area.y_min_m, p.y());
      area.y_max_m = std::max(area.y_max_m, p.y());
      const double footprint = t * d.norm() * pixel_angle_.at<float>(v, u) / (-d.z() / d.norm());
      min_footprint = std::min(min_footprint, footprint);
      max_footprint = std::max(max_footprint, footprint);
    }
  };
  for (int u = 0; u < W; u += 16) {
    visit(u, 0);
    visit(u, H - 1);
  }
  for (int v = 0; v < H; v += 16) {
    visit(0, v);
    visit(W - 1, v);
  }
  visit(W - 1, H - 1);
  visit(W / 2, H / 2);

  const double texel0 = texture_->baseTexelSize_m();
  const int max_level = texture_->maxLevel();
  // Relief slopes shrink footprints (steep faces seen obliquely grow them): widen the level range a little.
  const int level_lo = std::clamp(static_cast<int>(std::floor(std::log2(std::max(min_footprint * 0.7, texel0) / texel0))), 0, max_level);
  const int level_hi = std::clamp(static_cast<int>(std::floor(std::log2(std::max(max_footprint * 2.0, texel0) / texel0))) + 1, 0, max_level);
  const double margin = 8.0 * texel0 * std::pow(2.0, level_hi) + 0.05;
  area.x_min_m -= margin;
  area.y_min_m -= margin;
  area.x_max_m += margin;
  area.y_max_m += margin;
  std::vector<TextureWindow<cv::Vec3f>> levels;
  for (int L = level_lo; L <= level_hi; ++L) levels.push_back(texture_->albedoWindow(L, area));
  const bool flat = relief_->isFlat();
  TexturePatch<float> height_patch;
  if (!flat) height_patch = relief_->heightPatch(area);
  const HeightSampler heights(height_patch);
  const float slope_bound = static_cast<float>(relief_->maxSlope() * 1.5 + 1e-3);
  const float grid = static_cast<float>(relief_->gridSpacing_m());

  // Landmarks in view.
  std::vector<Landmark> marks;
  for (const Landmark& m : landmarks_)
    if (m.x_m + m.size_m > area.x_min_m && m.x_m - m.size_m < area.x_max_m && m.y_m + m.size_m > area.y_min_m &&
        m.y_m - m.size_m < area.y_max_m)
      marks.push_back(m);

  const float h_ref = static_cast<float>(reference_altitude_m_);
  const float strength = static_cast<float>(imaging_.light_cone_strength);
  const float half_angle = static_cast<float>(imaging_.light_half_angle_deg * M_PI / 180.0);
  const float beam_k = std::log(2.0f) / (half_angle * half_angle);
  float c[3], veil[3];
  for (int k = 0; k < 3; ++k) {
    c[k] = static_cast<float>(imaging_.attenuation_per_m[k] * g.turbidity);
    veil[k] = static_cast<float>(imaging_.backscatter * imaging_.backscatter_colour[k] * g.turbidity);
  }
  // Normalisation: clear water, green channel, light path (lamp + camera) at the nominal altitude transmits 1.
  const float path_ref = h_ref * (1.0f + strength);
  const float c_ref = static_cast<float>(imaging_.attenuation_per_m[1]);
  const float light_gain = static_cast<float>(g.light_gain);
  const float veil_light = 1.0f - strength + strength * light_gain;
  const bool attenuating = c[0] > 0.0f || c[1] > 0.0f || c[2] > 0.0f || veil[0] > 0.0f || veil[1] > 0.0f || veil[2] > 0.0f;

  cv::Mat radiance(H, W, CV_32FC3);
  cv::Mat depth(H, W, CV_32F);
  const float Cx = 0.0f, Cy = 0.0f;  // rows work relative to the camera centre for float precision
  const double Cz = g.C.z();
  const double ox = g.C.x(), oy = g.C.y();
  const int n_levels = static_cast<int>(levels.size());

  // Where each block of pixels starts marching: the highest point of the relief under its rays' paths between the
  // global highest and lowest heights, rather than the global highest. The conservative steps converge
  // geometrically, so starting a few centimetres above the local surface instead of decimetres saves most of them.
  constexpr int kPixelBlock = 16;
  const int blocks_u = (W + kPixelBlock - 1) / kPixelBlock, blocks_v = (H + kPixelBlock - 1) / kPixelBlock;
  std::vector<double> start_height_m(static_cast<size_t>(blocks_u * blocks_v), h_max);
  if (!flat) {
    for (int bv = 0; bv < blocks_v; ++bv)
      for (int bu = 0; bu < blocks_u; ++bu) {
        const int u0 = bu * kPixelBlock, u1 = std::min(W - 1, u0 + kPixelBlock - 1);
        const int v0 = bv * kPixelBlock, v1 = std::min(H - 1, v0 + kPixelBlock - 1);
        WorldRect paths{1e300, 1e300, -1e300, -1e300};
        for (const int u : {u0, (u0 + u1) / 2, u1})
          for (const int v : {v0, (v0 + v1) / 2, v1}) {
            const cv::Vec2f r = rays_.at<cv::Vec2f>(v, u);
            const Eigen::Vector3f d = g.R * Eigen::Vector3f(r[0], r[1], 1.0f);
            for (const double h : {h_min, h_max}) {
              const double t = std::max(0.0, (Cz - h) / -d.z());
              paths.x_min_m = std::min(paths.x_min_m, ox + t * d.x());
              paths.x_max_m = std::max(paths.x_max_m, ox + t * d.x());
              paths.y_min_m = std::min(paths.y_min_m, oy + t * d.y());
              paths.y_max_m = std::max(paths.y_max_m, oy + t * d.y());
            }
          }
        // The block's inner rays run between its border rays (the lens maps smoothly); the margin covers the
        // bilinear support and any bulge of distortion over 16 pixels.
        const double margin_m = 2.0 * grid + 0.01;
        paths.x_min_m -= margin_m;
        paths.y_min_m -= margin_m;
        paths.x_max_m += margin_m;
        paths.y_max_m += margin_m;
        // 10 um above: float rounding of a bilinear sample may exceed its corners by an ulp.
        start_height_m[bv * blocks_u + bu] = std::min(h_max, static_cast<double>(heights.maxOver(paths)) + 1e-5);
      }
  }

  // Each row in two passes: the rays' hits first, the texture and the light second. The texels a row samples are
  // scattered over tiles (the image rows cross the texture's rows at the heading's angle), so each sample would wait
  // for memory; the first pass asks for them as it finds the hits, and they have arrived when the second needs them.
  std::vector<PixelHit> hits(static_cast<size_t>(W));
  for (int v = 0; v < H; ++v) {
    const cv::Vec2f* ray = rays_.ptr<cv::Vec2f>(v);
    const float* ang = pixel_angle_.ptr<float>(v);
    const float* vig = vignette_.ptr<float>(v);
    cv::Vec3f* out = radiance.ptr<cv::Vec3f>(v);
    float* dep = depth.ptr<float>(v);
    for (int u = 0; u < W; ++u) {
      PixelHit& hit = hits[static_cast<size_t>(u)];
      const Eigen::Vector3f d_cam(ray[u][0], ray[u][1], 1.0f);
      const Eigen::Vector3f d = g.R * d_cam;
      const float d_norm = d.norm();
      // Ray-seabed intersection: closed form on the plane, conservative marching on the relief (never overshoots
      // a slope below the bound, so the first surface hit is found: occlusions are right).
      double t;
      Eigen::Vector3f n(0, 0, 1);
      double px, py;
      if (flat) {
        t = Cz / -d.z();
        px = ox + t * d.x();
        py = oy + t * d.y();
      } else {
        t = std::max(0.0, (Cz - start_height_m[(v / kPixelBlock) * blocks_u + u / kPixelBlock]) / -d.z());
        const double denom = -d.z() + slope_bound * std::hypot(d.x(), d.y());
        for (int it = 0; it < 200; ++it) {
          px = ox + t * d.x();
          py = oy + t * d.y();
          const double f = Cz + t * d.z() - heights(px, py);
          if (f < 2e-3) break;
          t += f / denom;
        }
        // Within 2 mm above the surface the conservative steps crawl: finish with Newton steps on the local slope
        // (the surface ahead is the first one hit; a step that would go back up is not taken).
        for (int it = 0; it < 6; ++it) {
          px = ox + t * d.x();
          py = oy + t * d.y();
          float gx, gy;
          const double f = Cz + t * d.z() - heights.sample(px, py, &gx, &gy);
          if (std::abs(f) < 1e-5) break;
          const double slope = d.z() - gx * d.x() - gy * d.y();
          if (slope > -1e-6) break;
          t -= f / slope;
        }
        px = ox + t * d.x();
        py = oy + t * d.y();
        const float hx = heights(px + grid, py) - heights(px - grid, py);
        const float hy = heights(px, py + grid) - heights(px, py - grid);
        n = Eigen::Vector3f(-hx / (2 * grid), -hy / (2 * grid), 1.0f).normalized();
      }
      const float range = static_cast<float>(t) * d_norm;
      dep[u] = static_cast<float>(t);  // d_cam has z = 1, so t is the depth along the optical axis
      const Eigen::Vector3f d_unit = d / d_norm;
      const float cos_incidence = std::max(0.25f, std::abs(d_unit.dot(n)));
      const float footprint = range * ang[u] / cos_incidence;
      const float lambda = std::log2(std::max(footprint, 1e-6f) / static_cast<float>(texel0));
      const float lf = std::max(0.0f, lambda - static_cast<float>(level_lo));
      hit.i0 = std::min(static_cast<int>(lf), n_levels - 1);
      hit.i1 = std::min(hit.i0 + 1, n_levels - 1);
      hit.w1 = hit.i1 == hit.i0 ? 0.0f : std::min(1.0f, lf - hit.i0);
      levels[hit.i0].prefetch(px, py);
      if (hit.w1 > 0.0f) levels[hit.i1].prefetch(px, py);
      hit.px = px;
      hit.py = py;
      hit.t = t;
      hit.d = d;
      hit.n = n;
      hit.range = range;
      hit.footprint = footprint;
    }
    for (int u = 0; u < W; ++u) {
      const PixelHit& hit = hits[static_cast<size_t>(u)];
      const double px = hit.px, py = hit.py, t = hit.t;
      const Eigen::Vector3f& d = hit.d;
      const Eigen::Vector3f& n = hit.n;
      const float range = hit.range, footprint = hit.footprint;
      // Trilinear texture sample.
      cv::Vec3f albedo = levels[hit.i0].sample(px, py);
      if (hit.w1 > 0.0f) albedo = albedo * (1.0f - hit.w1) + levels[hit.i1].sample(px, py) * hit.w1;

      for (const Landmark& m : marks) {
        const float dx = static_cast<float>(px - m.x_m), dy = static_cast<float>(py - m.y_m);
        const float half = static_cast<float>(m.size_m * 0.5);
        if (std::abs(dx) >= half || std::abs(dy) >= half) continue;
        // Anti-aliased saddle: product of two ramps one footprint wide; its centre is exact by symmetry.
        const float w = std::max(footprint, 1e-5f);
        const float q = smoothClamp(dx / w) * smoothClamp(dy / w);
        const float edge = std::min(1.0f, std::min(half - std::abs(dx), half - std::abs(dy)) / w);
        const float value = 0.45f + 0.40f * q;
        albedo = albedo * (1.0f - edge) + cv::Vec3f(value, value, value) * edge;
      }

      // Light: ambient from above plus the lamp's beam, attenuated on both paths; backscatter veils with range.
      const Eigen::Vector3f p_rel(static_cast<float>(px - ox) + Cx, static_cast<float>(py - oy) + Cy,
                                  static_cast<float>(Cz + t * d.z() - Cz));
      float irradiance = (1.0f - strength) * std::max(0.0f, n.z());
      float lamp_path = 0.0f;
      if (strength > 0.0f) {
        const Eigen::Vector3f to_lamp = g.lamp - p_rel;
        lamp_path = to_lamp.norm();
        const Eigen::Vector3f l = to_lamp / lamp_path;
        // theta^2 from cos(theta) by its series (2 (1 - c) (1 + (1 - c) / 3)): within 1% up to 60 deg, no acos.
        const float one_minus_cos = 1.0f - std::min(1.0f, std::max(-1.0f, -l.dot(g.lamp_axis)));
        const float off_axis2 = 2.0f * one_minus_cos * (1.0f + one_minus_cos / 3.0f);
        const float beam = std::exp(-beam_k * off_axis2);
        const float ratio = h_ref / lamp_path;
        irradiance += strength * light_gain * beam * std::max(0.0f, n.dot(l)) * ratio * ratio;
      }
      cv::Vec3f value;
      if (attenuating) {
        for (int k = 0; k < 3; ++k) {
          const float transmission = std::exp(-c[k] * (range + strength * lamp_path) + c_ref * path_ref);
          const float backscatter = veil[k] * (1.0f - std::exp(-c[k] * range)) * veil_light;
          value[k] = vig[u] * (albedo[k] * irradiance * transmission + backscatter);
        }
      } else {
        value = albedo * (vig[u] * irradiance);
      }
      out[u] = value;
    }
  }
  if (imaging_.marine_snow_per_m3 > 0.0) addMarineSnow(world_from_camera, t_s, depth, &radiance);
  if (depth_z_m) *depth_z_m = depth;
  return radiance;
}

void SeabedRenderer::addMarineSnow(const Eigen::Isometry3d& world_from_camera, double t_s, const cv::Mat& depth_z_m,
                                   cv::Mat* radiance) const {
  // Particles are fixed in water that sinks slowly: cells of 1 m^3 of that water each hold a Poisson number of
  // particles drawn from the cell's own hash, so the snow is the same whatever was rendered before.
  const double sink = imaging_.marine_snow_sink_mps * t_s;
  const Eigen::Isometry3d camera_from_world = world_from_camera.inverse();
  const Eigen::Vector3d C = world_from_camera.translation();
  double max_depth = 0.0;
  cv::minMaxLoc(depth_z_m, nullptr, &max_depth);
  const double reach = std::min(max_depth, 6.0);
  const double half_w = reach * 0.5 * camera_.width / camera_.fx * 1.2 + 0.5;
  const double half_h = reach * 0.5 * camera_.height / camera_.fy * 1.2 + 0.5;
  const double radius = std::hypot(half_w, half_h);
  const long x0 = static_cast<long>(std::floor(C.x() - radius)), x1 = static_cast<long>(std::floor(C.x() + radius));
  const long y0 = static_cast<long>(std::floor(C.y() - radius)), y1 = static_cast<long>(std::floor(C.y() + radius));
  const long z0 = static_cast<long>(std::floor(C.z() - reach + sink)), z1 = static_cast<long>(std::floor(C.z() + sink));
  const float strength = static_cast<float>(imaging_.light_cone_strength);
  float tint[3];
  for (int k = 0; k < 3; ++k) tint[k] = static_cast<float>(std::exp(-imaging_.attenuation_per_m[k] * 1.0));
  double turbidity = 1, light_gain = 1;
  imaging_.waterAt(t_s, &turbidity, &light_gain);
  const double f = std::sqrt(camera_.fx * camera_.fy);
  for (long cx = x0; cx <= x1; ++cx)
    for (long cy = y0; cy <= y1; ++cy)
      for (long cz = z0; cz <= z1; ++cz) {
        RandomStream rng(hashKeys(seed_ ^ 0x5A0Bu, static_cast<uint64_t>(cx), static_cast<uint64_t>(cy),
                                  static_cast<uint64_t>(cz)));
        const int count = rng.poisson(imaging_.marine_snow_per_m3 * turbidity);
        for (int i = 0; i < count; ++i) {
          const Eigen::Vector3d p(cx + rng.uniform(), cy + rng.uniform(), cz + rng.uniform() - sink);
          const double size = imaging_.marine_snow_size_m * (0.5 + rng.uniform());
          const double bright = imaging_.marine_snow_brightness * (0.5 + rng.uniform());
          const Eigen::Vector3d pc = camera_from_world * p;
          if (pc.z() < 0.15) continue;
          Eigen::Vector2d pix;
          if (!camera_.project(pc, &pix)) continue;
          const int u = static_cast<int>(std::lround(pix.x())), v = static_cast<int>(std::lround(pix.y()));
          if (u < -8 || v < -8 || u >= camera_.width + 8 || v >= camera_.height + 8) continue;
          const int uc = std::clamp(u, 0, camera_.width - 1), vc = std::clamp(v, 0, camera_.height - 1);
          if (pc.z() >= depth_z_m.at<float>(vc, uc)) continue;  // behind the seabed
          // Lit by the lamp (closer is brighter) or by the ambient light; a Gaussian blob of the particle's size.
          const double lamp_ratio = reference_altitude_m_ / std::max(0.2, pc.norm());
          const float lit = static_cast<float>(bright * ((1.0 - strength) + strength * light_gain * std::min(4.0, lamp_ratio * lamp_ratio)));
          const double sigma_px = std::max(0.5, 0.5 * size * f / pc.z());
          const int reach_px = static_cast<int>(std::ceil(3 * sigma_px));
          for (int dv = -reach_px; dv <= reach_px; ++dv)
            for (int du = -reach_px; du <= reach_px; ++du) {
              const int uu = u + du, vv = v + dv;
              if (uu < 0 || vv < 0 || uu >= camera_.width || vv >= camera_.height) continue;
              const double ex = uu - pix.x(), ey = vv - pix.y();
              const float w = static_cast<float>(std::exp(-(ex * ex + ey * ey) / (2 * sigma_px * sigma_px)));
              cv::Vec3f& px = radiance->at<cv::Vec3f>(vv, uu);
              for (int k = 0; k < 3; ++k) px[k] = px[k] * (1.0f - 0.8f * w) + 0.8f * w * lit * tint[k];
            }
        }
      }
}

cv::Mat SeabedRenderer::encode(const cv::Mat& radiance_rgb, int frame_index, const std::string& encoding) const {
  if (!isSupportedEncoding(encoding))
    throw std::invalid_argument("image encoding '" + encoding + "' is not one of bgr8, rgb8, mono8, mono16, bayer_rggb8");
  const int H = radiance_rgb.rows, W = radiance_rgb.cols;
  const bool wide = encoding == "mono16";
  const float full_scale = wide ? 65535.0f : 255.0f;
  const float dn_scale = full_scale / 255.0f;  // noise is specified in 8-bit DN
  const float inv_gamma = static_cast<float>(1.0 / imaging_.gamma);
  const float gain = static_cast<float>(imaging_.exposure_gain);
  const float read2 = static_cast<float>(imaging_.noise_sigma_dn * imaging_.noise_sigma_dn);
  const float shot = static_cast<float>(imaging_.shot_noise_dn);
  const bool noisy = read2 > 0.0f || shot > 0.0f;
  // Camera response through a table (4096 steps, linear between): pow() per sample would dominate encoding.
  constexpr int kSteps = 4096;
  std::vector<float> response(kSteps + 2);
  for (int i = 0; i <= kSteps + 1; ++i)
    response[i] = 255.0f * std::pow(std::min(1.0f, static_cast<float>(i) / kSteps), inv_gamma);
  cv::Mat rgb(H, W, wide ? CV_16UC3 : CV_8UC3);
  const uint64_t frame_key = hashKeys(seed_, 0x1A6E, static_cast<uint64_t>(frame_index));
  for (int v = 0; v < H; ++v) {
    RandomStream rng(frame_key, static_cast<uint64_t>(v));
    uint64_t bits = 0;
    int bits_left = 0;
    const cv::Vec3f* in = radiance_rgb.ptr<cv::Vec3f>(v);
    for (int u = 0; u < W; ++u)
      for (int k = 0; k < 3; ++k) {
        const float x = std::min(1.0f, std::max(0.0f, gain * in[u][k])) * kSteps;
        const int i = static_cast<int>(x);
        float value_dn = response[i] + (x - i) * (response[i + 1] - response[i]);
        if (noisy) {
          if (bits_left == 0) {
            bits = rng.next();
            bits_left = 4;
          }
          const float z = gaussian_table_[bits & 0xFFFF];
          bits >>= 16;
          --bits_left;
          value_dn += z * std::sqrt(read2 + shot * value_dn);
        }
        const float out = std::min(full_scale, std::max(0.0f, std::nearbyint(value_dn * dn_scale)));
        if (wide)
          rgb.ptr<cv::Vec3w>(v)[u][k] = static_cast<uint16_t>(out);
        else
          rgb.ptr<cv::Vec3b>(v)[u][k] = static_cast<uint8_t>(out);
      }
  }
  cv::Mat result;
  if (encoding == "rgb8") {
    result = rgb;
  } else if (encoding == "bgr8") {
    cv::cvtColor(rgb, result, cv::COLOR_RGB2BGR);
  } else if (encoding == "mono8" || encoding == "mono16") {
    cv::cvtColor(rgb, result, cv::COLOR_RGB2GRAY);
  } else {  // bayer_rggb8: keep the channel each photosite sees
    result.create(H, W, CV_8UC1);
    for (int v = 0; v < H; ++v)
      for (int u = 0; u < W; ++u) {
        const int channel = (v % 2 == 0) ? (u % 2 == 0 ? 0 : 1) : (u % 2 == 0 ? 1 : 2);
        result.at<uint8_t>(v, u) = rgb.at<cv::Vec3b>(v, u)[channel];
      }
  }
  return result;
}

cv::Mat SeabedRenderer::render(const std::function<Eigen::Isometry3d(double)>& pose_at, double t_s, int frame_index,
                               const std::string& encoding) const {
  if (!isSupportedEncoding(encoding))
    throw std::invalid_argument("image encoding '" + encoding + "' is not one of bgr8, rgb8, mono8, mono16, bayer_rggb8");
  cv::Mat radiance;
  if (imaging_.motion_blur_exposure_s > 0.0) {
    const int n = imaging_.motion_blur_samples;
    for (int i = 0; i < n; ++i) {
      const double ts = t_s + imaging_.motion_blur_exposure_s * (static_cast<double>(i) / (n - 1) - 0.5);
      cv::Mat sub = renderRadiance(pose_at(ts), ts, frame_index);
      if (radiance.empty())
        radiance = sub / n;
      else
        radiance += sub / n;
    }
  } else {
    radiance = renderRadiance(pose_at(t_s), t_s, frame_index);
  }
  return encode(radiance, frame_index, encoding);
}

}  // namespace sim
}  // namespace exocet_mosaic
