#include "exocet_servo/trajectory/screw_motion.h"

#include <cmath>

#include "exocet_servo/trajectory/se3.h"

namespace exocet_servo {
namespace trajectory {

Eigen::Vector3d ScrewMotion::position(double t) const {
  if (pure_translation) return pitch_per_step_m * t * axis;
  const double a = angle_per_step_rad * t;
  return axis_point + radius_m * (std::cos(a) * u + std::sin(a) * v) + pitch_per_step_m * t * axis;
}

Eigen::Isometry3d ScrewMotion::pose(double t) const {
  Eigen::Isometry3d p = Eigen::Isometry3d::Identity();
  if (!pure_translation) p.linear() = Eigen::AngleAxisd(angle_per_step_rad * t, axis).toRotationMatrix();
  p.translation() = position(t);
  return p;
}

ScrewMotion screwFromTransform(const Eigen::Isometry3d& t) {
  const Twist a = logSe3(t);
  const Eigen::Vector3d nu = a.head<3>();
  const Eigen::Vector3d omega = a.tail<3>();
  ScrewMotion s;
  const double theta = omega.norm();
  if (theta < 1e-12) {
    s.pure_translation = true;
    s.pitch_per_step_m = nu.norm();
    s.axis = s.pitch_per_step_m > 0.0 ? Eigen::Vector3d(nu / s.pitch_per_step_m) : Eigen::Vector3d::UnitZ();
    return s;
  }
  s.angle_per_step_rad = theta;
  s.axis = omega / theta;
  s.axis_point = omega.cross(nu) / (theta * theta);
  s.radius_m = s.axis_point.norm();
  s.pitch_per_step_m = s.axis.dot(nu);
  if (s.radius_m > 1e-15) {
    s.u = -s.axis_point / s.radius_m;
  } else {  // origin on the axis: any u orthogonal to w
    s.u = s.axis.unitOrthogonal();
  }
  s.v = s.axis.cross(s.u);
  return s;
}

std::vector<Eigen::Isometry3d> composedPowers(const Eigen::Isometry3d& t, int k) {
  std::vector<Eigen::Isometry3d> out{Eigen::Isometry3d::Identity()};
  for (int i = 0; i < k; ++i) out.push_back(out.back() * t);
  return out;
}

}  // namespace trajectory
}  // namespace exocet_servo
