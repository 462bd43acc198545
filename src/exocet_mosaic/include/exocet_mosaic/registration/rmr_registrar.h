/**
 * @file rmr_registrar.h
 * @brief RMR: robust multiresolution estimation of a parametric motion model from the image intensities (Odobez and
 * Bouthemy 1995; 2D3 report, section 3.2). Dense (no features): it registers the whole texture. No ROS in it.
 *
 * Method. Both images are slightly smoothed (smoothing_sigma_px) and reduced to Gaussian pyramids (each image once:
 * registerNext keeps the current image's pyramid for the next call). From the coarsest level to the finest, the
 * motion is refined by incremental Gauss-Newton steps on the linearised optical-flow constraint
 *     gain * grad(A) . (dW/dp dp) + A dgain + doffset = B(W(x; p)) - gain * A(x) - offset
 * written inverse-compositionally (the gradients of the reference image A and the warp Jacobian at the identity are
 * computed once per level; B is sampled, bilinearly, only at the warped positions of the selected pixels of A). Each
 * step is an IRLS solve with Tukey's biweight, the residual scale being the normalised median absolute residual
 * (floored); the increment is composed into the estimate, and the level stops when it moves no image corner by more
 * than the convergence threshold. The estimate then goes to the next finer level (translation x 2, perspective
 * terms / 2). Optional global illumination parameters (gain, offset) make it insensitive to a change of exposure or
 * lighting (Odobez-Bouthemy's Theta = (A, zeta)). Safeguards for poorly textured or periodic seabeds (ripples): the
 * coarsest level estimates the translation before the full model, a step longer than max_step_px is shortened, and a
 * coarse level that fails (diverges, loses the overlap) is abandoned, the next level starting from the previous
 * estimate; only a failure at the finest level fails the registration.
 *
 * Pixels. Each level of A is divided into cells (about 2.5 per pixel wanted), and each cell offers its strongest
 * gradient (|gx| + |gy|, above min_gradient); the strongest of these are kept: a fraction of the level's pixels,
 * within [min, max] counts. The pixels spread over the image (good conditioning), and a small bright blob (marine
 * snow, a particle), whose rim has the strongest gradients of a turbid image, yields a few pixels rather than many,
 * so that outliers stay the minority a robust estimator needs. Only the kept pixels are evaluated, which bounds the
 * cost whatever the image size.
 *
 * Covariance. sigma^2 (J^T W J)^-1 at the final iteration (sigma: robust residual scale), inflated by a measured
 * factor for the correlation of neighbouring residuals (interpolation, pyramid smoothing, camera noise): the ratio,
 * in the metric (J^T W J)^-1, of the score covariance counting the pairs of pixels of neighbouring cells to the one
 * assuming independent pixels (an effective-sample correction, >= 1), times RmrConfig::covariance_inflation. This
 * accounts for the image noise (calibrated on synthetic pairs); errors of the imaging model (a lamp pattern fixed in
 * the image, parallax, lens distortion) are not in it, hence covariance_inflation for real or rendered dives.
 *
 * Failures are explicit (never a confident wrong answer): see RmrConfig for the thresholds of each FailureReason.
 */
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "exocet_mosaic/registration/frame_registrar.h"

namespace exocet_mosaic {
namespace registration {

namespace internal {
class RmrFrame;
class RmrLevelSolver;
}  // namespace internal

/**
 * @brief Parameters of the RMR registration. validate() lists the allowed ranges. Grey levels are those of the 8-bit
 * input; gradients are grey levels per pixel of the level concerned.
 */
struct RmrConfig {
  /// translation, similarity, affine (the report's 6-parameter model), or homography (when perspective matters).
  MotionModel model = MotionModel::kAffine;

  // --- Pyramid and iterations ---
  int pyramid_levels = 5;              ///< [1, 10] levels including the full-resolution one
  int min_level_size_px = 32;          ///< [8, 1024] fewer levels when the coarsest's smaller side would be less
  int finest_level = 0;                ///< [0, pyramid_levels - 1] level of the final estimate (0: full resolution)
  int max_iterations_per_level = 24;   ///< [1, 200] Gauss-Newton/IRLS iterations at most per level
  double convergence_px = 0.01;        ///< (0, 1] finest level: stop when an increment moves no corner further
  double coarse_convergence_px = 0.2;  ///< (0, 1] same at the coarser levels (their estimate is refined anyway)
  double max_step_px = 2.0;            ///< (0, 100] longest corner displacement of one increment (pixels of the
                                       ///< level); longer steps are shortened (damped Gauss-Newton)

  // --- Robust estimation ---
  double tukey_constant = 4.6851;   ///< [1, 20] Tukey biweight cutoff, in robust scales (4.685: 95 % efficiency)
  double min_residual_scale = 1.0;  ///< [0.01, 50] floor of the robust residual scale (grey levels)

  // --- Image preparation ---
  /// [0, 3] Gaussian pre-smoothing of the full-resolution images (pixels; 0: none). Band-limits the images so that the
  /// bilinear interpolation of B is nearly exact: without it, the interpolation's own smoothing (strongest at
  /// half-pixel positions) leaves residuals of several grey levels on sharp texture, which inflate the robust scale.
  double smoothing_sigma_px = 0.8;

  // --- Pixel selection (per level, in the reference image) ---
  double min_gradient = 2.0;         ///< [0, 255] |gx| + |gy| below which a pixel is never used
  double pixel_fraction = 0.15;      ///< (0, 1] share of the level's pixels kept, strongest gradients first
  int min_pixels_per_level = 3000;   ///< [0, 10^7] ... but at least this many when the level has them
  int max_pixels_per_level = 16000;  ///< [100, 10^7] ... and at most this many at the finest level, a quarter as
                                     ///< many a level coarser and so on (bounds the cost per iteration)

  // --- Illumination ---
  bool estimate_illumination = true;  ///< also estimate B = gain * A + offset
  double min_gain = 0.5;              ///< (0, 1] a gain outside [min_gain, max_gain] is kInconsistent
  double max_gain = 2.0;              ///< [1, 100]

  // --- Failure thresholds ---
  double min_mean_intensity = 8.0;    ///< [0, 255] kTooDark when either image's mean is lower (grey levels)
  double min_intensity_stddev = 2.0;  ///< [0, 128] kTooDark when either image's standard deviation is lower
  int min_textured_pixels = 500;      ///< [10, 10^7] kTooLittleTexture: pixels >= min_gradient at the finest level
  double not_converged_px = 0.1;      ///< (0, 100] kNotConverged: the last increment at the finest level moved a
                                      ///< corner further than this (pixels of that level)
  double max_shift_fraction = 0.5;    ///< (0, 10] kMotionTooLarge: an image corner moved by more than this fraction
                                      ///< of the image diagonal
  double max_scale_change = 0.5;      ///< (0, 10] kMotionTooLarge: scale (sqrt of the area ratio) outside
                                      ///< [1 / (1 + x), 1 + x]
  double min_inlier_fraction = 0.5;   ///< [0, 1] kTooFewInliers: share of the evaluated pixels with weight > 0.5
  int min_inliers = 200;              ///< [0, 10^7] kTooFewInliers: count of such pixels
  double max_residual_scale = 25.0;   ///< (0, 255] kInconsistent: robust residual scale above this (grey levels)
  double min_correlation = 0.5;       ///< [-1, 1] kInconsistent: normalised cross-correlation of A and the aligned
                                      ///< B (weighted by the robust weights) below this (unrelated images give ~0)

  // --- Covariance ---
  /// [0.01, 100] extra factor on the covariance (after the measured one). On the rendered benchmark dive (lamp cone,
  /// backscatter, marine snow) the corner NEES says 3.2 to 3.9 without it, hence the default.
  double covariance_inflation = 3.5;

  /// Empty if usable, otherwise every bad field with its allowed range, separated by "; ".
  std::string validate() const;
};

/**
 * @brief The RMR registration method. Not thread-safe (one instance per image stream); registerPair() does not touch
 * the registerNext() state.
 *
 * Besides the motion, MotionEstimate::weights holds the final robust weights on the finest level used (CV_32F, that
 * level's size, full resolution when finest_level = 0): for each evaluated pixel its Tukey weight in [0, 1] (< 0.5:
 * outlier, e.g. a fish, a particle, a moving shadow), and NaN where the pixel was not evaluated (not selected: weak
 * gradient, border; or warped outside the other image). `observations` counts the evaluated pixels at that level,
 * `inliers` those of weight > 0.5, `residual_scale` is in grey levels. On a failure detected before the estimation
 * (too dark, too little texture), `parameters` are the prediction's (zero on invalid input and kNoPreviousFrame) and
 * `covariance` and `weights` are empty; on a later failure they are those of the rejected estimate.
 */
class RmrRegistrar : public FrameRegistrar {
 public:
  /// @throws std::invalid_argument with validate()'s message when the configuration is not usable.
  explicit RmrRegistrar(const RmrConfig& config = RmrConfig());
  ~RmrRegistrar() override;

  void reset() override;
  /// An empty or non-CV_8UC1 image fails with kInvalidInput and also forgets the previous image.
  MotionEstimate registerNext(const cv::Mat& gray,
                              const Eigen::Matrix3d& prediction_px = Eigen::Matrix3d::Identity()) override;
  MotionEstimate registerPair(const cv::Mat& previous, const cv::Mat& current,
                              const Eigen::Matrix3d& prediction_px = Eigen::Matrix3d::Identity()) override;
  RegistrationMethod method() const override { return RegistrationMethod::kRmr; }

  const RmrConfig& config() const { return config_; }

 private:
  /// Pyramid levels used for an image of this size.
  int levelCount(cv::Size size) const;
  std::unique_ptr<internal::RmrFrame> prepare(const cv::Mat& gray);
  /// Keeps a frame no longer needed so that the next prepare() reuses its buffers.
  void recycle(std::unique_ptr<internal::RmrFrame> frame);
  MotionEstimate estimate(internal::RmrFrame* previous, const internal::RmrFrame& current,
                          const Eigen::Matrix3d& prediction_px, double start_ms);

  RmrConfig config_;
  std::unique_ptr<internal::RmrFrame> previous_;
  std::vector<std::unique_ptr<internal::RmrFrame>> spare_frames_;
  std::unique_ptr<internal::RmrLevelSolver> solver_;
};

}  // namespace registration
}  // namespace exocet_mosaic
