#include "exocet_stereo/geometry/epipolar.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Geometry>

namespace exocet_stereo {
namespace geometry {

namespace {

Eigen::Matrix3d skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d S;
  S << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return S;
}

double lineDistance(const Eigen::Vector3d& line, const Eigen::Vector2d& p) {
  const double n = line.head<2>().norm();
  if (n <= 0.0) return std::numeric_limits<double>::infinity();
  return std::abs(line.dot(p.homogeneous())) / n;
}

}  // namespace

RelativePose relativePose(const PinholeView& view1, const PinholeView& view2) {
  RelativePose pose;
  pose.R_21 = view2.R * view1.R.transpose();
  pose.t_21 = view2.t - pose.R_21 * view1.t;
  return pose;
}

Eigen::Matrix3d essentialMatrix(const RelativePose& pose) { return skew(pose.t_21) * pose.R_21; }

Eigen::Matrix3d fundamentalFromCalibration(const Eigen::Matrix3d& K1, const Eigen::Matrix3d& K2,
                                           const RelativePose& pose) {
  const Eigen::Matrix3d F = K2.inverse().transpose() * essentialMatrix(pose) * K1.inverse();
  return F / F.norm();
}

Eigen::Matrix3d fundamentalFromViews(const PinholeView& view1, const PinholeView& view2) {
  return fundamentalFromCalibration(view1.K, view2.K, relativePose(view1, view2));
}

double epipolarLineDistance_px(const Eigen::Matrix3d& F, const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  return lineDistance(F * a.homogeneous(), b);
}

double symmetricEpipolarDistance_px(const Eigen::Matrix3d& F, const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  return std::max(lineDistance(F * a.homogeneous(), b), lineDistance(F.transpose() * b.homogeneous(), a));
}

double epipolarToleranceForPoseError_px(double focal_px, double rotation_error_rad, double relative_centre_error,
                                        double noise_px) {
  return focal_px * (std::abs(rotation_error_rad) + std::abs(relative_centre_error)) + std::abs(noise_px);
}

}  // namespace geometry
}  // namespace exocet_stereo
