/**
 * @file pinhole_view.h
 * @brief A calibrated pinhole view x ~ K (R X + t) (Middlebury's and OpenCV's convention: R, t map world to camera),
 * with projection helpers shared by matching, triangulation and bundle adjustment. No ROS in it.
 */
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

namespace exocet_stereo {
namespace geometry {

/// 3x4 projection matrix P = K [R | t].
using Projection = Eigen::Matrix<double, 3, 4>;

/// One calibrated view: intrinsics K (pixels) and the world-to-camera pose (R, t), so x ~ K (R X + t).
struct PinholeView {
  std::string name;                                 ///< image file name (may be empty)
  Eigen::Matrix3d K = Eigen::Matrix3d::Identity();  ///< intrinsics, pixels
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  ///< world-to-camera rotation
  Eigen::Vector3d t = Eigen::Vector3d::Zero();      ///< world-to-camera translation, world units

  /// P = K [R | t].
  Projection projection() const;
  /// Optical centre in the world frame, -R^T t.
  Eigen::Vector3d centre() const { return -R.transpose() * t; }
  /// Depth of a world point along the optical axis (world units); > 0 in front of the camera.
  double depth(const Eigen::Vector3d& X) const { return (R * X + t).z(); }
  /// Pixel of a world point (no check of the depth sign).
  Eigen::Vector2d project(const Eigen::Vector3d& X) const;
};

/**
 * @brief Reads a Middlebury multi-view parameter file ("<n>" then one line per image:
 * "name k11..k33 r11..r33 t1 t2 t3").
 * @throws std::runtime_error naming the file and the line if it cannot be read or a line is malformed.
 */
std::vector<PinholeView> readMiddleburyViews(const std::string& par_path);

}  // namespace geometry
}  // namespace exocet_stereo
