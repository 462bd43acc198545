/**
 * @file stereo_rectification.h
 * @brief Rectification of a calibrated pair (2D4 report section 3.2.4): cv::stereoRectify (Bouguet) for the
 * rotations and new projections, cv::initUndistortRectifyMap for the lookup maps. After rectification a match lies
 * on the same row in both images. No ROS in it.
 */
#pragma once

#include <vector>

#include <opencv2/core.hpp>

#include "exocet_stereo/geometry/stereo_rig.h"

namespace exocet_stereo {
namespace geometry {

/// Rectifying transforms and maps of a rig.
struct Rectification {
  cv::Size image_size;
  cv::Mat R1, R2, P1, P2, Q;  ///< as returned by cv::stereoRectify
  cv::Rect valid_left, valid_right;
  cv::Mat map_left_x, map_left_y, map_right_x, map_right_y;  ///< CV_32FC1 maps for cv::remap

  /// Baseline (rig units) and focal (px) of the rectified pair: depth = focal * baseline / disparity.
  double baseline() const;
  double focal_px() const { return P1.at<double>(0, 0); }
};

/**
 * @brief Rectification of the rig.
 * @param alpha cv::stereoRectify's free scaling, -1 (default) or [0, 1]: 0 keeps only valid pixels, 1 keeps all
 * @throws std::invalid_argument if the rig has no extrinsics or alpha is out of range.
 */
Rectification computeRectification(const StereoRig& rig, double alpha = 0.0);

/// Remaps a pair into the rectified geometry (linear interpolation).
void rectifyPair(const Rectification& rect, const cv::Mat& left, const cv::Mat& right, cv::Mat& left_rect,
                 cv::Mat& right_rect);

/// Rectified positions of raw pixels of the left (right = false) or right image.
std::vector<cv::Point2f> rectifyPoints(const StereoRig& rig, const Rectification& rect,
                                       const std::vector<cv::Point2f>& pixels, bool right);

}  // namespace geometry
}  // namespace exocet_stereo
