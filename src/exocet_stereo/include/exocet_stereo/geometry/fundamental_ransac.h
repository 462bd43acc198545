/**
 * @file fundamental_ransac.h
 * @brief Robust fundamental matrix for one image pair of a multi-view set (2D4 report section 3.2.2): the project's
 * own Hartley normalised 8-point algorithm inside MSAC (adaptive number of samples, Sampson distance, refit on the
 * inliers), shared with the mosaic's camera self-calibration (exocet_common/geometry/fundamental_estimator.h).
 * OpenCV's FM_RANSAC is the reference in the tests. No ROS in it.
 *
 * Convention (OpenCV's): b^T F a = 0 for a pixel a of the first image and its match b in the second.
 */
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace exocet_stereo {
namespace geometry {

/// RANSAC settings. validate() lists every bad field with its allowed range.
struct FundamentalRansacConfig {
  double threshold_px = 1.0;  ///< inlier if the Sampson distance is below this, (0, 50]
  double confidence = 0.999;  ///< probability of drawing one outlier-free sample before stopping, (0, 1)
  int max_samples = 2000;     ///< upper bound of the adaptive sample count, [1, 100000]
  int refits = 3;             ///< refits on all inliers while the inlier set changes, [0, 20]
  uint64_t seed = 7;          ///< random generator seed: same seed, same result

  std::string validate() const;
};

/// Outcome of one robust estimate.
struct FundamentalFit {
  bool ok = false;                              ///< false: fewer than 8 matches or no model (see `failure`)
  std::string failure;                          ///< why it failed
  Eigen::Matrix3d F = Eigen::Matrix3d::Zero();  ///< b^T F a = 0, unit Frobenius norm
  std::vector<bool> inliers;                    ///< one per match
  int inlier_count = 0;
  double rms_sampson_px = 0.0;  ///< RMS Sampson distance over the inliers
  int samples = 0;              ///< minimal samples drawn
};

/**
 * @brief Estimates F from matched pixels a[i] <-> b[i].
 * @throws std::invalid_argument if the lists differ in length or the config is invalid.
 */
FundamentalFit fitFundamentalRansac(const std::vector<Eigen::Vector2d>& a, const std::vector<Eigen::Vector2d>& b,
                                    const FundamentalRansacConfig& config = FundamentalRansacConfig());

}  // namespace geometry
}  // namespace exocet_stereo
