/**
 * @file robust_motion_fitter.h
 * @brief Robust fit of a parametric motion model (motion_model.h) to point correspondences x_A -> x_B: the "global
 * displacement computation by least squares with an acceptance criterion" of the KLT method (2D3 report, 3.1.2.3).
 * No ROS in it.
 *
 * The fit runs in three stages, all deterministic:
 *  1. an initial hypothesis: the best (MSAC cost) of the identity, the caller's initial parameters, the least-squares
 *     fit of all points, and hypotheses from minimal samples drawn with a seeded generator (adaptive count, so that
 *     a clean set costs a handful of samples and a set with many false matches is still handled);
 *  2. iteratively re-weighted least squares with Tukey's biweight, the scale sigma being the robust (median) scale of
 *     the current inliers' residuals, and points beyond rejection_k * sigma struck off (the first inlier set is taken
 *     with a scale from the lowest fifth of the residuals, so that many false matches that roughly agree among
 *     themselves cannot enter it);
 *  3. plain least squares on the inlier set, repeated until that set no longer changes (the acceptance criterion).
 * The linear models (translation, similarity, affine) are solved directly; the homography by Gauss-Newton on the
 * geometric error, started from a linear (DLT) solve. Everything runs in centred coordinates normalised by the RMS
 * radius of the points, so that the normal equations are well conditioned for all models.
 */
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "exocet_mosaic/registration/motion_estimate.h"
#include "exocet_mosaic/registration/motion_model.h"

namespace exocet_mosaic {
namespace registration {

/// Number of correspondences that determine the model: 1, 2, 3, 4.
int minimalPointCount(MotionModel model);

/// Parameters of RobustMotionFitter. validate() lists the allowed ranges.
struct RobustFitConfig {
  MotionModel model = MotionModel::kSimilarity;

  // --- Acceptance criterion ---
  double tukey_c = 4.685;            ///< Tukey biweight constant, in units of the residual scale sigma, [1, 20]
  double rejection_k = 4.0;          ///< a point whose residual exceeds rejection_k * sigma is a false match, [2, 20]
  double min_scale_px = 0.03;        ///< floor of sigma (pixels) for rejection and covariance, (0, 10]
  int min_inliers = 8;               ///< fewer inliers: failure kTooFewInliers, [1, 1000000] (and >= minimalPointCount)
  double min_inlier_fraction = 0.5;  ///< smaller inlier fraction: failure kTooFewInliers, [0, 1]

  // --- Initial hypothesis from minimal samples ---
  double sample_threshold_px = 3.0;  ///< a point is consistent with a hypothesis within this distance (px), (0, 1000]
  int max_samples = 300;             ///< cap of the minimal-sample hypotheses, [0, 100000] (0: none)
  double sample_confidence = 0.999;  ///< stop once an all-inlier sample was drawn with this probability, (0, 1)
  uint32_t seed = 1;                 ///< of the sampler: the same input always gives the same result

  // --- Iterations ---
  int max_iterations = 30;       ///< of the re-weighted stage, and again of the inlier-set stage, [1, 1000]
  double convergence_px = 1e-3;  ///< converged when the fit moves the points' bounding box by less (px), (0, 1]

  /// Empty if usable, otherwise every bad field with its allowed range, separated by "; ".
  std::string validate() const;
};

/// Result of a robust fit. On failure the fields still hold the best estimate reached (for diagnostics only).
struct RobustFit {
  bool ok = false;
  FailureReason failure = FailureReason::kNone;  ///< kInvalidInput, kTooFewInliers, kNotConverged, kInconsistent
  std::string failure_detail;

  MotionModel model = MotionModel::kSimilarity;
  Eigen::VectorXd parameters;        ///< parameterCount(model) values, in coordinates centred on the given centre
  Eigen::MatrixXd covariance;        ///< max(residual_scale_px, min_scale_px)^2 (J^T J)^-1 over the inliers
  std::vector<uint8_t> inlier_mask;  ///< one per correspondence: 1 inlier, 0 struck off
  int observations = 0;              ///< correspondences given
  int inliers = 0;
  double inlier_fraction = 0.0;
  double residual_scale_px = 0.0;  ///< per-coordinate RMS residual of the inliers (degrees of freedom corrected)
  /// Robust scale of the difference between the residuals of neighbouring inliers (divided by sqrt 2): the tracking
  /// noise when the points move with one surface, however well the model fits that surface; as large as the
  /// residual scale when neighbouring points move independently (particles at various depths).
  double local_scale_px = 0.0;
  int iterations = 0;  ///< least-squares solves (Gauss-Newton steps for the homography) in all
};

/**
 * @brief Robust least-squares fit of one motion model to point correspondences. Stateless and deterministic; one
 * instance may serve any number of fits (not concurrently if you mutate it, which the API does not allow).
 */
class RobustMotionFitter {
 public:
  /// @throws std::invalid_argument with config.validate()'s message.
  explicit RobustMotionFitter(const RobustFitConfig& config = RobustFitConfig());

  const RobustFitConfig& config() const { return config_; }

  /**
   * Fits the model to from_px[i] -> to_px[i] (pixels).
   * @param centre_px origin of the parameterisation (motion_model.h), usually the image centre.
   * @param initial_parameters an optional hypothesis (parameterCount values, e.g. the predicted motion); empty: none.
   */
  RobustFit fit(const std::vector<cv::Point2f>& from_px, const std::vector<cv::Point2f>& to_px,
                const Eigen::Vector2d& centre_px, const Eigen::VectorXd& initial_parameters = Eigen::VectorXd()) const;
  /// The same with double-precision points.
  RobustFit fit(const std::vector<Eigen::Vector2d>& from_px, const std::vector<Eigen::Vector2d>& to_px,
                const Eigen::Vector2d& centre_px, const Eigen::VectorXd& initial_parameters = Eigen::VectorXd()) const;

 private:
  struct Correspondence {
    double u, v;    ///< x_A, centred and normalised
    double tu, tv;  ///< x_B, centred and normalised
  };
  RobustFit fitNormalised(const std::vector<Correspondence>& points, double scale_px,
                          const Eigen::VectorXd& initial_parameters) const;

  RobustFitConfig config_;
};

}  // namespace registration
}  // namespace exocet_mosaic
