/**
 * @file filter_log.h
 * @brief The navigation filter's state layout, its estimate at one stamp, and the log of every step that the
 * Rauch-Tung-Striebel smoother needs. No ROS in it.
 */
#pragma once

#include <deque>

#include <Eigen/Core>

namespace exocet_mosaic {
namespace fusion {

/**
 * @brief Layout of the filter's state vector x (size kStateSize) and covariance P.
 *
 *  - kEast, kNorth: camera optical centre, UTM grid easting and northing (m).
 *  - kPixelSize: pixel-size correction c (dimensionless, relative): the true displacement is (1 + c) times the one
 *    measured by the images (2D3 section 3.5's third state: altimeter bias, focal length error).
 *  - kHeading: heading error psi (rad) of the attitude used to turn image motion into metres (and of the dead
 *    reckoning, see FilterConfig::dr_shares_heading): measured yaw = true yaw + psi (ENU, counter-clockwise).
 *  - kHeadingDrift: d psi / dt (rad/s): the gyro's bias, which makes the heading error grow linearly.
 *  - kDrEast, kDrNorth: dead-reckoning offset (m): DR camera position = true camera position + offset + white noise.
 *  - kDrScale: scale-factor error s of the dead reckoning's velocity (DVL): the DR's displacement is (1 + s) times
 *    the true one, so the offset grows by s times each displacement (dimensionless).
 */
enum StateIndex : int {
  kEast = 0,
  kNorth = 1,
  kPixelSize = 2,
  kHeading = 3,
  kHeadingDrift = 4,
  kDrEast = 5,
  kDrNorth = 6,
  kDrScale = 7,
  kStateSize = 8
};

using StateVector = Eigen::Matrix<double, kStateSize, 1>;
using StateMatrix = Eigen::Matrix<double, kStateSize, kStateSize>;

/// The estimate at one stamp (a filter posterior or a smoothed state).
struct FilterState {
  double stamp_s = 0.0;
  Eigen::Vector2d position_en_m = Eigen::Vector2d::Zero();  ///< camera centre, UTM easting/northing (m)
  Eigen::Matrix2d position_covariance_m2 = Eigen::Matrix2d::Zero();
  double pixel_size_correction = 0.0;  ///< relative: metric displacement = (1 + c) * image displacement
  double pixel_size_correction_sigma = 0.0;
  double heading_error_rad = 0.0;  ///< of the attitude used for the image motion (see StateIndex)
  double heading_error_sigma_rad = 0.0;
  double heading_drift_rps = 0.0;
  Eigen::Vector2d dr_offset_en_m = Eigen::Vector2d::Zero();  ///< dead-reckoning offset (zero until the first DR)
  Eigen::Matrix2d dr_offset_covariance_m2 = Eigen::Matrix2d::Zero();
  double dr_scale_error = 0.0;  ///< dead reckoning's velocity scale-factor error (relative)
  double dr_scale_error_sigma = 0.0;
  Eigen::VectorXd x;  ///< the whole state, layout StateIndex (empty before initialisation)
  Eigen::MatrixXd P;  ///< its covariance

  /// Fills every field from a state vector and covariance.
  static FilterState from(double stamp_s, const StateVector& x, const StateMatrix& P);
};

/**
 * @brief One step of the filter: the prediction from the previous step's stamp to this one, then every update at
 * this stamp. What a Rauch-Tung-Striebel smoother needs (prior, posterior, transition) plus the bookkeeping the
 * filter rewinds to for out-of-sequence fixes.
 */
struct FilterStep {
  double stamp_s = 0.0;
  StateVector x_prior = StateVector::Zero();  ///< after the prediction, before this stamp's updates
  StateMatrix P_prior = StateMatrix::Zero();
  StateVector x_posterior = StateVector::Zero();  ///< after this stamp's updates
  StateMatrix P_posterior = StateMatrix::Zero();
  /// Jacobian of the transition from the previous step's posterior (identity for the first step).
  StateMatrix transition = StateMatrix::Identity();
  /// The filter re-initialised part of its state at this step (recovery after consecutive rejected fixes): the
  /// smoother does not carry information across it.
  bool discontinuity = false;
  bool image_motion = false;  ///< an image motion (or registration failure) ends at this stamp
  int fixes_applied = 0, fixes_rejected = 0, dr_applied = 0, dr_rejected = 0;
  // Filter bookkeeping at the posterior (restored when the filter rewinds here).
  int consecutive_fix_rejections = 0;
  int consecutive_dr_rejections = 0;
  bool dr_initialized = false;
};

/// Every step kept (see NavigationFilter::setKeepLog), in time order.
struct FilterLog {
  std::deque<FilterStep> steps;
};

}  // namespace fusion
}  // namespace exocet_mosaic
