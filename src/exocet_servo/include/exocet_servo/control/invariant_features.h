/**
 * @file invariant_features.h
 * @brief Malis' projective space invariant to the camera intrinsics (2D4 report, 2.3, eqs. 13-15; Malis 2002).
 *
 * From n >= 3 non-collinear image points p_i = (u_i, v_i, 1) (pixels): S_p = (1/n) sum p_i p_i^T is symmetric
 * positive definite and factors as S_p = T_p T_p^T with T_p upper triangular with a positive diagonal; the invariant
 * points are q_i = T_p^-1 p_i. Since p = K m with K upper triangular, S_p = K S_m K^T and, the factor being unique,
 * T_p = K T_m: q_i = T_m^-1 m_i does not depend on K (focal lengths, aspect, principal point, skew). As the third row
 * of S_p is the mean of p_i whose third coordinate is 1, (T_p)_33 = 1 and every q_i = (a_i, b_i, 1).
 * No ROS in it.
 */
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

namespace exocet_servo {
namespace control {

/// Upper triangular U with a positive diagonal such that S = U U^T (the Cholesky factor taken in reverse order).
/// @param s symmetric positive definite 3x3 matrix.
/// @param[out] u the factor.
/// @return false when s is not positive definite (collinear points, too few points).
bool upperTriangularFactor(const Eigen::Matrix3d& s, Eigen::Matrix3d* u);

/// The invariant representation of one image's points.
struct InvariantPoints {
  Eigen::Matrix3d s = Eigen::Matrix3d::Zero();  ///< S_p, (1/n) sum p_i p_i^T
  Eigen::Matrix3d t = Eigen::Matrix3d::Zero();  ///< T_p, upper triangular, S_p = T_p T_p^T
  Eigen::Matrix3d t_inverse = Eigen::Matrix3d::Zero();
  std::vector<Eigen::Vector3d> q;  ///< q_i = T_p^-1 p_i, third coordinate 1
  /// Feature vector s = (a_1, b_1, ..., a_n, b_n) (the constant third coordinates are left out).
  Eigen::VectorXd stacked() const;
};

/// Computes the invariant points of n image points.
/// @param points homogeneous points (u, v, 1) in pixels, or normalised points (x, y, 1); n >= 3, not all collinear.
/// @param[out] out the factor and the invariant points.
/// @return "" or why it failed (too few points, collinear points, a third coordinate not 1).
std::string computeInvariantPoints(const std::vector<Eigen::Vector3d>& points, InvariantPoints* out);

/// Homogeneous points (u, v, 1) from pixel coordinates.
std::vector<Eigen::Vector3d> homogeneous(const std::vector<Eigen::Vector2d>& points_px);

}  // namespace control
}  // namespace exocet_servo
