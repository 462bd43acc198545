/**
 * @file twist_limit.h
 * @brief Speed limits on a camera velocity command, applied uniformly so that the direction the servo law chose is
 * kept (clamping each component separately would turn the motion).
 */
#pragma once

#include <Eigen/Core>

namespace exocet_servo {
namespace control {

/// Scales a twist (v [m/s], omega [rad/s]) down uniformly so that |v| <= max_linear_mps and |omega| <=
/// max_angular_rps; unchanged when both hold.
Eigen::Matrix<double, 6, 1> limitTwist(const Eigen::Matrix<double, 6, 1>& twist, double max_linear_mps,
                                       double max_angular_rps);

}  // namespace control
}  // namespace exocet_servo
