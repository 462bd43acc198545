#include "exocet_servo/trajectory/rig_geometry.h"

#include <cmath>
#include <sstream>

namespace exocet_servo {
namespace trajectory {

std::string RigGeometry::validate() const {
  std::ostringstream errors;
  auto check = [&errors](bool ok, const char* field, const std::string& range) {
    if (ok) return;
    if (errors.tellp() > 0) errors << "; ";
    errors << field << " must be in " << range;
  };
  check(baseline_m > 0.0 && baseline_m <= 10.0, "baseline_m", "(0, 10]");
  check(std::abs(pan_rad) <= M_PI / 2, "pan_rad", "[-pi/2, pi/2]");
  check(std::abs(tilt_rad) <= M_PI / 2, "tilt_rad", "[-pi/2, pi/2]");
  return errors.str();
}

Eigen::Isometry3d RigGeometry::leftFromRight() const {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.linear() =
      (Eigen::AngleAxisd(-pan_rad, Eigen::Vector3d::UnitY()) * Eigen::AngleAxisd(tilt_rad, Eigen::Vector3d::UnitX()))
          .toRotationMatrix();
  t.translation() = Eigen::Vector3d(baseline_m, 0.0, 0.0);
  return t;
}

}  // namespace trajectory
}  // namespace exocet_servo
