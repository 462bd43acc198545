/**
 * @file cross_pass_smoother.h
 * @brief Batch smoother (Ceres) of the camera track with relative position constraints between passes over the
 * same seabed (a return frame registered to an outbound frame): a 2D pose graph initialised from the RTS solution.
 * No ROS in it.
 *
 * Unknowns: the camera position (E, N) at every step of the filter's log. Residuals, each whitened by its
 * covariance:
 *  - odometry between consecutive steps: p(i) - p(i-1) = the RTS solution's displacement, with the covariance of
 *    the process noise the filter added over that step (image motion, or the no-motion random walk across gaps),
 *    plus odometry_floor_m; no odometry across a filter discontinuity;
 *  - absolute constraints (the USBL fixes) with a Cauchy loss (outliers have no pull);
 *  - relative constraints p(to) - p(from) = delta (cross-pass registrations) with a Huber loss.
 * A constraint stamped between two steps is linearly interpolated between them.
 */
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "exocet_mosaic/fusion/filter_log.h"

namespace exocet_mosaic {
namespace fusion {

/// p(to_stamp) - p(from_stamp) = delta_en_m (camera centres, metres), e.g. a return frame registered to an outbound
/// frame and converted to metres by toMetricMotion.
struct RelativeConstraint {
  double from_stamp_s = 0.0;
  double to_stamp_s = 0.0;
  Eigen::Vector2d delta_en_m = Eigen::Vector2d::Zero();
  Eigen::Matrix2d covariance_m2 = Eigen::Matrix2d::Identity();
};

/// p(stamp) = position_en_m (an absolute fix of the camera centre).
struct AbsoluteConstraint {
  double stamp_s = 0.0;
  Eigen::Vector2d position_en_m = Eigen::Vector2d::Zero();
  Eigen::Matrix2d covariance_m2 = Eigen::Matrix2d::Identity();
};

struct CrossPassSmootherConfig {
  double odometry_floor_m = 2e-4;          ///< added 1-sigma per odometry step (m, >= 0): keeps every step stiff but finite
  double absolute_loss_scale = 3.0;        ///< Cauchy scale of the absolute constraints, in sigmas (> 0)
  double relative_loss_scale = 3.0;        ///< Huber scale of the relative constraints, in sigmas (> 0)
  int max_iterations = 50;                 ///< Ceres iterations (>= 1)
  int threads = 1;
  std::string validate() const;            ///< "" or each problem naming the field and its allowed range
};

struct CrossPassResult {
  bool converged = false;
  std::vector<Eigen::Vector2d> positions_en_m;  ///< one per step of the log
  int iterations = 0;
  double initial_cost = 0.0, final_cost = 0.0;
  int relative_used = 0, absolute_used = 0;     ///< constraints whose stamps fall within the log
  std::string message;                          ///< Ceres' summary line, or why nothing was done
};

/**
 * @brief The track with the relative constraints, from the filter's log and its RTS solution (`smoothed`, one
 * state per step, from smoothRts(log)).
 * @throws std::invalid_argument when `smoothed` does not match the log or the configuration is invalid.
 */
CrossPassResult smoothWithCrossPassConstraints(const FilterLog& log, const std::vector<FilterState>& smoothed,
                                               const std::vector<AbsoluteConstraint>& absolute,
                                               const std::vector<RelativeConstraint>& relative,
                                               const CrossPassSmootherConfig& config = CrossPassSmootherConfig());

}  // namespace fusion
}  // namespace exocet_mosaic
