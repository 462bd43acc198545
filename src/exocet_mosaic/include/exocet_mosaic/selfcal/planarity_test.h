/**
 * @file planarity_test.h
 * @brief Whether two images of the seabed are related by a homography as well as by a fundamental matrix: a flat
 * seabed (or a pure rotation, or too short a baseline) makes the fundamental matrix degenerate, and the
 * self-calibration from it meaningless. Model selection by Torr's Geometric Robust Information Criterion (GRIC).
 * No ROS in it.
 */
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "exocet_common/geometry/fundamental_estimator.h"

namespace exocet_mosaic {
namespace selfcal {

// The fundamental-matrix estimator is the shared one (exocet_common), which the stereo side uses too.
using exocet_common::geometry::FundamentalConfig;
using exocet_common::geometry::FundamentalEstimator;
using exocet_common::geometry::FundamentalResult;
using exocet_common::geometry::eightPointFundamental;
using exocet_common::geometry::sampsonDistance_px;

/**
 * @brief Sampson distance (pixels) of a match to the homography H (b ~ H a): the first-order distance in R^4 from
 * (a, b) to the nearest pair that H maps exactly, comparable to sampsonDistance_px() for F.
 */
double homographySampsonDistance_px(const Eigen::Matrix3d& H, const Eigen::Vector2d& a, const Eigen::Vector2d& b);

/// Settings of the planarity test. validate() names a bad field and its allowed range.
struct PlanarityConfig {
  /// RANSAC threshold of the homography fit, in units of the noise sigma (> 0). Its reprojection error in the second
  /// image has about 2 sigma^2 per coordinate (both images' noise): 3.5 sigma keeps 95 % of the true inliers.
  double homography_threshold_sigmas = 3.5;
  /// Noise of the matches (pixels, 1 sigma) for GRIC; 0: estimated from the fundamental matrix's inliers
  /// (1.4826 x median Sampson distance), floored at min_noise_px.
  double noise_sigma_px = 0.0;
  double min_noise_px = 0.1;  ///< floor of the estimated noise (> 0): KLT is not better than this
  std::string validate() const;
};

/// The verdict for one image pair.
struct PlanarityVerdict {
  bool planar = false;    ///< the homography explains the matches as well as F (GRIC_H <= GRIC_F)
  double gric_f = 0.0;    ///< Torr's GRIC of the fundamental matrix (lower is better)
  double gric_h = 0.0;    ///< Torr's GRIC of the homography
  double sigma_px = 0.0;  ///< the noise used
  Eigen::Matrix3d H = Eigen::Matrix3d::Identity();  ///< b ~ H a
  int homography_inliers = 0;
  /// Median homography Sampson distance over F's inliers: the typical parallax the best plane leaves (about
  /// 1.18 sigma on a plane; a median, so that the few wrong matches F accepts do not dominate it).
  double median_homography_px = 0.0;
};

/**
 * @brief Fits a homography (cv::findHomography, RANSAC then Levenberg-Marquardt on its inliers) and compares it with
 * `fundamental` by GRIC (P. Torr, "An assessment of information criteria for motion model selection", CVPR 1997):
 *   GRIC = sum_i min(e_i^2 / sigma^2, 2 (r - d)) + d n ln(r) + k ln(r n),
 * r = 4 (two image points), d = 3, k = 7 for F and d = 2, k = 8 for H, e_i the Sampson distance of each match.
 * A homography explains n matches with two constraints each, F with one: on a plane, F's extra freedom buys a
 * residual of about n sigma^2 less, which costs n ln 4 more; with relief, H's residuals grow with the parallax.
 * @throws std::invalid_argument if the lists differ in length.
 */
PlanarityVerdict assessPlanarity(const std::vector<Eigen::Vector2d>& a, const std::vector<Eigen::Vector2d>& b,
                                 const FundamentalResult& fundamental, const PlanarityConfig& config);

}  // namespace selfcal
}  // namespace exocet_mosaic
