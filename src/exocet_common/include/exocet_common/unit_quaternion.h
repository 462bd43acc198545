/**
 * @file unit_quaternion.h
 * @brief One rule, for every node, of when a quaternion in a message stands for a rotation. No ROS in it.
 */
#pragma once

#include <cmath>

namespace exocet_common {

/// How far from 1 a quaternion's norm may be: float32 fields and drivers that print four decimals stay well inside
/// it, while a zero quaternion (ROS's "no orientation") or a garbled one does not.
constexpr double kUnitQuaternionTolerance = 0.01;

/// True when (w, x, y, z) is finite and of unit norm within kUnitQuaternionTolerance; the caller normalises it.
inline bool isUnitQuaternion(double w, double x, double y, double z) {
  const double norm = std::sqrt(w * w + x * x + y * y + z * z);
  return std::isfinite(norm) && std::abs(norm - 1.0) < kUnitQuaternionTolerance;
}

}  // namespace exocet_common
