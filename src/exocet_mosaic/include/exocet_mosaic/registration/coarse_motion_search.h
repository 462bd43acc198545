/**
 * @file coarse_motion_search.h
 * @brief A global search for the motion between two images that a local tracker cannot reach (a large shift, a
 * rotation, no prediction): SIFT features on a reduced copy of each image, ratio-test matches, a similarity fitted by
 * RANSAC (cv::estimateAffinePartial2D). Its result is a starting point for KLT, not a registration: KLT refines it
 * to sub-pixel on the full-resolution images. No ROS in it.
 */
#pragma once

#include <string>

#include <Eigen/Core>
#include <Eigen/LU>
#include <opencv2/core.hpp>

namespace exocet_mosaic {
namespace registration {

/// Parameters of the coarse search. validate() lists the allowed ranges.
struct CoarseSearchConfig {
  /// The images are reduced (INTER_AREA) to at most this width: the search is for the motion to a pixel or two, and
  /// SIFT costs in proportion to the pixels, [64, 100000].
  int width_px = 480;
  int max_features = 800;  ///< SIFT features per image, [20, 100000]
  /// SIFT's contrast threshold, (0, 1): seabed texture is faint; OpenCV's 0.04 keeps only a few dozen points of a
  /// 384x288 Sparus frame.
  double contrast_threshold = 0.01;
  double ratio = 0.8;                ///< Lowe's ratio test, (0, 1]
  double ransac_px = 3.0;            ///< RANSAC inlier distance on the reduced images, (0, 50]
  int min_inliers = 12;              ///< fewer RANSAC inliers: not found, [3, 100000]
  double min_inlier_fraction = 0.2;  ///< of the ratio-test matches, [0, 1]

  /// Empty if usable, otherwise every bad field with its allowed range, separated by "; ".
  std::string validate() const;
};

/// The search's outcome.
struct CoarseMotion {
  bool found = false;
  Eigen::Matrix3d pixel_matrix = Eigen::Matrix3d::Identity();  ///< full-resolution pixels, x_B ~ pixel_matrix x_A
  int matches = 0;                                             ///< ratio-test matches
  int inliers = 0;                                             ///< RANSAC inliers
  double elapsed_ms = 0.0;
  std::string detail;  ///< why not found, or what was found
};

/// The similarity from image `a` to image `b` (8-bit grey, the same size). Never throws for image content; a config
/// that does not validate throws std::invalid_argument.
CoarseMotion coarseMotionSearch(const cv::Mat& a, const cv::Mat& b, const CoarseSearchConfig& config = {});

}  // namespace registration
}  // namespace exocet_mosaic
