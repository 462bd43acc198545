/**
 * @file acquisition_planner.h
 * @brief Plans the image acquisition around an object with a vertical axis (2D4 report 2.2 and 2.4, figure 4): legs
 * of a quarter circle (by default) at the wanted distance from the object's axis, joined by U-turns, rising as a helix
 * so that the legs together cover the object's height. Each leg is one rig geometry (baseline, pan, tilt) repeated:
 * the pan sets the angle per servoing and, with the baseline, the radius; the tilt sets the rise per servoing. At a
 * U-turn the rig rolls 180 deg about the left optical axis (the arm's wrist), the tilt changes sign, and the rig walks
 * back while still rising. No ROS in it.
 *
 * The plan's poses are also the pre-programmed alternative (report 2.6): the left camera poses an arm can be sent to
 * directly (inverse kinematics is not part of this).
 */
#pragma once

#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "exocet_servo/trajectory/rig_geometry.h"
#include "exocet_servo/trajectory/screw_motion.h"

namespace exocet_servo {
namespace trajectory {

/// What to acquire; world frame with z up. validate() lists the allowed ranges.
struct AcquisitionPlanConfig {
  Eigen::Vector3d object_base_m = Eigen::Vector3d::Zero();  ///< point of the object's vertical axis at its base
  double object_height_m = 0.3;                             ///< (0, 100]
  double object_radius_m = 0.1;                             ///< (0, 100]
  double distance_m = 1.0;         ///< camera centre to the object's axis, (object_radius_m, 100]
  double baseline_m = 0.3;         ///< of the rig, (0, 2 * distance_m)
  int legs = 3;                    ///< legs joined by U-turns, [1, 100]
  double leg_arc_rad = M_PI / 2;   ///< azimuth covered by a leg, (0, 2 pi]
  double start_azimuth_rad = 0.0;  ///< of the first camera position around the axis
  /// Camera centre heights above object_base_m at the start and end of the plan (the rise is spread evenly over
  /// every servoing); defaults: the bottom and the top of the object.
  double start_height_m = 0.0;
  double end_height_m = 0.3;
  std::string validate() const;
};

/// One leg: a rig geometry repeated `steps` times from a start pose.
struct AcquisitionLeg {
  RigGeometry rig;
  ScrewMotion screw;  ///< of rig.leftFromRight(), in the left camera frame at the leg's start
  Eigen::Isometry3d world_T_left_start = Eigen::Isometry3d::Identity();
  int steps = 0;      ///< servoings in the leg
  int direction = 1;  ///< +1: counter-clockwise seen from above, -1: clockwise
};

/// The plan.
struct AcquisitionPlan {
  std::vector<AcquisitionLeg> legs;
  /// Left camera poses of every acquisition, in order (each leg's start pose then its `steps` servoed poses; the
  /// start of a later leg is the end of the previous one, rolled by the U-turn).
  std::vector<Eigen::Isometry3d> poses;
  std::vector<int> pose_leg;  ///< leg index of each pose
  double pan_rad = 0.0;       ///< pan of the legs (the same for all)
  double tilt_rad = 0.0;      ///< |tilt| of the legs (its sign alternates)
  double angle_per_step_rad = 0.0;
  double rise_per_step_m = 0.0;
  double radius_m = 0.0;  ///< achieved distance to the axis
};

/// Plans the acquisition.
/// @return "" or why no plan fits (invalid config, no rig geometry reaching the radius and rise).
std::string planAcquisition(const AcquisitionPlanConfig& config, AcquisitionPlan* plan);

/// Left camera pose such that the screw axis of `screw` (left frame) lies on the world line through axis_point_w
/// along axis_direction_w, with the camera centre at `azimuth_rad` around it (counter-clockwise seen from above, from
/// world x) and `height_m` from axis_point_w along axis_direction_w. The screw then turns the camera counter-clockwise
/// about axis_direction_w.
Eigen::Isometry3d alignScrewWithAxis(const ScrewMotion& screw, const Eigen::Vector3d& axis_point_w,
                                     const Eigen::Vector3d& axis_direction_w, double azimuth_rad, double height_m);

}  // namespace trajectory
}  // namespace exocet_servo
