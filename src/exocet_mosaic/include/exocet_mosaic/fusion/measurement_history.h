/**
 * @file measurement_history.h
 * @brief Short, time-indexed histories of the vehicle's attitude and altitude, so that an image pair can be given
 * the attitude and height at each image's own stamp (the IMU and the altimeter run at other rates). No ROS in it.
 */
#pragma once

#include <deque>
#include <optional>
#include <utility>
#include <vector>

#include <Eigen/Geometry>

namespace exocet_mosaic {
namespace fusion {

/// Attitudes (body to world rotations) by time, interpolated by slerp.
class AttitudeHistory {
 public:
  /// @param window_s how long samples are kept behind the newest (s)
  /// @param max_interpolation_gap_s two samples further apart than this are not interpolated between (s)
  explicit AttitudeHistory(double window_s = 30.0, double max_interpolation_gap_s = 0.5)
      : window_s_(window_s), max_gap_s_(max_interpolation_gap_s) {}

  /// Adds a sample. Samples must come in time order: an older one (a clock jump) clears the history first.
  void add(double stamp_s, const Eigen::Quaterniond& world_from_body);
  /// The attitude at `stamp_s`: interpolated between the samples around it, or the nearest sample when it lies
  /// within `max_interpolation_gap_s` / 2 outside the covered interval; empty otherwise.
  std::optional<Eigen::Quaterniond> at(double stamp_s) const;
  /// The samples stamped in [from_s, to_s], oldest first.
  std::vector<std::pair<double, Eigen::Quaterniond>> between(double from_s, double to_s) const;
  /// Stamp of the newest sample; empty when there is none.
  std::optional<double> newestStamp() const;
  bool empty() const { return samples_.empty(); }
  void clear() { samples_.clear(); }

 private:
  double window_s_, max_gap_s_;
  std::deque<std::pair<double, Eigen::Quaterniond>> samples_;
};

/// Scalar measurements (e.g. altimeter range, metres) by time, interpolated linearly.
class ScalarHistory {
 public:
  explicit ScalarHistory(double window_s = 30.0, double max_interpolation_gap_s = 1.0)
      : window_s_(window_s), max_gap_s_(max_interpolation_gap_s) {}
  void add(double stamp_s, double value);
  std::optional<double> at(double stamp_s) const;
  /// The samples stamped in [from_s, to_s], oldest first.
  std::vector<std::pair<double, double>> between(double from_s, double to_s) const;
  bool empty() const { return samples_.empty(); }
  void clear() { samples_.clear(); }

 private:
  double window_s_, max_gap_s_;
  std::deque<std::pair<double, double>> samples_;
};

}  // namespace fusion
}  // namespace exocet_mosaic
