#include "exocet_servo/sim/vent_renderer.h"

#include "exocet_servo/vision/depth_lookup.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <sstream>
#include <stdexcept>

#include <opencv2/imgproc.hpp>

namespace exocet_servo {
namespace sim {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kMinT = 1e-6;

/// Procedural albedo in [0.08, 0.95]: multi-scale value noise, blobs (pebbles, bacterial mats) and dark cracks, so
/// that corners and blobs exist at every scale.
cv::Mat makeTexture(int width, int height, std::mt19937* rng) {
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  cv::Mat tex(height, width, CV_32FC1, cv::Scalar(0.0));
  const int cells[] = {96, 48, 24, 12, 6, 3};
  const float amplitudes[] = {0.12f, 0.15f, 0.20f, 0.25f, 0.20f, 0.12f};
  for (int k = 0; k < 6; ++k) {
    cv::Mat small(height / cells[k] + 2, width / cells[k] + 2, CV_32FC1);
    for (int r = 0; r < small.rows; ++r)
      for (int c = 0; c < small.cols; ++c) small.at<float>(r, c) = 2.0f * unit(*rng) - 1.0f;
    cv::Mat up;
    cv::resize(small, up, cv::Size(width, height), 0, 0, cv::INTER_CUBIC);
    tex += amplitudes[k] * up;
  }
  const int blobs = width * height / 120;
  for (int i = 0; i < blobs; ++i) {
    const cv::Point2f centre(unit(*rng) * width, unit(*rng) * height);
    const float a = 1.5f + 10.0f * unit(*rng) * unit(*rng), b = a * (0.4f + 0.6f * unit(*rng));
    const double value = unit(*rng) < 0.5 ? -0.7 + 0.4 * unit(*rng) : 0.3 + 0.4 * unit(*rng);
    cv::ellipse(tex, cv::RotatedRect(centre, cv::Size2f(2 * a, 2 * b), 360.0f * unit(*rng)), cv::Scalar(value), -1,
                cv::LINE_AA);
  }
  const int cracks = std::max(1, width * height / 5000);
  for (int i = 0; i < cracks; ++i) {
    cv::Point2f p(unit(*rng) * width, unit(*rng) * height);
    float heading = 6.2832f * unit(*rng);
    const int segments = 4 + static_cast<int>(12 * unit(*rng));
    for (int s = 0; s < segments; ++s) {
      heading += 0.8f * (unit(*rng) - 0.5f);
      const cv::Point2f q = p + (4.0f + 12.0f * unit(*rng)) * cv::Point2f(std::cos(heading), std::sin(heading));
      cv::line(tex, p, q, cv::Scalar(-0.9), unit(*rng) < 0.7 ? 1 : 2, cv::LINE_AA);
      p = q;
    }
  }
  cv::GaussianBlur(tex, tex, cv::Size(0, 0), 0.8);
  // Mean +- 2 sigma to [0.08, 0.95], clamped: the rare extremes (cracks) must not flatten the rest.
  cv::Scalar mean, stddev;
  cv::meanStdDev(tex, mean, stddev);
  const double lo = mean[0] - 2.0 * stddev[0], span = std::max(1e-9, 4.0 * stddev[0]);
  tex.convertTo(tex, CV_32FC1, 0.87 / span, 0.08 - 0.87 * lo / span);
  cv::min(cv::max(tex, 0.08), 0.95, tex);
  return tex;
}

std::vector<cv::Mat> mipmaps(const cv::Mat& level0) {
  std::vector<cv::Mat> levels{level0};
  while (levels.size() < 10 && std::min(levels.back().cols, levels.back().rows) >= 16) {
    cv::Mat down;
    cv::pyrDown(levels.back(), down);
    levels.push_back(down);
  }
  return levels;
}

/// Bilinear sample with clamped borders; (u, v) in texels of the level.
float bilinear(const cv::Mat& tex, double u, double v) {
  u = std::clamp(u, 0.0, tex.cols - 1.001);
  v = std::clamp(v, 0.0, tex.rows - 1.001);
  const int x = static_cast<int>(u), y = static_cast<int>(v);
  const float fx = static_cast<float>(u - x), fy = static_cast<float>(v - y);
  const float* r0 = tex.ptr<float>(y);
  const float* r1 = tex.ptr<float>(y + 1);
  return (1 - fy) * ((1 - fx) * r0[x] + fx * r0[x + 1]) + fy * ((1 - fx) * r1[x] + fx * r1[x + 1]);
}

/// Trilinear mip-mapped sample; (u, v) in level-0 texels, footprint in level-0 texels.
float sampleMip(const std::vector<cv::Mat>& mips, double u, double v, double footprint_texels) {
  const double level = std::clamp(std::log2(std::max(1.0, footprint_texels)), 0.0, mips.size() - 1.0);
  const int l0 = static_cast<int>(level);
  const int l1 = std::min<int>(l0 + 1, static_cast<int>(mips.size()) - 1);
  const double f = level - l0;
  // pyrDown maps texel centre i of level l+1 to 2i of level l.
  const double s0 = std::ldexp(1.0, -l0), s1 = std::ldexp(1.0, -l1);
  const float a = bilinear(mips[l0], u * s0, v * s0);
  if (f < 1e-3 || l1 == l0) return a;
  return static_cast<float>((1 - f) * a + f * bilinear(mips[l1], u * s1, v * s1));
}

}  // namespace

std::string VentSceneConfig::validate() const {
  std::ostringstream errors;
  auto check = [&errors](bool ok, const char* field, const std::string& range) {
    if (ok) return;
    if (errors.tellp() > 0) errors << "; ";
    errors << field << " must be in " << range;
  };
  check(base_m.allFinite(), "base_m", "finite vectors");
  check(height_m > 0.0 && height_m <= 100.0, "height_m", "(0, 100]");
  check(base_radius_m > 0.0 && base_radius_m <= 100.0, "base_radius_m", "(0, 100]");
  check(top_radius_m > 0.0 && top_radius_m <= 100.0, "top_radius_m", "(0, 100]");
  check(seabed_half_size_m > 0.0 && seabed_half_size_m <= 1000.0, "seabed_half_size_m", "(0, 1000]");
  check(chimney_texel_m >= 1e-5 && chimney_texel_m <= 0.1, "chimney_texel_m", "[1e-5, 0.1]");
  check(seabed_texel_m >= 1e-5 && seabed_texel_m <= 1.0, "seabed_texel_m", "[1e-5, 1]");
  // Texture sizes: keep each below ~50 Mtexels.
  check(seabed_half_size_m / seabed_texel_m <= 3500.0, "seabed_half_size_m / seabed_texel_m", "(0, 3500]");
  check(M_PI * (base_radius_m + top_radius_m) / chimney_texel_m <= 8000.0 && height_m / chimney_texel_m <= 8000.0,
        "chimney size / chimney_texel_m", "(0, 8000] texels per side");
  check(supersampling >= 1 && supersampling <= 8, "supersampling", "[1, 8]");
  check(attenuation_per_m >= 0.0 && attenuation_per_m <= 100.0, "attenuation_per_m", "[0, 100]");
  check(water_gray >= 0.0 && water_gray <= 255.0, "water_gray", "[0, 255]");
  return errors.str();
}

bool RenderedView::smoothDepthAt(const Eigen::Vector2d& px, int radius_px, double max_relative_step,
                                 double* depth) const {
  return vision::screenedDepthAt(depth_m, px, radius_px, max_relative_step, depth);
}

VentRenderer::VentRenderer(const VentSceneConfig& config) : config_(config) {
  const std::string errors = config.validate();
  if (!errors.empty()) throw std::invalid_argument("VentSceneConfig: " + errors);
  std::mt19937 rng(config.seed);
  const double mean_radius = 0.5 * (config.base_radius_m + config.top_radius_m);
  const int chimney_w = std::max(16, static_cast<int>(std::lround(2.0 * M_PI * mean_radius / config.chimney_texel_m)));
  const int chimney_h = std::max(16, static_cast<int>(std::lround(config.height_m / config.chimney_texel_m)));
  chimney_mips_ = mipmaps(makeTexture(chimney_w, chimney_h, &rng));
  const int seabed_n =
      std::max(16, static_cast<int>(std::lround(2.0 * config.seabed_half_size_m / config.seabed_texel_m)));
  seabed_mips_ = mipmaps(makeTexture(seabed_n, seabed_n, &rng));
  light_w_ = Eigen::Vector3d(0.5, 0.3, 0.8).normalized();
}

VentRenderer::Hit VentRenderer::cast(const Eigen::Vector3d& o, const Eigen::Vector3d& d) const {
  const VentSceneConfig& c = config_;
  Hit best;
  best.t = kInf;
  // Chimney side: (x - bx)^2 + (y - by)^2 = (r0 + s (z - zb))^2 for z in [zb, zb + H].
  const double s = (c.top_radius_m - c.base_radius_m) / c.height_m;
  const double dx = o.x() - c.base_m.x(), dy = o.y() - c.base_m.y(), w = o.z() - c.base_m.z();
  const double rw = c.base_radius_m + s * w;
  const double a = d.x() * d.x() + d.y() * d.y() - s * s * d.z() * d.z();
  const double b = 2.0 * (dx * d.x() + dy * d.y() - s * rw * d.z());
  const double cc = dx * dx + dy * dy - rw * rw;
  auto try_side = [&](double t) {
    if (!(t > kMinT) || t >= best.t) return;
    const double h = w + t * d.z();
    if (h < 0.0 || h > c.height_m) return;
    best.t = t;
    best.kind = SurfaceKind::kChimney;
  };
  if (std::abs(a) > 1e-12) {
    const double disc = b * b - 4.0 * a * cc;
    if (disc >= 0.0) {
      const double sq = std::sqrt(disc);
      try_side((-b - sq) / (2.0 * a));
      try_side((-b + sq) / (2.0 * a));
    }
  } else if (std::abs(b) > 1e-12) {
    try_side(-cc / b);
  }
  if (std::abs(d.z()) > 1e-12) {
    const double t_top = (c.height_m - w) / d.z();
    if (t_top > kMinT && t_top < best.t) {
      const double x = dx + t_top * d.x(), y = dy + t_top * d.y();
      if (x * x + y * y <= c.top_radius_m * c.top_radius_m) {
        best.t = t_top;
        best.kind = SurfaceKind::kTop;
      }
    }
    if (c.draw_seabed) {
      const double t_bed = -w / d.z();
      if (t_bed > kMinT && t_bed < best.t) {
        best.t = t_bed;
        best.kind = SurfaceKind::kSeabed;
      }
    }
  }
  return best;
}

double VentRenderer::shade(const Eigen::Vector3d& p, SurfaceKind kind, const Eigen::Vector3d& d,
                           double footprint_m) const {
  const VentSceneConfig& c = config_;
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  double albedo = 0.5;
  const Eigen::Vector3d dn = d.normalized();
  if (kind == SurfaceKind::kChimney) {
    const double x = p.x() - c.base_m.x(), y = p.y() - c.base_m.y();
    const double rho = std::max(1e-9, std::hypot(x, y));
    const double s = (c.top_radius_m - c.base_radius_m) / c.height_m;
    normal = Eigen::Vector3d(x / rho, y / rho, -s).normalized();
    const double cos_incidence = std::max(0.15, std::abs(normal.dot(dn)));
    const double azimuth = std::atan2(y, x) + M_PI;  // [0, 2 pi]
    const cv::Mat& tex = chimney_mips_.front();
    const double u = azimuth / (2.0 * M_PI) * (tex.cols - 1);
    const double v = (p.z() - c.base_m.z()) / c.chimney_texel_m;
    albedo = sampleMip(chimney_mips_, u, v, footprint_m / cos_incidence / c.chimney_texel_m);
  } else {
    const double cos_incidence = std::max(0.15, std::abs(dn.z()));
    const cv::Mat& tex = seabed_mips_.front();
    const double u = (p.x() - c.base_m.x() + c.seabed_half_size_m) / c.seabed_texel_m;
    const double v = (p.y() - c.base_m.y() + c.seabed_half_size_m) / c.seabed_texel_m;
    if (u >= 0.0 && v >= 0.0 && u < tex.cols && v < tex.rows)
      albedo = sampleMip(seabed_mips_, u, v, footprint_m / cos_incidence / c.seabed_texel_m);
  }
  return albedo * (0.3 + 0.7 * std::max(0.0, normal.dot(light_w_)));
}

RenderedView VentRenderer::render(const PinholeCamera& camera, const Eigen::Isometry3d& world_T_camera) const {
  RenderedView view;
  view.image.create(camera.height_px, camera.width_px, CV_8UC1);
  view.depth_m.create(camera.height_px, camera.width_px, CV_32FC1);
  const Eigen::Matrix3d k_inv = camera.k.inverse();
  const Eigen::Matrix3d rotation = world_T_camera.linear();
  const Eigen::Vector3d origin = world_T_camera.translation();
  const double focal = 0.5 * (camera.k(0, 0) + camera.k(1, 1));
  const int n = config_.supersampling;
  const double footprint_per_depth = 1.0 / (focal * n);  // one sub-ray's share of the pixel, at unit depth
  const double k_att = config_.attenuation_per_m, water = config_.water_gray;
  cv::parallel_for_(cv::Range(0, camera.height_px), [&](const cv::Range& rows) {
    for (int y = rows.start; y < rows.end; ++y) {
      uint8_t* out = view.image.ptr<uint8_t>(y);
      float* depth = view.depth_m.ptr<float>(y);
      for (int x = 0; x < camera.width_px; ++x) {
        // Direction with camera z = 1, so the ray parameter is the depth.
        const Eigen::Vector3d centre = rotation * (k_inv * Eigen::Vector3d(x, y, 1.0));
        const Hit centre_hit = cast(origin, centre);
        depth[x] = centre_hit.kind == SurfaceKind::kNone ? std::numeric_limits<float>::infinity()
                                                         : static_cast<float>(centre_hit.t);
        double sum = 0.0;
        for (int j = 0; j < n; ++j) {
          for (int i = 0; i < n; ++i) {
            const double u = x + (i + 0.5) / n - 0.5, v = y + (j + 0.5) / n - 0.5;
            const Eigen::Vector3d d = rotation * (k_inv * Eigen::Vector3d(u, v, 1.0));
            const Hit hit = cast(origin, d);
            if (hit.kind == SurfaceKind::kNone) {
              sum += water;
              continue;
            }
            const double range_m = hit.t * d.norm();
            const double radiance = 255.0 * shade(origin + hit.t * d, hit.kind, d, hit.t * footprint_per_depth);
            const double transmission = std::exp(-k_att * range_m);
            sum += radiance * transmission + water * (1.0 - transmission);
          }
        }
        out[x] = cv::saturate_cast<uint8_t>(sum / (n * n));
      }
    }
  });
  return view;
}

double VentRenderer::depthAt(const PinholeCamera& camera, const Eigen::Isometry3d& world_T_camera,
                             const Eigen::Vector2d& px, SurfaceKind* kind) const {
  const Eigen::Vector3d d = world_T_camera.linear() * (camera.k.inverse() * Eigen::Vector3d(px.x(), px.y(), 1.0));
  const Hit hit = cast(world_T_camera.translation(), d);
  if (kind != nullptr) *kind = hit.kind;
  return hit.kind == SurfaceKind::kNone ? kInf : hit.t;
}

double distanceToScene(const VentSceneConfig& scene, const Eigen::Vector3d& p) {
  const Eigen::Vector3d r = p - scene.base_m;
  const Eigen::Vector2d q(std::hypot(r.x(), r.y()), r.z());  // (distance from the axis, height)
  const auto toSegment = [&q](const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
    const double t = std::clamp((q - a).dot(b - a) / (b - a).squaredNorm(), 0.0, 1.0);
    return (a + t * (b - a) - q).norm();
  };
  const Eigen::Vector2d base_rim(scene.base_radius_m, 0.0), top_rim(scene.top_radius_m, scene.height_m);
  double best = std::min(toSegment(base_rim, top_rim), toSegment(top_rim, Eigen::Vector2d(0.0, scene.height_m)));
  if (scene.draw_seabed) {
    if (q.x() >= scene.base_radius_m) {        // nearest seabed point straight below (the plane is drawn, untextured,
      best = std::min(best, std::abs(q.y()));  // beyond its textured square too)
    } else {  // above or below the chimney's foot: the nearest seabed point is on the base rim
      best = std::min(best, (q - base_rim).norm());
    }
  }
  return best;
}

double VentRenderer::distanceToSurface(const Eigen::Vector3d& p) const { return distanceToScene(config_, p); }

}  // namespace sim
}  // namespace exocet_servo
