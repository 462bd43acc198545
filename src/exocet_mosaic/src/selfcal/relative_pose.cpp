#include "exocet_mosaic/selfcal/relative_pose.h"

#include <stdexcept>
#include <string>

#include <Eigen/Dense>

namespace exocet_mosaic {
namespace selfcal {

namespace {

Eigen::Matrix3d skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d s;
  s << 0.0, -v.z(), v.y(), v.z(), 0.0, -v.x(), -v.y(), v.x(), 0.0;
  return s;
}

/// Depths of the two rays' closest points (least squares of lambda_b x_b = R lambda_a x_a + t).
bool inFront(const Eigen::Matrix3d& R, const Eigen::Vector3d& t, const Eigen::Vector3d& xa, const Eigen::Vector3d& xb) {
  Eigen::Matrix<double, 3, 2> A;
  A.col(0) = R * xa;
  A.col(1) = -xb;
  const Eigen::Vector2d depths = A.colPivHouseholderQr().solve(-t);
  return depths(0) > 0.0 && depths(1) > 0.0;
}

}  // namespace

Eigen::Matrix3d essentialFromPose(const Eigen::Matrix3d& R_b_a, const Eigen::Vector3d& t_b_a) {
  return skew(t_b_a) * R_b_a;
}

RelativePose relativePoseFromFundamental(const Eigen::Matrix3d& F, const Eigen::Matrix3d& K,
                                         const std::vector<Eigen::Vector2d>& a, const std::vector<Eigen::Vector2d>& b,
                                         const std::vector<bool>& use) {
  if (a.size() != b.size() || (!use.empty() && use.size() != a.size()))
    throw std::invalid_argument("relativePoseFromFundamental: " + std::to_string(a.size()) + " points in a, " +
                                std::to_string(b.size()) + " in b, " + std::to_string(use.size()) + " flags");
  const Eigen::Matrix3d E = K.transpose() * F * K;
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(E, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d U = svd.matrixU(), V = svd.matrixV();
  // E's third singular value is zero: flipping the last column keeps U S V^T and makes U and V rotations.
  if (U.determinant() < 0.0) U.col(2) *= -1.0;
  if (V.determinant() < 0.0) V.col(2) *= -1.0;
  // Translation first: the left null vector of E (E^T t = 0), up to sign.
  const Eigen::Vector3d t = U.col(2);
  Eigen::Matrix3d W;
  W << 0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0;
  const Eigen::Matrix3d candidates_R[2] = {U * W * V.transpose(), U * W.transpose() * V.transpose()};
  const Eigen::Matrix3d k_inverse = K.inverse();
  RelativePose best;
  for (const Eigen::Matrix3d& R : candidates_R) {
    for (double sign : {1.0, -1.0}) {
      RelativePose pose;
      pose.R_b_a = R;
      pose.t_b_a = sign * t;
      for (size_t i = 0; i < a.size(); ++i) {
        if (!use.empty() && !use[i]) continue;
        ++pose.points_tested;
        if (inFront(R, pose.t_b_a, k_inverse * a[i].homogeneous(), k_inverse * b[i].homogeneous()))
          ++pose.points_in_front;
      }
      if (pose.points_in_front > best.points_in_front || best.points_tested == 0) best = pose;
    }
  }
  best.ok = best.points_tested > 0 && 2 * best.points_in_front > best.points_tested;
  return best;
}

}  // namespace selfcal
}  // namespace exocet_mosaic
