#include "exocet_servo/trajectory/se3.h"

#include <algorithm>
#include <cmath>

namespace exocet_servo {
namespace trajectory {

Eigen::Matrix3d skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d s;
  s << 0.0, -v.z(), v.y(), v.z(), 0.0, -v.x(), -v.y(), v.x(), 0.0;
  return s;
}

Eigen::Isometry3d expSe3(const Twist& twist) {
  const Eigen::Vector3d nu = twist.head<3>();
  const Eigen::Vector3d omega = twist.tail<3>();
  const double theta = omega.norm();
  const Eigen::Matrix3d w = skew(omega);
  // Series below 1e-6 rad: the closed-form coefficients lose all their digits there.
  double a, b;
  if (theta < 1e-6) {
    a = 0.5 - theta * theta / 24.0;
    b = 1.0 / 6.0 - theta * theta / 120.0;
  } else {
    a = (1.0 - std::cos(theta)) / (theta * theta);
    b = (theta - std::sin(theta)) / (theta * theta * theta);
  }
  const Eigen::Matrix3d v = Eigen::Matrix3d::Identity() + a * w + b * w * w;
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() =
      theta < 1e-12 ? Eigen::Matrix3d::Identity() : Eigen::AngleAxisd(theta, omega / theta).toRotationMatrix();
  pose.translation() = v * nu;
  return pose;
}

double rotationAngleRad(const Eigen::Matrix3d& r) {
  // atan2 of (sin, cos) keeps full precision at both ends, unlike acos((trace - 1) / 2).
  const Eigen::Vector3d axis_sin(r(2, 1) - r(1, 2), r(0, 2) - r(2, 0), r(1, 0) - r(0, 1));
  return std::atan2(0.5 * axis_sin.norm(), 0.5 * (r.trace() - 1.0));
}

Twist logSe3(const Eigen::Isometry3d& pose) {
  const Eigen::AngleAxisd aa(pose.linear());
  double theta = aa.angle();
  Eigen::Vector3d omega = theta * aa.axis();
  if (theta < 1e-12) omega.setZero();
  theta = omega.norm();
  const Eigen::Matrix3d w = skew(omega);
  double c;  // coefficient of [w]^2 in V^-1
  if (theta < 1e-6) {
    c = 1.0 / 12.0 + theta * theta / 720.0;
  } else {
    c = (1.0 - theta * std::sin(theta) / (2.0 * (1.0 - std::cos(theta)))) / (theta * theta);
  }
  const Eigen::Matrix3d v_inv = Eigen::Matrix3d::Identity() - 0.5 * w + c * w * w;
  Twist twist;
  twist.head<3>() = v_inv * pose.translation();
  twist.tail<3>() = omega;
  return twist;
}

}  // namespace trajectory
}  // namespace exocet_servo
