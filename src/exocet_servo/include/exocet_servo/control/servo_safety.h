/**
 * @file servo_safety.h
 * @brief Safety stops of the arm-borne servoing (issue 6): fed once per iteration with what the loop knows (tracked
 * point count, task error norm, camera position, arm status), the monitor stops the servo with a status and a clear
 * message on lost tracking, a growing error, leaving the workspace, an arm joint limit or the iteration budget. The
 * stop is latched until reset(): the caller must command a zero velocity from then on. No ROS in it.
 *
 * Independent of InvariantServo's own stop criteria (which watch the control law): this one watches the whole loop,
 * including the arm and the tracker, and is the last line before the motion command.
 */
#pragma once

#include <string>

#include <Eigen/Core>

#include "exocet_servo/arm/arm_kinematics.h"

namespace exocet_servo {
namespace control {

/// Thresholds of the stops; validate() lists the allowed ranges.
struct ServoSafetyConfig {
  /// Fewer tracked points than this is lost tracking, [4, 100000] (4: the least the servo law accepts).
  int min_tracked_points = 8;
  /// The error is growing when |e| > growth_factor x its smallest value so far, (1, 1e6] ...
  double growth_factor = 2.0;
  /// ... for this many consecutive iterations, [1, 10000].
  int growth_iterations = 5;
  /// |e| at or below this never counts as growing, [0, 1]: near the goal |e| is the measurement's noise, and against a
  /// lucky low sample the noise alone would look like a growth. 0: off.
  double growth_floor = 0.0;
  /// Workspace box of the camera centre (world, m); min < max on every axis.
  Eigen::Vector3d workspace_min_m = Eigen::Vector3d(-2.0, -2.0, -2.0);
  Eigen::Vector3d workspace_max_m = Eigen::Vector3d(2.0, 2.0, 2.0);
  /// And a sphere around workspace_centre_m (e.g. a stand-off around the object); radius 0 disables it, [0, 1000].
  Eigen::Vector3d workspace_centre_m = Eigen::Vector3d::Zero();
  double workspace_radius_m = 0.0;
  /// Iteration budget, [1, 10000000].
  int max_iterations = 500;
  /// Whether the arm's kSingular (damped, the twist no longer followed exactly) also stops the servo.
  bool stop_on_singular = false;
  /// "" or every bad field with its allowed range ("; "-joined).
  std::string validate() const;
};

/// Verdict after an iteration.
enum class SafetyStatus {
  kOk,             ///< keep going
  kLostTracking,   ///< too few tracked points
  kErrorGrowing,   ///< |e| stayed above growth_factor x its minimum for growth_iterations iterations
  kLeftWorkspace,  ///< the camera left the workspace box or sphere
  kJointLimit,     ///< the arm stopped on a joint limit
  kSingular,       ///< the arm is near a singularity (only with stop_on_singular)
  kMaxIterations,  ///< iteration budget spent
  kInvalidInput,   ///< a non-finite error norm or position, a negative count, or the arm refused its input
};

/// Short name of a status ("ok", "lost tracking", "error growing", "left workspace", "joint limit", ...).
std::string toString(SafetyStatus status);

/// What the loop reports after an iteration.
struct SafetyInput {
  int tracked_points = 0;   ///< points the tracker still follows (matched with the reference)
  double error_norm = 0.0;  ///< the task error |e| of the servo law
  Eigen::Vector3d camera_position_m = Eigen::Vector3d::Zero();  ///< controlled camera centre (world)
  arm::ArmStatus arm_status = arm::ArmStatus::kOk;              ///< of the last motion command
  std::string arm_message;                                      ///< its text (quoted in the stop message)
};

/// The monitor.
class ServoSafetyMonitor {
 public:
  /// @throws std::invalid_argument with config.validate()'s message.
  explicit ServoSafetyMonitor(const ServoSafetyConfig& config);

  /// Checks one iteration; returns kOk or the stop (latched: later calls return it again without counting).
  /// Order of the checks: input, arm joint limit, singular, workspace, lost tracking, error growth, budget.
  SafetyStatus update(const SafetyInput& input);

  /// Clears the stop and the history (a new servoing).
  void reset();

  SafetyStatus status() const { return status_; }
  bool stopped() const { return status_ != SafetyStatus::kOk; }
  /// Why it stopped ("" while kOk), e.g. "lost tracking: 5 tracked points < 8 at iteration 12".
  const std::string& message() const { return message_; }
  int iterations() const { return iterations_; }
  double minErrorNorm() const { return min_error_; }
  const ServoSafetyConfig& config() const { return config_; }

 private:
  SafetyStatus stop(SafetyStatus status, const std::string& message);

  ServoSafetyConfig config_;
  SafetyStatus status_ = SafetyStatus::kOk;
  std::string message_;
  int iterations_ = 0;
  int growth_count_ = 0;
  double min_error_ = 0.0;
};

}  // namespace control
}  // namespace exocet_servo
