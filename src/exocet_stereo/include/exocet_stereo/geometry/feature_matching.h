/**
 * @file feature_matching.h
 * @brief SIFT features (cv::SIFT) and their matching between two images with Lowe's ratio test and a mutual
 * (left-right) consistency check, 2D4 report section 3.2.1. No ROS in it.
 */
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>

namespace exocet_stereo {
namespace geometry {

/// Detection and matching settings. validate() lists every bad field with its allowed range.
struct SiftMatchingConfig {
  int max_features = 4000;           ///< strongest keypoints kept per image, [16, 100000]
  double contrast_threshold = 0.04;  ///< cv::SIFT contrast threshold, (0, 1)
  double edge_threshold = 10.0;      ///< cv::SIFT edge threshold, [1, 100]
  double ratio = 0.8;                ///< Lowe's ratio: best / second-best distance below this, (0, 1]
  bool mutual = true;                ///< keep a match only if it is also the best match in the other direction

  std::string validate() const;
};

/// Keypoints and descriptors of one image.
struct ImageFeatures {
  std::vector<cv::KeyPoint> keypoints;
  cv::Mat descriptors;  ///< one CV_32F row of 128 per keypoint

  /// Pixel position of keypoint i.
  Eigen::Vector2d pixel(int i) const { return {keypoints[i].pt.x, keypoints[i].pt.y}; }
};

/**
 * @brief SIFT keypoints of an image (8-bit gray or BGR; converted to gray).
 * @throws std::invalid_argument if the image is empty or the config invalid.
 */
ImageFeatures detectSift(const cv::Mat& image, const SiftMatchingConfig& config = SiftMatchingConfig());

/**
 * @brief Matches of `a` into `b` that pass the ratio test and, if configured, the mutual check. queryIdx indexes a,
 * trainIdx indexes b. Empty if either set has fewer than 2 keypoints.
 */
std::vector<cv::DMatch> matchSift(const ImageFeatures& a, const ImageFeatures& b,
                                  const SiftMatchingConfig& config = SiftMatchingConfig());

}  // namespace geometry
}  // namespace exocet_stereo
