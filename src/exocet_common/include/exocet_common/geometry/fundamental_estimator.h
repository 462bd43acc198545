/**
 * @file fundamental_estimator.h
 * @brief The fundamental matrix between two images from point matches: Hartley's normalised 8-point algorithm inside
 * RANSAC with a Sampson-distance threshold (2D3 sections 3.3.2 and 3.3.3). Our own implementation; OpenCV's
 * findFundamentalMat is only its reference in the tests and the benchmark. No ROS in it.
 *
 * Convention (OpenCV's): b^T F a = 0 for a point a of the first image and its match b in the second, pixels.
 */
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace exocet_common {
namespace geometry {

/**
 * @brief Hartley's normalised 8-point algorithm: both point sets are moved to their centroid and scaled to a mean
 * distance of sqrt(2), the 9 entries of F are the singular vector of the smallest singular value of the linear
 * system, the rank 2 is enforced by zeroing the smallest singular value of F, and F is brought back to pixels.
 * @return F with unit Frobenius norm.
 * @throws std::invalid_argument if fewer than 8 matches are given or the two lists differ in length.
 */
Eigen::Matrix3d eightPointFundamental(const std::vector<Eigen::Vector2d>& a, const std::vector<Eigen::Vector2d>& b);

/// Least squares over the matches listed in `subset` only (indices into a and b).
Eigen::Matrix3d eightPointFundamental(const std::vector<Eigen::Vector2d>& a, const std::vector<Eigen::Vector2d>& b,
                                      const std::vector<int>& subset);

/**
 * @brief Sampson distance (pixels) of a match to F: the first-order approximation of the distance in R^4 from
 * (a, b) to the nearest pair that satisfies the epipolar constraint exactly. Its square is the Sampson error.
 */
double sampsonDistance_px(const Eigen::Matrix3d& F, const Eigen::Vector2d& a, const Eigen::Vector2d& b);

/// RANSAC settings. validate() names a bad field and its allowed range.
struct FundamentalConfig {
  double threshold_px = 1.0;  ///< inlier if the Sampson distance is below this (> 0)
  double confidence = 0.999;  ///< probability that one sample is outlier-free when RANSAC stops, (0, 1)
  int max_iterations = 5000;  ///< upper bound of the adaptive number of samples (>= 1)
  int refinement_rounds = 5;  ///< final re-estimates on all inliers, until the inlier set stops changing (>= 1)
  uint64_t seed = 1;          ///< the sampling's random generator: same seed, same result

  std::string validate() const;
};

/// The outcome of one RANSAC estimate.
struct FundamentalResult {
  bool ok = false;                              ///< false: too few matches or inliers (see `failure`)
  std::string failure;                          ///< why it failed
  Eigen::Matrix3d F = Eigen::Matrix3d::Zero();  ///< b^T F a = 0, unit Frobenius norm, rank 2
  std::vector<bool> inliers;                    ///< one per match
  int inlier_count = 0;
  double rms_sampson_px = 0.0;  ///< RMS Sampson distance over the inliers
  int iterations = 0;           ///< RANSAC samples drawn
};

/**
 * @brief RANSAC around the normalised 8-point algorithm: minimal samples of 8 matches scored by the truncated
 * quadratic Sampson loss (MSAC), an adaptive number of samples N = log(1 - confidence) / log(1 - w^8) from the best
 * inlier ratio w so far, and a final least-squares re-estimate on all inliers repeated until the inlier set is
 * stable. Deterministic given the seed.
 */
class FundamentalEstimator {
 public:
  /// @throws std::invalid_argument with config.validate()'s message.
  explicit FundamentalEstimator(const FundamentalConfig& config);

  /// @throws std::invalid_argument if the two lists differ in length.
  FundamentalResult estimate(const std::vector<Eigen::Vector2d>& a, const std::vector<Eigen::Vector2d>& b) const;

  const FundamentalConfig& config() const { return config_; }

 private:
  FundamentalConfig config_;
};

}  // namespace geometry
}  // namespace exocet_common
