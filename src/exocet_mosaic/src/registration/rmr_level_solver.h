/**
 * @file rmr_level_solver.h
 * @brief Internal to the RMR registration: the robust incremental estimation at one pyramid level (inverse
 * compositional Gauss-Newton, IRLS with Tukey's biweight), and the statistics of the final fit. No ROS in it.
 */
#pragma once

#include <limits>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "exocet_mosaic/registration/motion_estimate.h"
#include "exocet_mosaic/registration/motion_model.h"
#include "rmr_frame.h"

namespace exocet_mosaic {
namespace registration {
namespace internal {

/// The running estimate: B(W(x)) = gain * A(x) + offset, W given by `centred` (coordinates centred on the level's
/// centre, RmrFrame::centre).
struct RmrState {
  Eigen::Matrix3d centred = Eigen::Matrix3d::Identity();
  double gain = 1.0;
  double offset = 0.0;
};

struct RmrSolverSettings {
  MotionModel model = MotionModel::kAffine;
  bool illumination = true;
  int max_iterations = 10;
  double convergence_px = 0.01;    ///< stop when the increment moves no image corner by more (level pixels)
  double tukey_constant = 4.6851;  ///< in units of the robust scale
  double min_scale = 1.0;          ///< floor of the robust scale (grey levels)
  int min_evaluated = 50;          ///< fewer reference pixels landing in the other image: the motion is too large
  double divergence_px = 1e9;      ///< an image corner moved further than this (level pixels): diverged
  double max_step_px = 1e9;        ///< longest corner displacement of one increment (level pixels), longer ones damped
  bool translation_only = false;   ///< estimate the translation (and illumination) only, the rest kept as is
};

struct RmrLevelResult {
  int iterations = 0;
  bool converged = false;
  double last_increment_px = std::numeric_limits<double>::infinity();
  FailureReason failure = FailureReason::kNone;
  std::string detail;
  // Of the last evaluation (at the estimate before the last, small, increment):
  int evaluated = 0;
  double scale = 0.0;             ///< robust residual scale (grey levels)
  Eigen::MatrixXd normal_matrix;  ///< J^T W J of all the parameters (geometric first, then gain and offset)
};

/// Statistics of the final fit at the finest level.
struct RmrFitStatistics {
  int evaluated = 0;
  int inliers = 0;                     ///< weight > 0.5
  double correlation = 0.0;            ///< normalised cross-correlation of A and the aligned B (robust weights)
  double correlation_inflation = 1.0;  ///< variance factor due to correlated neighbouring residuals (>= 1)
  /// scale^2 * correlation_inflation * (J^T W J)^-1 of all the parameters at this level (empty if singular)
  Eigen::MatrixXd covariance;
  cv::Mat weights;  ///< CV_32F, the level's size: Tukey weight, NaN where not evaluated
};

/// Geometric parameters of `model` from a centred matrix of that model normalised to m(2, 2) = 1.
Eigen::VectorXd parametersFromCentred(MotionModel model, const Eigen::Matrix3d& centred);

/// Largest displacement of the corners of the image whose centre is `centre` (centred coordinates) by `centred`.
double cornerShift(const Eigen::Matrix3d& centred, const Eigen::Vector2d& centre);

/// Holds the per-pixel buffers between calls, so that steady-state registration allocates nothing large.
class RmrLevelSolver {
 public:
  /// Iterates at one level from `state` (updated in place) on the pixels `reference` selected in A, sampling `target`
  /// (level of B, CV_32F) at their warped positions.
  RmrLevelResult solve(const RmrLevelSelection& reference, const cv::Mat& target, const Eigen::Vector2d& centre,
                       const RmrSolverSettings& settings, RmrState* state);

  /// Statistics of the last evaluation of solve() (call right after it, with the same reference and result).
  RmrFitStatistics statistics(const RmrLevelSelection& reference, cv::Size level_size, const RmrState& state,
                              const RmrLevelResult& result);

 private:
  std::vector<float> residuals_;   ///< per selected pixel, NaN when not evaluated
  std::vector<float> weights_;     ///< per selected pixel, its Tukey weight (0 when not evaluated)
  std::vector<float> magnitudes_;  ///< |residual| of the evaluated pixels, for the median
  std::vector<float> weighted_;    ///< per selected pixel, weight * residual
  std::vector<float> scratch_;     ///< per selected pixel, work array of the normal equations
  cv::Mat weights_image_;          ///< reused when the caller has released the previous result's weights
};

}  // namespace internal
}  // namespace registration
}  // namespace exocet_mosaic
