/**
 * @file point_matcher.h
 * @brief SIFT point matches between the reference image (taken by one camera) and a current image (taken by another
 * camera, other intrinsics): Lowe's ratio test, mutual consistency, then RANSAC on the fundamental matrix (the two
 * views are of a 3D scene from two poses, so no homography holds). The reference keypoints are computed once. No ROS
 * in it.
 */
#pragma once

#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>

namespace exocet_servo {
namespace vision {

/// Matcher parameters; validate() lists the allowed ranges.
struct MatcherConfig {
  int max_features = 2000;           ///< SIFT keypoints kept per image (strongest), [8, 100000]
  double ratio = 0.75;               ///< Lowe's ratio test, (0, 1]
  bool cross_check = true;           ///< keep only mutual best matches
  double ransac_threshold_px = 1.0;  ///< distance to the epipolar line, (0, 20]
  double ransac_confidence = 0.999;  ///< (0, 1)
  int min_matches = 20;              ///< fewer inliers is a failure, [8, 100000]
  double duplicate_distance_px =
      1.0;  ///< reference keypoints closer than this are one point (SIFT orientations), [0, 10]
  /// "" or every bad field with its allowed range ("; "-joined).
  std::string validate() const;
};

/// Matched points, one to one.
struct PointMatches {
  std::vector<cv::Point2f> reference_px;
  std::vector<cv::Point2f> current_px;
  int reference_keypoints = 0;
  int current_keypoints = 0;
  int ratio_matches = 0;  ///< before RANSAC
  std::string error;      ///< "" on success, else why matching failed (too few keypoints or inliers)
  bool ok() const { return error.empty(); }
};

/// SIFT matcher with a fixed reference image.
class PointMatcher {
 public:
  /// @throws std::invalid_argument with config.validate()'s message.
  explicit PointMatcher(const MatcherConfig& config = MatcherConfig());

  /// Detects and describes the reference image (8-bit gray). @return "" or why it is unusable.
  std::string setReference(const cv::Mat& reference_image);

  /// Matches a current image (8-bit gray) against the reference.
  PointMatches match(const cv::Mat& current_image) const;

  const MatcherConfig& config() const { return config_; }

 private:
  MatcherConfig config_;
  cv::Ptr<cv::SIFT> sift_;
  std::vector<cv::KeyPoint> reference_keypoints_;
  cv::Mat reference_descriptors_;
};

}  // namespace vision
}  // namespace exocet_servo
