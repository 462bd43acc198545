/**
 * @file adaptive_gain.h
 * @brief Gain of the control law as a function of the task error norm, as ViSP's vpAdaptiveGain:
 * lambda(x) = (lambda_0 - lambda_inf) exp(-lambda_dot_0 x / (lambda_0 - lambda_inf)) + lambda_inf.
 * A high gain near convergence speeds up the end of the exponential decrease; a low gain far from it keeps the
 * first velocities (and the points' excursions in the image) small. No ROS in it.
 */
#pragma once

#include <string>

namespace exocet_servo {
namespace control {

/// Adaptive gain; with lambda_0 == lambda_inf it is the constant gain lambda_0.
struct AdaptiveGain {
  double gain_at_zero = 0.5;      ///< lambda_0, gain when the error norm is 0 (1/s), (0, 100]
  double gain_at_infinity = 0.5;  ///< lambda_inf, gain for a large error (1/s), (0, gain_at_zero]
  double slope_at_zero = 0.0;     ///< lambda_dot_0, |d lambda / dx| at 0, [0, 1e6]
  /// lambda(error_norm) (1/s).
  double operator()(double error_norm) const;
  /// "" or every bad field with its allowed range.
  std::string validate() const;
  /// A constant gain.
  static AdaptiveGain constant(double gain);
};

}  // namespace control
}  // namespace exocet_servo
