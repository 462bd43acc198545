/**
 * @file motion_estimate.h
 * @brief The result of registering two images: the motion, its covariance and quality, or an explicit failure.
 * No ROS in it.
 */
#pragma once

#include <string>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "exocet_mosaic/registration/motion_model.h"

namespace exocet_mosaic {
namespace registration {

enum class RegistrationMethod { kKlt, kRmr, kAuto };

/// "klt", "rmr", "auto".
std::string toString(RegistrationMethod method);
/// Inverse of toString; throws std::invalid_argument naming the allowed values.
RegistrationMethod registrationMethodFromString(const std::string& name);

/// Why a registration failed. A failure is never reported as a (confident) motion.
enum class FailureReason {
  kNone,
  kNoPreviousFrame,   ///< first image after a reset: nothing to register against
  kInvalidInput,      ///< empty image, wrong type, images of different sizes
  kTooDark,           ///< too little signal (mean or contrast below the threshold)
  kTooLittleTexture,  ///< too few pixels/features with usable gradients
  kTooFewTracks,      ///< KLT: too few features tracked into the current image
  kTooFewInliers,     ///< the robust fit kept too small a fraction or count of the observations
  kMotionTooLarge,    ///< the estimated motion exceeds the configured bounds (or the pyramid's capture range)
  kNotConverged,      ///< the iterations diverged or did not converge
  kInconsistent,      ///< the estimate is not consistent with its data (residual too large, ill-conditioned)
};

/// Stable snake_case name ("too_little_texture"...), used in messages and JSON.
std::string toString(FailureReason reason);

/// Motion from the previous image A to the current image B.
struct MotionEstimate {
  bool failed = true;
  FailureReason failure = FailureReason::kNoPreviousFrame;
  std::string failure_detail;  ///< human-readable: what was measured against which threshold

  RegistrationMethod method = RegistrationMethod::kKlt;  ///< the method that produced this result
  MotionModel model = MotionModel::kSimilarity;
  Eigen::Vector2d centre_px = Eigen::Vector2d::Zero();   ///< origin of the parameterisation (see motion_model.h)
  Eigen::VectorXd parameters;                            ///< parameterCount(model) values
  Eigen::MatrixXd covariance;                            ///< of the parameters (pixel units)
  Eigen::Matrix3d pixel_matrix = Eigen::Matrix3d::Identity();  ///< x_B ~ pixel_matrix * x_A (pixel coordinates)

  int observations = 0;         ///< KLT: tracked points; RMR: pixels used at the finest level
  int inliers = 0;              ///< observations kept by the robust fit
  double inlier_fraction = 0.0;
  double residual_scale = 0.0;  ///< robust scale of the inlier residuals: pixels (KLT) or grey levels (RMR)
  int iterations = 0;           ///< IRLS iterations in all
  double elapsed_ms = 0.0;      ///< wall time of the estimation

  /// RMR: final robust weights in [0, 1] at the finest level used (CV_32F, that level's size; 0 = outlier such as a
  /// fish or a particle; NaN where a pixel was not evaluated, see rmr_registrar.h). KLT: empty.
  cv::Mat weights;
};

}  // namespace registration
}  // namespace exocet_mosaic
