#include "exocet_servo/control/twist_limit.h"

#include <algorithm>

namespace exocet_servo {
namespace control {

Eigen::Matrix<double, 6, 1> limitTwist(const Eigen::Matrix<double, 6, 1>& twist, double max_linear_mps,
                                       double max_angular_rps) {
  const double v = twist.head<3>().norm(), w = twist.tail<3>().norm();
  double scale = 1.0;
  if (v > max_linear_mps) scale = std::min(scale, max_linear_mps / v);
  if (w > max_angular_rps) scale = std::min(scale, max_angular_rps / w);
  return scale * twist;
}

}  // namespace control
}  // namespace exocet_servo
