/**
 * @file depth_lookup.h
 * @brief Depth of an image point read from a depth map, refused across depth discontinuities: a point on a
 * silhouette mixes foreground and background and is no 3D point. The servo's interaction matrix needs a depth per
 * point; a depth camera, a stereo depth map or the simulator's renderer supplies the map. No ROS in it.
 */
#pragma once

#include <Eigen/Core>
#include <opencv2/core.hpp>

namespace exocet_servo {
namespace vision {

/**
 * Depth (m) at a sub-pixel position of `depth_m` (CV_32FC1, Z in the camera frame; non-finite where unknown),
 * bilinear, when the (2 r + 2)^2 square of pixels around it is all finite and holds no discontinuity
 * (max / min <= 1 + max_relative_step).
 * @return false outside the image (with its margin), where a depth is unknown, or across a discontinuity.
 */
bool screenedDepthAt(const cv::Mat& depth_m, const Eigen::Vector2d& px, int radius_px, double max_relative_step,
                     double* depth);

}  // namespace vision
}  // namespace exocet_servo
