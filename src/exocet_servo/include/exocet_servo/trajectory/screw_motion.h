/**
 * @file screw_motion.h
 * @brief The trajectory induced by repeating one rigid displacement T (2D4 report 2.2, eqs. 6-9): T = exp(A),
 * A = (nu, omega) in se(3); T^t = exp(t A) moves the frame origin on a cylinder (a helix in general: circle when
 * omega . nu = 0, straight line when omega = 0),
 *   C(t) = r0 + radius (cos(theta t) u + sin(theta t) v) + pitch t w,
 * with w = omega / |omega| the axis, theta = |omega| the rotation per step, r0 = (omega x nu) / |omega|^2 the point of
 * the axis closest to the origin, u = -r0 / |r0| (from the axis to the origin), v = w x u, radius = |r0| and
 * pitch = w . nu the translation along the axis per step. This is the report's closed form in screw (Chasles)
 * terms, with unit u, v, w. No ROS in it.
 */
#pragma once

#include <vector>

#include <Eigen/Geometry>

namespace exocet_servo {
namespace trajectory {

/// Screw decomposition of a rigid displacement, expressed in the frame where the displacement starts.
struct ScrewMotion {
  bool pure_translation = false;  ///< omega = 0: the trajectory is the line t nu (w = nu / |nu|, the rest zero)
  Eigen::Vector3d axis_point = Eigen::Vector3d::Zero();  ///< r0 (m)
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();       ///< w, unit
  Eigen::Vector3d u = Eigen::Vector3d::UnitX();          ///< unit, from the axis towards the origin
  Eigen::Vector3d v = Eigen::Vector3d::UnitY();          ///< w x u
  double radius_m = 0.0;                                 ///< distance from the origin to the axis
  double angle_per_step_rad = 0.0;                       ///< theta = |omega|, in [0, pi)
  double pitch_per_step_m = 0.0;                         ///< translation along w per step (signed)

  /// Position of the frame origin after t steps (t real: the continuous trajectory of eq. 8).
  Eigen::Vector3d position(double t) const;
  /// Pose T^t (rotation about w by theta t, position position(t)).
  Eigen::Isometry3d pose(double t) const;
};

/// Screw decomposition of T (from log(T)); T's rotation angle must be below pi.
ScrewMotion screwFromTransform(const Eigen::Isometry3d& t);

/// T^0, T^1, ..., T^k by repeated composition.
std::vector<Eigen::Isometry3d> composedPowers(const Eigen::Isometry3d& t, int k);

}  // namespace trajectory
}  // namespace exocet_servo
