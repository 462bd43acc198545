/**
 * @file acquisition_feasibility.h
 * @brief Which acquisitions the arm can perform (2D4 report: "the simulation of the arm makes possible to determine
 * which trajectories can be performed within the robot workspace"), issue 6. Two tools:
 *  - checkFeasibility(): inverse kinematics along a sequence of left camera poses (an acquisition plan's, or the
 *    repeated-servoing poses left_0 (left_T_right)^k) AND along the path between consecutive poses (the servo follows
 *    roughly the screw / geodesic between its stops), each solve seeded by the previous one so that the arm stays on
 *    one branch, as a resolved-rate motion would; per pose: reachable, joint-limit margin, smallest singular value of
 *    the Jacobian; overall: feasible, the first failing pose and why, the worst margins.
 *  - searchPlacement(): where the object's vertical axis (the vent) should stand in the arm's base frame, and from
 *    which start azimuth the rig should begin, so that N servoings of the rig's screw around that axis are feasible
 *    with the best-conditioned arm (grid search).
 * No ROS in it.
 */
#pragma once

#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "exocet_servo/arm/arm_kinematics.h"
#include "exocet_servo/trajectory/arm_inverse_kinematics.h"

namespace exocet_servo {
namespace trajectory {

/// Thresholds of the check; validate() lists the allowed ranges.
struct FeasibilityConfig {
  /// Poses checked on the geodesic of each step (from pose k - 1 to pose k, pose k included), [1, 1000].
  int samples_per_step = 10;
  /// Smallest singular value of the arm's Jacobian required at every pose; the default is the arm's damping
  /// threshold (sim::ArmModelConfig::singular_threshold): below it the resolved rate no longer follows the twist.
  /// (0, 10]
  double min_sigma = 0.04;
  /// Distance (rad) every joint must keep from its limits, [0, pi].
  double min_joint_margin_rad = 0.05;
  /// Largest change of any joint between consecutive checked poses (rad): more means the solution jumped to another
  /// branch (elbow, wrist flip) that a continuous motion cannot follow. (0, 2 pi]
  double max_joint_step_rad = 0.5;
  /// Stop at the first failing pose (the search uses it); otherwise every pose is checked (after an unreachable pose
  /// the next is seeded from the last solved one).
  bool stop_at_first_failure = false;
  /// Solver of the first pose (restarts allowed, nearest seeds first); along the path the solves are seeded by the
  /// previous solution and restarts are limited to max_joint_step_rad around it (one branch).
  IkConfig ik = [] {
    IkConfig c;
    c.position_tolerance_m = 1e-8;
    c.rotation_tolerance_rad = 1e-8;
    return c;
  }();
  /// "" or every bad field with its allowed range ("; "-joined).
  std::string validate() const;
};

/// Verdict on one pose; the first failing condition in this order.
enum class PoseVerdict {
  kOk,
  kUnreachable,  ///< inverse kinematics did not converge (out of reach, or only beyond the joint limits)
  kBranchJump,   ///< solved, but only by a joint jump larger than max_joint_step_rad from the previous pose
  kJointMargin,  ///< a joint closer to its limit than min_joint_margin_rad
  kSingular,     ///< smallest singular value of the Jacobian below min_sigma
};

/// Short name ("ok", "unreachable", "branch jump", "joint margin", "singular").
std::string toString(PoseVerdict verdict);

/// One checked pose.
struct PoseFeasibility {
  int step = 0;           ///< 0: the first pose; k >= 1: on the path from pose k - 1 to pose k
  double fraction = 1.0;  ///< along the step, (0, 1]; 1 is pose k itself (and the first pose)
  Eigen::Isometry3d base_T_camera = Eigen::Isometry3d::Identity();  ///< the camera pose checked
  IkStatus ik_status = IkStatus::kUnreachable;
  bool reachable = false;                         ///< ik_status == kConverged
  arm::JointVector q = arm::JointVector::Zero();  ///< the solution (the best attempt when unreachable)
  double joint_margin_rad = 0.0;                  ///< smallest distance of a joint to its limits
  int margin_joint = -1;                          ///< that joint, 0-based
  double sigma_min = 0.0;                         ///< smallest singular value of the Jacobian at q
  double joint_step_rad = 0.0;                    ///< largest joint change from the previous checked pose
  PoseVerdict verdict = PoseVerdict::kUnreachable;
  std::string message;  ///< "" when ok; else what failed, its value and the allowed range
};

/// The check of a whole sequence.
struct FeasibilityReport {
  bool feasible = false;               ///< every pose kOk
  std::vector<PoseFeasibility> poses;  ///< in path order: the first pose, then samples_per_step per step
  int steps = 0;                       ///< steps of the sequence (poses given - 1)
  /// Steps from the start whose every checked pose is kOk (the servoings the arm can perform in a row).
  int feasible_steps = 0;
  int first_failing = -1;  ///< index into poses, -1 when feasible
  /// "" when feasible; else names the pose (step, fraction, index in the sequence) and what failed.
  std::string reason;
  /// Over the reachable checked poses up to the first failing one (included when reachable), or all when feasible.
  double worst_sigma_min = 0.0;
  int worst_sigma_index = -1;
  double worst_joint_margin_rad = 0.0;
  int worst_margin_index = -1;
  int worst_margin_joint = -1;
};

/// Checks that the arm can take the camera (fixed on the flange at flange_T_camera) through every pose of
/// base_T_camera_poses in order and along the geodesic between consecutive poses
/// (P_k-1 exp(s log(P_k-1^-1 P_k)), s in (0, 1], which for repeated servoings is the rig's screw T^s).
/// @param seed joint angles to start the first solve from (e.g. the arm's current joints; the first pose's branch
///        is the nearest converged one).
/// @throws std::invalid_argument when config.validate() is not empty.
FeasibilityReport checkFeasibility(const arm::ArmModel& arm, const Eigen::Isometry3d& flange_T_camera,
                                   const std::vector<Eigen::Isometry3d>& base_T_camera_poses,
                                   const arm::JointVector& seed, const FeasibilityConfig& config = FeasibilityConfig());

/// The repeated-servoing poses left_0 (left_T_right)^k, k = 0 .. servoings.
std::vector<Eigen::Isometry3d> repeatedServoingPoses(const Eigen::Isometry3d& base_T_left_0,
                                                     const Eigen::Isometry3d& left_T_right, int servoings);

/// Grid of the placement search; validate() lists the allowed ranges.
struct PlacementSearchConfig {
  int servoings = 5;  ///< servoings that must be feasible (5 x 18 deg: a quarter circle), [1, 100]
  /// Grid of the object's axis base (x, y) in the arm's base frame (m), step_m apart, bounds included. Each bound in
  /// [-10, 10], min <= max, step_m in [0.01, 5].
  /// Default: in front of the vehicle (x forward), where it lands facing the vent.
  double x_min_m = 0.5;
  double x_max_m = 2.0;
  double y_min_m = -1.0;
  double y_max_m = 1.0;
  double step_m = 0.1;
  /// Heights of the object's base (the seabed) tried, m in [-10, 10], at least one; default the simulator's seabed.
  std::vector<double> base_z_m = {-0.2};
  /// The object's axis must stand at least this far (horizontally) from the arm's joint-1 axis (the vehicle), [0, 10].
  double min_axis_distance_m = 0.5;
  /// Start azimuths tried (evenly spread over 2 pi, from world x, counter-clockwise), [1, 3600].
  int azimuth_samples = 72;
  /// Height of the left camera above the object's base along the axis (m), [-10, 10]: mid-height of the 0.3 m vent.
  double camera_height_m = 0.15;
  /// Thresholds of each candidate's check; the search stops each check at its first failure and allows 4 IK restarts
  /// (instead of 16: about twice as fast, the same choice on the default arm).
  FeasibilityConfig feasibility = [] {
    FeasibilityConfig c;
    c.stop_at_first_failure = true;
    c.ik.restarts = 4;
    return c;
  }();
  /// "" or every bad field with its allowed range ("; "-joined).
  std::string validate() const;
};

/// The placement found.
struct PlacementResult {
  bool found = false;
  std::string message;  ///< why nothing was found, or a one-line summary of the choice
  Eigen::Vector3d axis_base_m = Eigen::Vector3d::Zero();  ///< where the object's axis base should be (base frame)
  double start_azimuth_rad = 0.0;                         ///< of the left camera around the axis, from world x
  Eigen::Isometry3d base_T_left_start = Eigen::Isometry3d::Identity();
  arm::JointVector q_start = arm::JointVector::Zero();  ///< joints at the start pose (the arm's q_initial)
  FeasibilityReport report;                             ///< of the chosen placement over `servoings`
  int candidates = 0;         ///< (x, y, z, azimuth) combinations on the grid, min_axis_distance_m away from the arm
  int solved_candidates = 0;  ///< those that reached the inverse kinematics
  int feasible_candidates = 0;
};

/// Grid search of the placement of an object with a vertical axis for repeated servoings of the rig.
///
/// For each grid point (x, y, z) at least min_axis_distance_m from the arm's axis and each start azimuth a, the left
/// camera starts where the rig's screw axis (of left_T_right) lies on the vertical line through (x, y, z), at azimuth
/// a and camera_height_m (alignScrewWithAxis()); the poses are repeatedServoingPoses(start, left_T_right, servoings).
/// The first pose is solved from q_reference turned about joint 1 by the bearing change of the camera (the arm is
/// symmetric about that axis, so the reference's elbow and wrist configuration is kept), then checkFeasibility().
/// Objective: among the feasible candidates, the largest worst-case smallest singular value of the Jacobian along
/// the whole path (the distance to the nearest singularity, which is what stopped the servo); ties (within 1e-6)
/// go to the larger worst joint margin. Candidates with a stop whose flange is beyond the arm's reach bound
/// (sim::ArmModel::reachBoundM()) are skipped before any inverse kinematics. About 3-7 s with the defaults (24192
/// candidates) on one core.
/// @throws std::invalid_argument when config.validate() is not empty.
PlacementResult searchPlacement(const arm::ArmModel& arm, const Eigen::Isometry3d& flange_T_camera,
                                const Eigen::Isometry3d& left_T_right, const arm::JointVector& q_reference,
                                const PlacementSearchConfig& config = PlacementSearchConfig());

}  // namespace trajectory
}  // namespace exocet_servo
