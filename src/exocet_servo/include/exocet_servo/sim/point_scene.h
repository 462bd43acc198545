/**
 * @file point_scene.h
 * @brief Point-level scene for the servo simulation (2D4 report 2.4, figures 4-5): a vent-like 3D point set (a
 * rough, tapering chimney with a vertical axis), pinhole cameras with their own intrinsics, projection with gaussian
 * pixel noise, and a look-at helper. World frame: z up; camera frame: x right, y down, z forward. No ROS in it.
 */
#pragma once

#include <random>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace exocet_servo {
namespace sim {

/// A hydrothermal-vent-like chimney: points on a truncated cone with a rough radius.
struct VentConfig {
  Eigen::Vector3d base_m = Eigen::Vector3d::Zero();  ///< centre of the base (world)
  double height_m = 0.3;                             ///< (0, 100]
  double base_radius_m = 0.1;                        ///< (0, 100]
  double top_radius_m = 0.05;                        ///< (0, 100]
  double roughness = 0.15;                           ///< relative random variation of the radius, [0, 0.9]
  int points = 60;                                   ///< [8, 100000]
  unsigned seed = 1;
  std::string validate() const;
};

/// The points of the chimney (world frame). The heights are stratified so that any 8 of them are not coplanar in
/// practice.
/// @throws std::invalid_argument with config.validate()'s message.
std::vector<Eigen::Vector3d> makeVentPoints(const VentConfig& config);

/// Upper triangular intrinsic matrix [fx s cx; 0 fy cy; 0 0 1].
Eigen::Matrix3d intrinsics(double fx_px, double fy_px, double cx_px, double cy_px, double skew_px = 0.0);

/// A pinhole camera without distortion.
struct PinholeCamera {
  Eigen::Matrix3d k = intrinsics(800.0, 800.0, 319.5, 239.5);
  int width_px = 640;
  int height_px = 480;
};

/// Projection of one image.
struct Projection {
  std::vector<Eigen::Vector2d> points_px;  ///< NaN for a point behind the camera
  std::vector<double> depths_m;            ///< Z in the camera frame
};

/// Projects world points into a camera at world_T_camera, adding N(0, noise_px^2) to each coordinate when rng is given.
Projection project(const PinholeCamera& camera, const Eigen::Isometry3d& world_T_camera,
                   const std::vector<Eigen::Vector3d>& points_w, double noise_px = 0.0, std::mt19937* rng = nullptr);

/// Pose of a camera at `position` looking at `target`, with the image "up" (-y) as close as possible to `up`.
Eigen::Isometry3d lookAt(const Eigen::Vector3d& position, const Eigen::Vector3d& target,
                         const Eigen::Vector3d& up = Eigen::Vector3d::UnitZ());

/// Position (mm) and rotation (deg) distances between two poses.
struct PoseError {
  double position_mm = 0.0;
  double rotation_deg = 0.0;
};
PoseError poseError(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b);

}  // namespace sim
}  // namespace exocet_servo
