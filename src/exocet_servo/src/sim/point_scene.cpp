#include "exocet_servo/sim/point_scene.h"

#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

#include "exocet_servo/trajectory/se3.h"

namespace exocet_servo {
namespace sim {

std::string VentConfig::validate() const {
  std::ostringstream errors;
  auto check = [&errors](bool ok, const char* field, const std::string& range) {
    if (ok) return;
    if (errors.tellp() > 0) errors << "; ";
    errors << field << " must be in " << range;
  };
  check(height_m > 0.0 && height_m <= 100.0, "height_m", "(0, 100]");
  check(base_radius_m > 0.0 && base_radius_m <= 100.0, "base_radius_m", "(0, 100]");
  check(top_radius_m > 0.0 && top_radius_m <= 100.0, "top_radius_m", "(0, 100]");
  check(roughness >= 0.0 && roughness <= 0.9, "roughness", "[0, 0.9]");
  check(points >= 8 && points <= 100000, "points", "[8, 100000]");
  return errors.str();
}

std::vector<Eigen::Vector3d> makeVentPoints(const VentConfig& c) {
  const std::string errors = c.validate();
  if (!errors.empty()) throw std::invalid_argument("VentConfig: " + errors);
  std::mt19937 rng(c.seed);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::vector<Eigen::Vector3d> pts;
  pts.reserve(c.points);
  for (int i = 0; i < c.points; ++i) {
    // Stratified height (one point per slice) and random azimuth: spread over the whole chimney.
    const double h = (i + unit(rng)) / c.points;
    const double azimuth = 2.0 * M_PI * unit(rng);
    const double r =
        (c.base_radius_m + h * (c.top_radius_m - c.base_radius_m)) * (1.0 + c.roughness * (2.0 * unit(rng) - 1.0));
    pts.push_back(c.base_m + Eigen::Vector3d(r * std::cos(azimuth), r * std::sin(azimuth), h * c.height_m));
  }
  return pts;
}

Eigen::Matrix3d intrinsics(double fx, double fy, double cx, double cy, double skew) {
  Eigen::Matrix3d k;
  k << fx, skew, cx, 0.0, fy, cy, 0.0, 0.0, 1.0;
  return k;
}

Projection project(const PinholeCamera& camera, const Eigen::Isometry3d& world_T_camera,
                   const std::vector<Eigen::Vector3d>& points_w, double noise_px, std::mt19937* rng) {
  const Eigen::Isometry3d camera_T_world = world_T_camera.inverse();
  std::normal_distribution<double> noise(0.0, noise_px > 0.0 ? noise_px : 1.0);
  Projection out;
  out.points_px.reserve(points_w.size());
  out.depths_m.reserve(points_w.size());
  for (const auto& pw : points_w) {
    const Eigen::Vector3d pc = camera_T_world * pw;
    out.depths_m.push_back(pc.z());
    if (pc.z() <= 1e-9) {
      const double nan = std::numeric_limits<double>::quiet_NaN();
      out.points_px.emplace_back(nan, nan);
      continue;
    }
    const Eigen::Vector3d p = camera.k * (pc / pc.z());
    Eigen::Vector2d px(p.x(), p.y());
    if (rng != nullptr && noise_px > 0.0) px += Eigen::Vector2d(noise(*rng), noise(*rng));
    out.points_px.push_back(px);
  }
  return out;
}

Eigen::Isometry3d lookAt(const Eigen::Vector3d& position, const Eigen::Vector3d& target, const Eigen::Vector3d& up) {
  const Eigen::Vector3d z = (target - position).normalized();
  Eigen::Vector3d x = z.cross(up);  // right = forward x up... for y down: x = y x z with y = -up
  if (x.norm() < 1e-9) x = z.unitOrthogonal();
  x.normalize();
  const Eigen::Vector3d y = z.cross(x);
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear().col(0) = x;
  pose.linear().col(1) = y;
  pose.linear().col(2) = z;
  pose.translation() = position;
  return pose;
}

PoseError poseError(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  PoseError e;
  e.position_mm = 1000.0 * (a.translation() - b.translation()).norm();
  e.rotation_deg = trajectory::rotationAngleRad(a.linear().transpose() * b.linear()) * 180.0 / M_PI;
  return e;
}

}  // namespace sim
}  // namespace exocet_servo
