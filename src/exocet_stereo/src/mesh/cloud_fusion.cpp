#include "exocet_stereo/mesh/cloud_fusion.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <sstream>
#include <stdexcept>
#include <unordered_map>

#include <opencv2/core/utility.hpp>

namespace exocet_stereo {
namespace mesh {

namespace {

bool known(float z) { return std::isfinite(z) && z > 0.0f; }

/// A depth map's camera, precomputed for projection and back-projection.
struct Camera {
  Eigen::Matrix3d K, K_inv;
  Eigen::Matrix3d R_cw;  ///< world to camera
  Eigen::Vector3d t_cw;
  Eigen::Isometry3d world_T_camera;
};

/// Depth of a map at a sub-pixel position: bilinear when the 4 neighbours are known and smooth (max / min within
/// 1 + max_step), else the nearest pixel's. False outside the map or on an unknown pixel.
bool sampleDepth(const cv::Mat& depth, double u, double v, double max_step, double* out) {
  const int xn = static_cast<int>(std::lround(u)), yn = static_cast<int>(std::lround(v));
  if (xn < 0 || yn < 0 || xn >= depth.cols || yn >= depth.rows) return false;
  const int x0 = static_cast<int>(std::floor(u)), y0 = static_cast<int>(std::floor(v));
  if (x0 >= 0 && y0 >= 0 && x0 + 1 < depth.cols && y0 + 1 < depth.rows) {
    const float a = depth.at<float>(y0, x0), b = depth.at<float>(y0, x0 + 1), c = depth.at<float>(y0 + 1, x0),
                d = depth.at<float>(y0 + 1, x0 + 1);
    if (known(a) && known(b) && known(c) && known(d)) {
      const float lo = std::min({a, b, c, d}), hi = std::max({a, b, c, d});
      if (hi <= lo * (1.0 + max_step)) {
        const double fx = u - x0, fy = v - y0;
        *out = (1 - fy) * ((1 - fx) * a + fx * b) + fy * ((1 - fx) * c + fx * d);
        return true;
      }
    }
  }
  const float z = depth.at<float>(yn, xn);
  if (!known(z)) return false;
  *out = z;
  return true;
}

/// A kept pixel before merging.
struct Sample {
  Eigen::Vector3d point, normal, rgb;
  int confirmations;
};

/// Per-row result of the parallel pass.
struct RowResult {
  std::vector<Sample> samples;
  long candidates = 0, discontinuity = 0, oblique = 0, unconfirmed = 0;
};

/// Voxel key: three 21-bit signed indices packed in 64 bits (+-1e6 voxels per axis).
constexpr int64_t kIndexOffset = 1 << 20;
bool voxelKey(const Eigen::Vector3d& p, double voxel_m, uint64_t* key) {
  uint64_t k = 0;
  for (int a = 0; a < 3; ++a) {
    const double i = std::floor(p[a] / voxel_m) + kIndexOffset;
    if (!(i >= 0 && i < 2 * kIndexOffset)) return false;
    k = (k << 21) | static_cast<uint64_t>(i);
  }
  *key = k;
  return true;
}

struct Voxel {
  Eigen::Vector3d point_sum = Eigen::Vector3d::Zero(), normal_sum = Eigen::Vector3d::Zero(),
                  rgb_sum = Eigen::Vector3d::Zero();
  int samples = 0, confirmations = 0;
};

void checkViews(const std::vector<DepthView>& views) {
  for (size_t i = 0; i < views.size(); ++i) {
    const DepthView& v = views[i];
    const std::string name = "fuseDepthMaps: view " + std::to_string(i) + ": ";
    if (v.depth_m.empty() || v.depth_m.type() != CV_32FC1)
      throw std::invalid_argument(name + "depth_m must be a non-empty CV_32FC1 map");
    if (!v.image.empty() &&
        (v.image.size() != v.depth_m.size() || (v.image.type() != CV_8UC1 && v.image.type() != CV_8UC3)))
      throw std::invalid_argument(name + "image must be CV_8UC1 or CV_8UC3 of the depth map's size");
    if (!(std::abs(v.K.determinant()) > 1e-12) || !v.K.allFinite())
      throw std::invalid_argument(name + "K is not an invertible finite matrix");
  }
}

}  // namespace

std::string CloudFusionConfig::validate() const {
  std::vector<std::string> bad;
  if (min_confirmations < 0 || min_confirmations > 64) bad.push_back("min_confirmations must be in [0, 64]");
  if (!(depth_tolerance > 0.0 && depth_tolerance <= 1.0)) bad.push_back("depth_tolerance must be in (0, 1]");
  if (!(voxel_m > 0.0 && voxel_m <= 1e3)) bad.push_back("voxel_m must be in (0, 1e3]");
  if (step_px < 1 || step_px > 64) bad.push_back("step_px must be in [1, 64]");
  if (normal_radius_px < 1 || normal_radius_px > 16) bad.push_back("normal_radius_px must be in [1, 16]");
  if (!(max_relative_depth_step > 0.0 && max_relative_depth_step <= 10.0))
    bad.push_back("max_relative_depth_step must be in (0, 10]");
  if (!(max_incidence_deg >= 0.0 && max_incidence_deg <= 90.0)) bad.push_back("max_incidence_deg must be in [0, 90]");
  if (min_samples_per_voxel < 1 || min_samples_per_voxel > 1000000)
    bad.push_back("min_samples_per_voxel must be in [1, 1000000]");
  std::ostringstream s;
  for (size_t i = 0; i < bad.size(); ++i) s << (i ? "; " : "") << bad[i];
  return s.str();
}

FusedCloud FusedCloud::cropped(const Eigen::Vector3d& min_m, const Eigen::Vector3d& max_m) const {
  FusedCloud out;
  for (size_t i = 0; i < points.size(); ++i) {
    const Eigen::Vector3d& p = points[i];
    if ((p.array() < min_m.array()).any() || (p.array() > max_m.array()).any()) continue;
    out.points.push_back(p);
    if (i < normals.size()) out.normals.push_back(normals[i]);
    if (i < colors.size()) out.colors.push_back(colors[i]);
    if (i < confirmations.size()) out.confirmations.push_back(confirmations[i]);
    if (i < samples.size()) out.samples.push_back(samples[i]);
  }
  return out;
}

FusedCloud fuseDepthMaps(const std::vector<DepthView>& views, const CloudFusionConfig& config,
                         CloudFusionStats* stats) {
  const std::string problems = config.validate();
  if (!problems.empty()) throw std::invalid_argument("CloudFusionConfig: " + problems);
  checkViews(views);
  std::vector<Camera> cameras(views.size());
  bool any_image = false;
  for (size_t i = 0; i < views.size(); ++i) {
    cameras[i].K = views[i].K;
    cameras[i].K_inv = views[i].K.inverse();
    cameras[i].world_T_camera = views[i].world_T_camera;
    const Eigen::Isometry3d camera_T_world = views[i].world_T_camera.inverse();
    cameras[i].R_cw = camera_T_world.linear();
    cameras[i].t_cw = camera_T_world.translation();
    any_image = any_image || !views[i].image.empty();
  }
  const double cos_max_incidence = std::cos(config.max_incidence_deg * M_PI / 180.0);
  const double step = config.max_relative_depth_step;
  const int r = config.normal_radius_px;

  CloudFusionStats total;
  std::unordered_map<uint64_t, Voxel> voxels;
  for (size_t i = 0; i < views.size(); ++i) {
    const cv::Mat& depth = views[i].depth_m;
    const cv::Mat& image = views[i].image;
    const Camera& cam = cameras[i];
    const int grid_rows = (depth.rows + config.step_px - 1) / config.step_px;
    std::vector<RowResult> rows(grid_rows);
    cv::parallel_for_(cv::Range(0, grid_rows), [&](const cv::Range& range) {
      for (int gy = range.start; gy < range.end; ++gy) {
        const int y = gy * config.step_px;
        RowResult& row = rows[gy];
        for (int x = 0; x < depth.cols; x += config.step_px) {
          const float z = depth.at<float>(y, x);
          if (!known(z)) continue;
          ++row.candidates;
          // The gradient neighbours must exist and be on the same surface: a silhouette pixel is no 3D point.
          if (x - r < 0 || y - r < 0 || x + r >= depth.cols || y + r >= depth.rows) {
            ++row.discontinuity;
            continue;
          }
          const float zl = depth.at<float>(y, x - r), zr = depth.at<float>(y, x + r), zu = depth.at<float>(y - r, x),
                      zd = depth.at<float>(y + r, x);
          bool smooth = true;
          for (float zn : {zl, zr, zu, zd}) smooth = smooth && known(zn) && std::abs(zn - z) <= step * z;
          if (!smooth) {
            ++row.discontinuity;
            continue;
          }
          auto backProject = [&](double px, double py, double depth_m) {
            return Eigen::Vector3d(depth_m * (cam.K_inv * Eigen::Vector3d(px, py, 1.0)));
          };
          const Eigen::Vector3d p = backProject(x, y, z);
          Eigen::Vector3d n = (backProject(x + r, y, zr) - backProject(x - r, y, zl))
                                  .cross(backProject(x, y + r, zd) - backProject(x, y - r, zu));
          if (!(n.norm() > 0.0)) {
            ++row.discontinuity;
            continue;
          }
          n.normalize();
          if (n.dot(p) > 0.0) n = -n;  // towards the camera
          if (-n.dot(p) / p.norm() < cos_max_incidence) {
            ++row.oblique;
            continue;
          }
          const Eigen::Vector3d X = cam.world_T_camera * p;
          int confirmations = 0;
          for (size_t j = 0; j < views.size() && config.min_confirmations > 0; ++j) {
            if (j == i) continue;
            const Eigen::Vector3d Xc = cameras[j].R_cw * X + cameras[j].t_cw;
            if (!(Xc.z() > 0.0)) continue;
            const Eigen::Vector3d uv = cameras[j].K * Xc;
            double dj;
            if (!sampleDepth(views[j].depth_m, uv.x() / uv.z(), uv.y() / uv.z(), step, &dj)) continue;
            if (std::abs(dj - Xc.z()) <= config.depth_tolerance * Xc.z()) ++confirmations;
          }
          if (confirmations < config.min_confirmations) {
            ++row.unconfirmed;
            continue;
          }
          Eigen::Vector3d rgb(0, 0, 0);
          if (image.empty()) {
            // no colour (an empty cv::Mat reports type CV_8UC1: test emptiness first)
          } else if (image.type() == CV_8UC3) {
            const cv::Vec3b& bgr = image.at<cv::Vec3b>(y, x);
            rgb = Eigen::Vector3d(bgr[2], bgr[1], bgr[0]);
          } else {
            rgb.setConstant(image.at<uint8_t>(y, x));
          }
          row.samples.push_back({X, cam.world_T_camera.linear() * n, rgb, confirmations});
        }
      }
    });
    for (const RowResult& row : rows) {
      total.candidates += row.candidates;
      total.discontinuity += row.discontinuity;
      total.oblique += row.oblique;
      total.unconfirmed += row.unconfirmed;
      for (const Sample& s : row.samples) {
        uint64_t key;
        if (!voxelKey(s.point, config.voxel_m, &key)) continue;  // beyond +-1e6 voxels: not a usable point
        Voxel& v = voxels[key];
        v.point_sum += s.point;
        v.normal_sum += s.normal;
        v.rgb_sum += s.rgb;
        ++v.samples;
        v.confirmations = std::max(v.confirmations, s.confirmations);
        ++total.fused_pixels;
      }
    }
  }

  // Sorted keys: the output order does not depend on the hash table.
  std::vector<uint64_t> keys;
  keys.reserve(voxels.size());
  for (const auto& kv : voxels) keys.push_back(kv.first);
  std::sort(keys.begin(), keys.end());
  FusedCloud cloud;
  for (uint64_t key : keys) {
    const Voxel& v = voxels[key];
    if (v.samples < config.min_samples_per_voxel || !(v.normal_sum.norm() > 0.0)) {
      ++total.sparse_voxels;
      continue;
    }
    cloud.points.push_back(v.point_sum / v.samples);
    cloud.normals.push_back(v.normal_sum.normalized());
    if (any_image) {
      const Eigen::Vector3d c = v.rgb_sum / v.samples;
      cloud.colors.emplace_back(cv::saturate_cast<uint8_t>(c.x()), cv::saturate_cast<uint8_t>(c.y()),
                                cv::saturate_cast<uint8_t>(c.z()));
    }
    cloud.confirmations.push_back(v.confirmations);
    cloud.samples.push_back(v.samples);
  }
  if (stats) *stats = total;
  return cloud;
}

}  // namespace mesh
}  // namespace exocet_stereo
