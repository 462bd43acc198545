/**
 * @file mendonca_cipolla_calibrator.h
 * @brief Camera intrinsics from fundamental matrices alone (Mendonca and Cipolla, "A simple technique for
 * self-calibration", CVPR 1999; 2D3 section 3.3.4): the essential matrix E = K^T F K of a calibrated camera has two
 * equal non-zero singular values, so K is found by minimising, over all image pairs,
 *   C(K) = sum_ij w_ij ((s1_ij - s2_ij) / s2_ij)^2,   s1 >= s2 the non-zero singular values of K^T F_ij K,
 * with Ceres. K = [alpha_u 0 u0; 0 alpha_v v0; 0 0 1] (no skew). No ROS in it.
 */
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

namespace exocet_mosaic {
namespace selfcal {

/// One image pair's fundamental matrix (b^T F a = 0, pixels) and the confidence in it.
struct PairFundamental {
  int key_a = 0, key_b = 0;  ///< which key frames (for reports)
  Eigen::Matrix3d F = Eigen::Matrix3d::Zero();
  double weight = 1.0;  ///< w_ij (> 0); normalised to a mean of 1 by the calibrator
};

/// The four intrinsics of the pinhole model, pixels.
struct Intrinsics {
  double alpha_u = 0.0, alpha_v = 0.0;  ///< focal length in pixels along u and v
  double u0 = 0.0, v0 = 0.0;            ///< principal point (OpenCV convention: (0, 0) = centre of top-left pixel)
  Eigen::Matrix3d K() const;
};

/**
 * @brief Whether a solution is a plausible camera: focal lengths within [0.05, 50] x the image width, aspect ratio
 * alpha_u / alpha_v within [0.5, 2], principal point inside the image. Minimisers that leave this set have followed
 * a degenerate direction of their cost.
 */
bool isAdmissible(const Intrinsics& k, const cv::Size& image_size);

/// The estimate with its uncertainty.
struct IntrinsicsEstimate {
  Intrinsics value;
  Intrinsics sigma;                                      ///< 1-sigma of each parameter (pixels)
  Eigen::Matrix4d covariance = Eigen::Matrix4d::Zero();  ///< of (alpha_u, alpha_v, u0, v0), pixels^2
  double cost = 0.0;                                     ///< C(K) at the solution
  double residual_rms = 0.0;                             ///< RMS of sqrt(w) (s1 - s2) / s2 over the pairs
  int pairs = 0;                                         ///< pairs in the cost
  int starts = 0;                                        ///< starting points tried
  int starts_converged = 0;                              ///< of which converged to an admissible K
  bool covariance_ok = false;  ///< false: the problem is singular (a critical motion), sigmas infinite
};

/// Settings. validate() names a bad field and its allowed range.
struct MendoncaCipollaConfig {
  double initial_hfov_deg = 60.0;  ///< nominal horizontal field of view of the initial guess (deg, (1, 179))
  /// The initial focal length is tried at each of these multiples of the nominal one (robustness to the guess).
  std::vector<double> focal_start_factors = {0.5, 0.7, 1.0, 1.4, 2.0};
  int max_iterations = 200;  ///< Levenberg-Marquardt iterations per start (>= 1)
  std::string validate() const;
};

/**
 * @brief Minimises C(K) from several initial focal lengths (principal point at the image centre, square pixels) and
 * keeps the lowest cost among admissible solutions (positive focal lengths, aspect ratio within [0.5, 2], principal
 * point inside the image). The 1-sigma of each parameter comes from ceres::Covariance (the inverse of J^T J at the
 * solution) scaled by the residual variance 2 C / (m - 4) of the m pairs.
 */
class MendoncaCipollaCalibrator {
 public:
  /// @throws std::invalid_argument with config.validate()'s message.
  explicit MendoncaCipollaCalibrator(const MendoncaCipollaConfig& config);

  /**
   * @throws std::invalid_argument for an empty image size, fewer than 3 pairs (4 unknowns, 2 constraints per pair,
   * and one more for the variance) or a non-finite F or weight.
   * @throws std::runtime_error if no start converges to an admissible K (message says why).
   */
  IntrinsicsEstimate calibrate(const std::vector<PairFundamental>& pairs, const cv::Size& image_size) const;

  /// C(K) with the given weights (not normalised): for tests and diagnostics.
  static double cost(const Intrinsics& k, const std::vector<PairFundamental>& pairs);

  const MendoncaCipollaConfig& config() const { return config_; }

 private:
  MendoncaCipollaConfig config_;
};

}  // namespace selfcal
}  // namespace exocet_mosaic
