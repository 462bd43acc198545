/**
 * @file arm_inverse_kinematics.h
 * @brief Numerical inverse kinematics of the 6-DOF arm (sim/arm_kinematics.h) and the pre-programmed alternative of
 * the servoing (2D4 report 2.6, issue 6): the joint targets of every acquisition pose, to be executed open loop.
 * Levenberg-Marquardt on the pose error (position and rotation vector, base frame) with the geometric Jacobian,
 * projected into the joint limits at every step, from a seed q; when the seeded solve fails, deterministic restarts
 * from other seeds. No ROS in it.
 */
#pragma once

#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "exocet_servo/arm/arm_kinematics.h"

namespace exocet_servo {
namespace trajectory {

/// Solver parameters; validate() lists the allowed ranges.
struct IkConfig {
  double position_tolerance_m = 1e-9;    ///< converged when the position residual is below, (0, 0.1]
  double rotation_tolerance_rad = 1e-9;  ///< and the rotation residual below, (0, 0.1]
  int max_iterations = 200;              ///< per attempt, [1, 100000]
  double initial_damping = 1e-3;         ///< LM lambda, (0, 1e6]
  /// Restarts from other seeds (deterministic, spread in the joint limits) after a failed seeded solve, [0, 1000].
  int restarts = 16;
  unsigned restart_seed = 1;
  /// Seeds too far from the seed of the call are skipped: within this max joint distance (rad) of the seed the
  /// solution stays on the seed's branch (elbow, wrist) when a nearby one exists; 0 allows any restart. [0, 100]
  double max_restart_distance_rad = 0.0;
  /// "" or every bad field with its allowed range ("; "-joined).
  std::string validate() const;
};

enum class IkStatus {
  kConverged,      ///< residuals below the tolerances
  kUnreachable,    ///< the target is beyond the arm's reach, or the solver stalled away from it with free joints
  kJointLimits,    ///< the solver stalled with joints on their limits: reachable only beyond them
  kMaxIterations,  ///< still improving when the iteration budget was spent
};

/// Short name of a status ("converged", "unreachable", "joint limits", "max iterations").
std::string toString(IkStatus status);

struct IkResult {
  IkStatus status = IkStatus::kUnreachable;
  std::string message;                            ///< why it failed ("" when converged)
  arm::JointVector q = arm::JointVector::Zero();  ///< best joint angles found (within the limits)
  double position_residual_m = 0.0;               ///< |p_target - p(q)| of the flange
  double rotation_residual_rad = 0.0;             ///< angle of R_target R(q)^T
  int iterations = 0;                             ///< over every attempt
  int attempts = 0;                               ///< 1 + restarts used
};

/// Inverse kinematics of a flange pose (base frame) from a seed q (clamped into the limits).
IkResult solveFlangeIk(const arm::ArmModel& arm, const Eigen::Isometry3d& base_T_flange_target,
                       const arm::JointVector& seed, const IkConfig& config = IkConfig());

/// Inverse kinematics of a camera pose (base frame) for a camera fixed on the flange at flange_T_camera; the residuals
/// are those of the flange (the same rotation, positions differ by the lever arm).
IkResult solveCameraIk(const arm::ArmModel& arm, const Eigen::Isometry3d& flange_T_camera,
                       const Eigen::Isometry3d& base_T_camera_target, const arm::JointVector& seed,
                       const IkConfig& config = IkConfig());

/// Joint targets of a sequence of acquisition poses (the pre-programmed alternative, executed open loop): each solved
/// from the previous solution (the first from q0) so that the arm moves little between poses.
/// @param config IK parameters; restarts (nearest seeds first) are allowed for every pose.
/// @return one IkResult per pose (check each status); after a failure the next pose is seeded from the last
///         converged q.
std::vector<IkResult> planJointTargets(const arm::ArmModel& arm, const Eigen::Isometry3d& flange_T_camera,
                                       const std::vector<Eigen::Isometry3d>& base_T_camera_poses,
                                       const arm::JointVector& q0, const IkConfig& config = IkConfig());

}  // namespace trajectory
}  // namespace exocet_servo
