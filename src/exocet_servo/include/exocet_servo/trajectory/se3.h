/**
 * @file se3.h
 * @brief Exponential and logarithm maps of SE(3) for rigid poses (Eigen::Isometry3d) and twists. No ROS in it.
 *
 * A twist is the 6-vector (nu, omega): translational part first, then the rotation vector, as in ViSP's camera
 * velocity (v, omega). exp(twist) is the pose reached after moving for one unit of time at that constant body
 * velocity; log is its inverse for rotation angles in [0, pi).
 */
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace exocet_servo {
namespace trajectory {

using Twist = Eigen::Matrix<double, 6, 1>;  ///< (nu_x, nu_y, nu_z [m], omega_x, omega_y, omega_z [rad])

/// Skew-symmetric matrix [v]x such that [v]x w = v x w.
Eigen::Matrix3d skew(const Eigen::Vector3d& v);

/// Exponential map se(3) -> SE(3) (closed form, exact for any angle).
Eigen::Isometry3d expSe3(const Twist& twist);

/// Logarithm map SE(3) -> se(3); the rotation part has angle in [0, pi] (the axis is ambiguous at exactly pi).
Twist logSe3(const Eigen::Isometry3d& pose);

/// Rotation angle (rad, [0, pi]) of a rotation matrix; robust near 0 and pi.
double rotationAngleRad(const Eigen::Matrix3d& rotation);

}  // namespace trajectory
}  // namespace exocet_servo
