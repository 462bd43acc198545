/**
 * @file sift_reference.h
 * @brief An independent reference for the motion between two real images, where there is no ground truth: SIFT
 * features, ratio-test matches, a homography by RANSAC (OpenCV's MAGSAC++) on its inliers. Slow; for tests and
 * benchmarks. No ROS in it.
 */
#pragma once

#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

namespace exocet_mosaic {
namespace registration {

struct SiftReference {
  bool found = false;
  Eigen::Matrix3d pixel_matrix = Eigen::Matrix3d::Identity();  ///< x_B ~ pixel_matrix x_A
  int matches = 0;                                             ///< ratio-test matches
  int inliers = 0;                                             ///< RANSAC inliers (1 px)
};

/**
 * SIFT features of `a` and `b` (8-bit grey; at most max_features each, 0: all; OpenCV's contrast threshold) matched
 * by Lowe's ratio test: the matched points of `a` in pa, of `b` in pb (cleared first). Returns the smaller feature
 * count of the two images.
 */
int siftRatioMatches(const cv::Mat& a, const cv::Mat& b, int max_features, double contrast_threshold, double ratio,
                     std::vector<cv::Point2f>* pa, std::vector<cv::Point2f>* pb);

/// The reference homography from `a` to `b` (8-bit grey); found = false with fewer than 20 matches.
SiftReference siftReferenceHomography(const cv::Mat& a, const cv::Mat& b);

}  // namespace registration
}  // namespace exocet_mosaic
