/**
 * @file relative_pose.h
 * @brief The extrinsics between two key frames from the essential matrix E = K^T F K = [t]x R (2D3 section 3.3.5):
 * the translation direction first (the left null vector of E: E^T t = 0), then the rotation from the SVD of E, the
 * sign of t and the choice between the two rotations made by the cheirality test (the matched seabed points must lie
 * in front of both cameras). No ROS in it.
 *
 * Convention: x_b = R x_a + t for a point in camera a's frame (z forward, metres) seen in camera b's frame;
 * b^T F a = 0 for matching pixels. The length of t cannot be known from images: it is a unit vector.
 */
#pragma once

#include <vector>

#include <Eigen/Core>

namespace exocet_mosaic {
namespace selfcal {

struct RelativePose {
  bool ok = false;                                      ///< false: no solution puts most points in front
  Eigen::Matrix3d R_b_a = Eigen::Matrix3d::Identity();  ///< rotation from camera a to camera b
  Eigen::Vector3d t_b_a = Eigen::Vector3d::Zero();      ///< unit translation direction (camera a's centre in b: -R^T t)
  int points_in_front = 0;                              ///< matches triangulated in front of both cameras
  int points_tested = 0;
};

/**
 * @brief Decomposes E = K^T F K (F rank 2, pixels; K the intrinsics) into (R, t) with the cheirality test over the
 * listed matches (pixels; `use` selects which, empty = all). @throws std::invalid_argument on mismatched lists.
 */
RelativePose relativePoseFromFundamental(const Eigen::Matrix3d& F, const Eigen::Matrix3d& K,
                                         const std::vector<Eigen::Vector2d>& a, const std::vector<Eigen::Vector2d>& b,
                                         const std::vector<bool>& use = {});

/// The essential matrix [t]x R of a pose, for tests: x_b^T E x_a = 0 in normalised coordinates.
Eigen::Matrix3d essentialFromPose(const Eigen::Matrix3d& R_b_a, const Eigen::Vector3d& t_b_a);

}  // namespace selfcal
}  // namespace exocet_mosaic
