/**
 * @file keyed_throttle.h
 * @brief Throttling of repeated log messages per kind of problem, on the wall clock. ROS_*_THROTTLE throttles per
 * call site on the ROS clock: one helper that logs every rejection through one call site lets a frequent problem (a
 * NaN attitude at 50 Hz) hide a rare one (a NaN fix), and a fast replay speeds the ROS clock up.
 */
#pragma once

#include <cstdint>
#include <map>
#include <string>

#include <ros/time.h>

namespace exocet_mosaic {

class KeyedThrottle {
 public:
  explicit KeyedThrottle(double period_s = 5.0) : period_s_(period_s) {}

  /// True when a message of kind `key` may be logged now; `*held_back` is then how many of that kind were not
  /// logged since the last one.
  bool allow(const std::string& key, std::uint64_t* held_back) {
    Entry& entry = entries_[key];
    const ros::WallTime now = ros::WallTime::now();
    if (!entry.last.isZero() && (now - entry.last).toSec() < period_s_) {
      ++entry.held_back;
      return false;
    }
    *held_back = entry.held_back;
    entry.held_back = 0;
    entry.last = now;
    return true;
  }

  /// " (and N more in the last P s)", or "" when none was held back.
  std::string heldBackNote(std::uint64_t held_back) const {
    if (held_back == 0) return "";
    return " (and " + std::to_string(held_back) + " more in the last " + std::to_string(static_cast<int>(period_s_)) +
           " s)";
  }

 private:
  struct Entry {
    ros::WallTime last;
    std::uint64_t held_back = 0;
  };
  double period_s_;
  std::map<std::string, Entry> entries_;
};

}  // namespace exocet_mosaic
