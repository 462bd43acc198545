/**
 * @file rig_geometry.h
 * @brief Geometry of the stereo rig (2D4 report 2.2, eqs. 1-5): the right camera sits baseline_m to the right of the
 * left camera (its +x), turned by pan_rad towards the left camera's optical axis (toe-in, a rotation of -pan about
 * the camera y axis, which points down) and tilted by tilt_rad about its x axis. No ROS in it.
 *
 * Servoing the left camera to where the right camera took the reference image moves the rig by
 * leftFromRight() each time (screw_motion.h).
 */
#pragma once

#include <string>

#include <Eigen/Geometry>

namespace exocet_servo {
namespace trajectory {

/// Baseline, pan and tilt of the right camera relative to the left one.
struct RigGeometry {
  double baseline_m = 0.3;    ///< distance between the optical centres, (0, 10]
  double pan_rad = 0.314159;  ///< toe-in of the right camera (18 deg), [-pi/2, pi/2]
  double tilt_rad = 0.0;      ///< tilt of the right camera about its x axis, [-pi/2, pi/2]
  /// "" or every bad field with its allowed range.
  std::string validate() const;
  /// Pose of the right camera in the left camera frame (left_T_right): rotation R_y(-pan) R_x(tilt), translation
  /// (baseline, 0, 0).
  Eigen::Isometry3d leftFromRight() const;
};

}  // namespace trajectory
}  // namespace exocet_servo
