/**
 * @file planar_self_calibrator.h
 * @brief Camera intrinsics from the homographies of a flat seabed (B. Triggs, "Autocalibration from planar scenes",
 * ECCV 1998), for the case where the fundamental matrix is degenerate and Mendonca-Cipolla cannot work.
 *
 * The plane's two circular points (its points at infinity (1, +-i, 0) in any Euclidean frame of the plane) are seen
 * in key frame k at x_k = H_k0 x_0, and every image of a circular point lies on the image of the absolute conic
 * omega = K^-T K^-1: x_k^T omega x_k = 0 (one complex equation per key frame). The unknowns are K (alpha_u, alpha_v,
 * u0, v0) and the complex point x_0 = (1, c2, c3) of the reference key frame (4 real numbers); each key frame gives
 * two real equations, so at least 5 key frames are needed for an over-determined problem. The scene must be seen
 * under different tilts (roll and pitch): fronto-parallel views of a plane only fix the aspect ratio. No ROS in it.
 */
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "exocet_mosaic/selfcal/mendonca_cipolla_calibrator.h"

namespace exocet_mosaic {
namespace selfcal {

/// One key-frame pair's plane homography: b ~ H a, pixels.
struct PairHomography {
  int key_a = 0, key_b = 0;
  Eigen::Matrix3d H = Eigen::Matrix3d::Identity();
  double weight = 1.0;  ///< confidence (> 0), e.g. inliers; the spanning tree prefers heavy pairs
};

/// Settings. validate() names a bad field and its allowed range.
struct PlanarCalibrationConfig {
  double initial_hfov_deg = 60.0;  ///< nominal horizontal field of view of the initial guess (deg, (1, 179))
  std::vector<double> focal_start_factors = {0.5, 0.7, 1.0, 1.4, 2.0};  ///< starts, multiples of the nominal focal
  int max_iterations = 300;  ///< Levenberg-Marquardt iterations per start (>= 1)
  int min_key_frames = 5;    ///< key frames linked to the reference by homographies (>= 4)
  std::string validate() const;
};

/**
 * @brief Links every key frame to the reference (the lowest key frame index) through a spanning tree of the pairs
 * (breadth first, heaviest pairs first), then minimises sum_k |x_k^T omega x_k / x_k^H omega x_k|^2 with Ceres from
 * several focal lengths, in coordinates normalised by the nominal camera for conditioning. Uncertainty as for
 * MendoncaCipollaCalibrator (ceres::Covariance of K scaled by the residual variance).
 */
class PlanarSelfCalibrator {
 public:
  /// @throws std::invalid_argument with config.validate()'s message.
  explicit PlanarSelfCalibrator(const PlanarCalibrationConfig& config);

  /**
   * @throws std::invalid_argument for an empty image size or a non-finite H.
   * @throws std::runtime_error if fewer than min_key_frames key frames are linked or no start converges to an
   * admissible K (the message says which).
   */
  IntrinsicsEstimate calibrate(const std::vector<PairHomography>& pairs, const cv::Size& image_size) const;

  const PlanarCalibrationConfig& config() const { return config_; }

 private:
  PlanarCalibrationConfig config_;
};

}  // namespace selfcal
}  // namespace exocet_mosaic
