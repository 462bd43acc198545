/**
 * @file pose_bound.h
 * @brief Cramer-Rao lower bound of the camera pose measured from one image of known 3D points with gaussian pixel
 * noise, with the intrinsics known (calibrated servo) or unknown (what an intrinsics-free servo can at best do: the
 * 5 intrinsic parameters are nuisance parameters). The servo converges where the current image matches the noisy
 * reference, so its final pose error cannot beat this bound (about sqrt(2) times it, reference and final image
 * both noisy). No ROS in it.
 */
#pragma once

#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "exocet_servo/sim/point_scene.h"

namespace exocet_servo {
namespace sim {

/// Standard deviations of the pose components (camera frame).
struct PoseBound {
  Eigen::Vector3d translation_mm = Eigen::Vector3d::Zero();         ///< along the camera x, y, z
  Eigen::Vector3d rotation_deg = Eigen::Vector3d::Zero();           ///< about the camera x, y, z
  double position_rms_mm() const { return translation_mm.norm(); }  ///< sqrt(E|dt|^2)
  double rotation_rms_deg() const { return rotation_deg.norm(); }
};

/// Bound for one image of points_w taken by `camera` at world_T_camera with N(0, noise_px^2) on each coordinate.
/// @param intrinsics_known true: calibrated; false: fx, fy, cx, cy and skew estimated jointly with the pose.
PoseBound poseCramerRao(const std::vector<Eigen::Vector3d>& points_w, const PinholeCamera& camera,
                        const Eigen::Isometry3d& world_T_camera, double noise_px, bool intrinsics_known);

}  // namespace sim
}  // namespace exocet_servo
