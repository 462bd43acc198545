#include "exocet_servo/control/servo_safety.h"

#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace exocet_servo {
namespace control {

std::string toString(SafetyStatus status) {
  switch (status) {
    case SafetyStatus::kOk:
      return "ok";
    case SafetyStatus::kLostTracking:
      return "lost tracking";
    case SafetyStatus::kErrorGrowing:
      return "error growing";
    case SafetyStatus::kLeftWorkspace:
      return "left workspace";
    case SafetyStatus::kJointLimit:
      return "joint limit";
    case SafetyStatus::kSingular:
      return "singular";
    case SafetyStatus::kMaxIterations:
      return "max iterations";
    case SafetyStatus::kInvalidInput:
      return "invalid input";
  }
  return "unknown";
}

std::string ServoSafetyConfig::validate() const {
  std::ostringstream errors;
  auto check = [&errors](bool ok, const char* field, const std::string& range) {
    if (ok) return;
    if (errors.tellp() > 0) errors << "; ";
    errors << field << " must be in " << range;
  };
  check(min_tracked_points >= 4 && min_tracked_points <= 100000, "min_tracked_points", "[4, 100000]");
  check(growth_factor > 1.0 && growth_factor <= 1e6, "growth_factor", "(1, 1e6]");
  check(growth_iterations >= 1 && growth_iterations <= 10000, "growth_iterations", "[1, 10000]");
  check(growth_floor >= 0.0 && growth_floor <= 1.0, "growth_floor", "[0, 1]");
  check(workspace_min_m.allFinite() && workspace_max_m.allFinite() &&
            (workspace_min_m.array() < workspace_max_m.array()).all(),
        "workspace_min_m, workspace_max_m", "finite vectors with min < max on every axis");
  check(workspace_centre_m.allFinite(), "workspace_centre_m", "finite vectors");
  check(workspace_radius_m >= 0.0 && workspace_radius_m <= 1000.0, "workspace_radius_m", "[0, 1000] (0 disables)");
  check(max_iterations >= 1 && max_iterations <= 10000000, "max_iterations", "[1, 10000000]");
  return errors.str();
}

ServoSafetyMonitor::ServoSafetyMonitor(const ServoSafetyConfig& config) : config_(config) {
  const std::string errors = config.validate();
  if (!errors.empty()) throw std::invalid_argument("ServoSafetyConfig: " + errors);
  reset();
}

void ServoSafetyMonitor::reset() {
  status_ = SafetyStatus::kOk;
  message_.clear();
  iterations_ = 0;
  growth_count_ = 0;
  min_error_ = std::numeric_limits<double>::infinity();
}

SafetyStatus ServoSafetyMonitor::stop(SafetyStatus status, const std::string& message) {
  status_ = status;
  std::ostringstream m;
  m << toString(status) << ": " << message << " at iteration " << iterations_;
  message_ = m.str();
  return status_;
}

SafetyStatus ServoSafetyMonitor::update(const SafetyInput& in) {
  if (stopped()) return status_;
  ++iterations_;
  std::ostringstream m;
  if (in.tracked_points < 0 || !std::isfinite(in.error_norm) || in.error_norm < 0.0 ||
      !in.camera_position_m.allFinite()) {
    m << "tracked_points must be >= 0, error_norm finite and >= 0, camera_position_m finite (got " << in.tracked_points
      << ", " << in.error_norm << ", (" << in.camera_position_m.transpose() << "))";
    return stop(SafetyStatus::kInvalidInput, m.str());
  }
  if (in.arm_status == arm::ArmStatus::kInvalidInput) {
    return stop(SafetyStatus::kInvalidInput, "the arm refused the command (" + in.arm_message + ")");
  }
  if (in.arm_status == arm::ArmStatus::kJointLimit) {
    return stop(SafetyStatus::kJointLimit, in.arm_message.empty() ? "a joint reached its limit" : in.arm_message);
  }
  if (in.arm_status == arm::ArmStatus::kSingular && config_.stop_on_singular) {
    return stop(SafetyStatus::kSingular, in.arm_message.empty() ? "the arm is near a singularity" : in.arm_message);
  }
  // Workspace: the box, then the sphere.
  const Eigen::Vector3d& p = in.camera_position_m;
  for (int axis = 0; axis < 3; ++axis) {
    if (p(axis) >= config_.workspace_min_m(axis) && p(axis) <= config_.workspace_max_m(axis)) continue;
    const char* names = "xyz";
    m << "camera at (" << p.transpose() << ") m, its " << names[axis] << " = " << p(axis) << " m is outside the box ["
      << config_.workspace_min_m(axis) << ", " << config_.workspace_max_m(axis) << "] m";
    return stop(SafetyStatus::kLeftWorkspace, m.str());
  }
  if (config_.workspace_radius_m > 0.0) {
    const double r = (p - config_.workspace_centre_m).norm();
    if (r > config_.workspace_radius_m) {
      m << "camera at (" << p.transpose() << ") m is " << r << " m from the workspace centre ("
        << config_.workspace_centre_m.transpose() << "), beyond its radius " << config_.workspace_radius_m << " m";
      return stop(SafetyStatus::kLeftWorkspace, m.str());
    }
  }
  if (in.tracked_points < config_.min_tracked_points) {
    m << in.tracked_points << " tracked points < " << config_.min_tracked_points;
    return stop(SafetyStatus::kLostTracking, m.str());
  }
  // Growth against the smallest error so far: noise makes |e| wobble, a real divergence keeps it high.
  if (in.error_norm > config_.growth_floor && in.error_norm > config_.growth_factor * min_error_) {
    ++growth_count_;
    if (growth_count_ >= config_.growth_iterations) {
      m << "|e| = " << in.error_norm << " > " << config_.growth_factor << " x its minimum " << min_error_ << " for "
        << growth_count_ << " consecutive iterations";
      return stop(SafetyStatus::kErrorGrowing, m.str());
    }
  } else {
    growth_count_ = 0;
  }
  if (in.error_norm < min_error_) min_error_ = in.error_norm;
  if (iterations_ >= config_.max_iterations) {
    m << "budget of " << config_.max_iterations << " iterations spent, |e| = " << in.error_norm;
    return stop(SafetyStatus::kMaxIterations, m.str());
  }
  return SafetyStatus::kOk;
}

}  // namespace control
}  // namespace exocet_servo
