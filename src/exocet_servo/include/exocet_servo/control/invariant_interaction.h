/**
 * @file invariant_interaction.h
 * @brief Interaction matrix of the invariant points q_i = T^-1 m_i with respect to the camera velocity (v, omega)
 * (Malis 2002), derived analytically from the point interaction matrix L_m. No ROS in it.
 *
 * The invariant points are computed from normalised points m_i = K^-1 p_i (any K gives the same q, see
 * invariant_features.h), so the derivation can be done on m: with dm_i = L_m(m_i, Z_i) v,
 *   dS = (1/n) sum (dm_i m_i^T + m_i dm_i^T),   dS = dT T^T + T dT^T,
 *   X = T^-1 dT is upper triangular and X + X^T = T^-1 dS T^-T, hence X = upper(T^-1 dS T^-T) with a halved diagonal,
 *   dq_i = T^-1 dm_i - T^-1 dT T^-1 m_i = T^-1 dm_i - X q_i.
 * Each q_i depends on every point through T: the matrix is dense, (2n x 6). It needs the normalised points (an
 * estimate K_hat of K suffices: a wrong K_hat only changes the matrix, not where the servo converges, which is set by
 * the invariant error) and the depths Z_i of the points in the camera frame (true, triangulated by the stereo rig,
 * or a rough estimate of each). The depths must differ from point to point: with equal depths (or any planar
 * object) the translations move the points like a change of principal point or focal length, which the invariant
 * space removes, and the matrix loses rank. Translations are observed only through the depth differences (parallax)
 * within the object, which is why the pose is much less precise along the optical axis than with a calibrated camera
 * (pose_bound.h). For the same reason random depth errors must stay well below the object's depth spread: on a
 * 0.2 m deep chimney at 1 m, 2 % errors per point cost a few iterations, 10 % ones stall the servo.
 */
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

namespace exocet_servo {
namespace control {

/// Classical 2x6 interaction matrix of a normalised image point (x, y) at depth z_m (camera velocity (v, omega)).
Eigen::Matrix<double, 2, 6> pointInteraction(double x, double y, double z_m);

/// Interaction matrix (2n x 6) of the stacked invariant points (a_1, b_1, ..., a_n, b_n).
/// @param normalized_points m_i = (x_i, y_i, 1), n >= 3, not collinear.
/// @param depths_m depth Z_i > 0 of each point (metres), same size.
/// @param[out] interaction the matrix; rows 2i, 2i+1 are d(a_i, b_i)/d(v, omega).
/// @return "" or why it could not be computed.
std::string invariantInteraction(const std::vector<Eigen::Vector3d>& normalized_points,
                                 const std::vector<double>& depths_m, Eigen::MatrixXd* interaction);

}  // namespace control
}  // namespace exocet_servo
