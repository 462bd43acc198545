/**
 * @file invariant_servo.h
 * @brief Intrinsics-free visual servoing (2D4 report 2.3, eqs. 16-18; Malis 2002): the error s - s* is measured
 * between invariant points (invariant_features.h), so the left camera converges to the pose where the right camera
 * took the reference image even though their intrinsics differ; task e = L_hat^+ (s - s*), velocity v = -lambda e,
 * with stop criteria (convergence, growing error, iteration budget, points leaving the image). No ROS in it.
 *
 * Usage: setReference() once with the reference camera's points, then step() with each new current image until the
 * returned status is not kRunning; apply step().velocity (camera frame, m/s and rad/s) in between.
 */
#pragma once

#include <deque>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "exocet_servo/control/adaptive_gain.h"
#include "exocet_servo/control/invariant_features.h"

namespace exocet_servo {
namespace control {

/// Where the interaction matrix L_hat is evaluated.
enum class InteractionModel {
  kCurrent,  ///< at the current points and depths (recomputed every step)
  kDesired,  ///< at the reference points and depths (computed once)
  kMean,     ///< (L_current + L_desired) / 2 (a second-order approximation, Malis 2004)
};

/// State of the servo after a step.
enum class ServoStatus {
  kRunning,          ///< keep going, apply the velocity
  kConverged,        ///< |e| < convergence_threshold
  kMaxIterations,    ///< iteration budget spent before convergence
  kErrorGrowing,     ///< |e| grew for growth_iterations steps in a row and exceeds growth_ratio * its minimum
  kPointsLeftImage,  ///< a current point lies outside the image (minus the margin)
  kDegenerate,       ///< collinear points, or a rank-deficient interaction matrix (equal depths, planar object)
  kInvalidInput,     ///< wrong sizes, no reference, non-positive depths
};

/// Short name of a status ("converged", ...).
std::string toString(ServoStatus status);

/// Parameters of the servo; validate() lists the allowed ranges.
struct ServoConfig {
  AdaptiveGain gain = AdaptiveGain::constant(0.5);  ///< lambda(|e|) (1/s)
  InteractionModel interaction = InteractionModel::kMean;
  /// On |e|, (0, 1]. e estimates the remaining displacement (m and rad mixed: 1e-4 ~ 0.1 mm or 0.006 deg). With noisy
  /// points set it just above the noise floor of |e|, about sqrt(2) times the pose bound of sim/pose_bound.h (0.025
  /// for 100 points at 0.5 px on the 0.3 m vent at 1 m), or the servo never converges.
  double convergence_threshold = 1e-4;
  /// Converged also when the mean of e over the last this many steps (of one reference set) is below the threshold,
  /// [1, 1000]: near the goal e carries the image noise, and the mean of a few steps estimates the remaining
  /// displacement better than one step (1: one step only).
  int convergence_window = 1;
  int max_iterations = 200;      ///< [1, 1000000]
  int growth_iterations = 10;    ///< consecutive increases of |e| that stop the servo, [2, 10000]
  double growth_ratio = 3.0;     ///< and |e| must exceed this times its smallest value so far, [1, 1e6]
  int image_width_px = 640;      ///< of the controlled (current) camera, [16, 100000]
  int image_height_px = 480;     ///< [16, 100000]
  double image_margin_px = 0.0;  ///< points must stay this far inside the image, [0, min(w, h) / 4]
  /// Depth used for every point when none is given, (0, 1000]. Equal depths make L_hat rank deficient in the
  /// invariant space (translations then act on the image like a change of K): give per-point depths.
  double default_depth_m = 1.0;
  /// "" or every bad field with its allowed range ("; "-joined).
  std::string validate() const;
};

/// Result of one control step.
struct ServoStep {
  ServoStatus status = ServoStatus::kInvalidInput;
  std::string message;                                                         ///< human-readable reason of the status
  Eigen::Matrix<double, 6, 1> velocity = Eigen::Matrix<double, 6, 1>::Zero();  ///< (v [m/s], omega [rad/s]), camera
  Eigen::Matrix<double, 6, 1> task_error = Eigen::Matrix<double, 6, 1>::Zero();  ///< e = L_hat^+ (s - s*)
  double error_norm = 0.0;                                                       ///< |e|
  double feature_rms = 0.0;                                                      ///< RMS of s - s* (invariant units)
  double gain = 0.0;                                                             ///< lambda used
  int iteration = 0;                                                             ///< 1 for the first step
};

/// The intrinsics-free servo.
class InvariantServo {
 public:
  /// @throws std::invalid_argument with config.validate()'s message.
  explicit InvariantServo(const ServoConfig& config);

  /// Sets the reference image (resets the iteration count and the stop criteria).
  /// @param points_px reference points (pixels), n >= 4, matched one to one with the current points.
  /// @param k_estimate estimate of the reference camera's intrinsics (only for L_hat at the desired position; the
  ///        invariant s* does not depend on it).
  /// @param depths_m depth of each point in the reference camera (m), or empty for config.default_depth_m.
  /// @return "" or why the reference is unusable.
  std::string setReference(const std::vector<Eigen::Vector2d>& points_px, const Eigen::Matrix3d& k_estimate,
                           const std::vector<double>& depths_m = {});

  /// One control step on the current image.
  /// @param points_px current points (pixels), matched with the reference ones.
  /// @param k_estimate estimate of the current camera's intrinsics (only for L_hat).
  /// @param depths_m estimated depth of each point in the current camera (m), or empty for config.default_depth_m.
  /// Once a status other than kRunning is returned, further steps return it again with a zero velocity.
  ServoStep step(const std::vector<Eigen::Vector2d>& points_px, const Eigen::Matrix3d& k_estimate,
                 const std::vector<double>& depths_m = {});

  /// Invariant points of the reference.
  const InvariantPoints& reference() const { return reference_; }
  const ServoConfig& config() const { return config_; }

 private:
  ServoStep finish(ServoStep step, ServoStatus status, const std::string& message);

  ServoConfig config_;
  bool has_reference_ = false;
  InvariantPoints reference_;
  Eigen::VectorXd reference_stacked_;
  Eigen::MatrixXd reference_interaction_;
  int iteration_ = 0;
  std::deque<Eigen::Matrix<double, 6, 1>> recent_errors_;  ///< e of the last convergence_window steps
  int growth_count_ = 0;
  double last_norm_ = 0.0;
  double min_norm_ = 0.0;
  bool finished_ = false;
  ServoStep last_terminal_;
};

}  // namespace control
}  // namespace exocet_servo
