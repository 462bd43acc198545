/**
 * @file arm_kinematics.h
 * @brief Kinematic model of a 6-DOF arm with revolute joints (issue 6): STANDARD Denavit-Hartenberg parameters
 * (Craig's "distal" convention: link i = Rot_z(theta_i) Trans_z(d_i) Trans_x(a_i) Rot_x(alpha_i), joint i turns about
 * z_{i-1}), joint position and velocity limits, forward kinematics, the geometric Jacobian, and resolved-rate control
 * of a flange twist by damped least squares with velocity scaling and joint-limit stops. No ROS in it.
 *
 * Frames: the base frame of the arm (z up for the default arm) is the simulator's world frame; the flange frame is the
 * DH frame 6 (z along the tool approach). Twists are (v [m/s], omega [rad/s]) as in se3.h.
 */
#pragma once

#include <array>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace exocet_servo {
namespace arm {

constexpr int kArmJoints = 6;
using JointVector = Eigen::Matrix<double, kArmJoints, 1>;  ///< one value per joint (rad, rad/s)
using ArmJacobian = Eigen::Matrix<double, 6, kArmJoints>;  ///< rows (v, omega), columns the joints

/// One revolute joint and its link (standard DH).
struct DhJoint {
  std::string name = "joint";
  double a_m = 0.0;               ///< link length along x_i
  double alpha_rad = 0.0;         ///< link twist about x_i
  double d_m = 0.0;               ///< link offset along z_{i-1}
  double theta_offset_rad = 0.0;  ///< theta_i = q_i + theta_offset_rad
  double min_rad = -M_PI;         ///< position limits of q_i, min < max
  double max_rad = M_PI;
  double max_velocity_rad_s = 1.0;  ///< |dq_i/dt| limit, (0, 100]
};

/// Parameters of the arm; validate() lists the allowed ranges.
struct ArmModelConfig {
  std::array<DhJoint, kArmJoints> joints;
  /// Damped least squares (Nakamura/Chiaverini): below this smallest singular value of the Jacobian the damping
  /// lambda^2 = (1 - (sigma_min / threshold)^2) max_damping^2 is added, and the status is kSingular. (0, 1]
  double singular_threshold = 0.04;
  double max_damping = 0.04;  ///< (0, 1]
  /// "" or every bad field with its allowed range ("; "-joined).
  std::string validate() const;
};

/// Status of a resolved-rate step (or of any arm motion).
enum class ArmStatus {
  kOk,              ///< the twist is executed as asked
  kVelocityScaled,  ///< the joint velocities were scaled down uniformly (the twist direction is kept)
  kJointLimit,      ///< a joint would cross its position limit within dt: the motion is stopped (zero velocity)
  kSingular,        ///< near a singularity: the damped solution no longer follows the twist exactly
  kInvalidInput,    ///< non-finite q or twist, or dt <= 0: zero velocity
};

/// Short name of a status ("ok", "velocity scaled", "joint limit", "singular", "invalid input").
std::string toString(ArmStatus status);

/// Joint velocities of one resolved-rate step.
struct ResolvedRate {
  JointVector joint_velocities_rad_s = JointVector::Zero();  ///< to apply for dt (zero on kJointLimit)
  ArmStatus status = ArmStatus::kOk;
  std::string message;              ///< "" for kOk; names the joint and its limit for kJointLimit
  double scale = 1.0;               ///< uniform velocity scale applied, (0, 1]
  double min_singular_value = 0.0;  ///< of the Jacobian (flange frame)
  int limiting_joint = -1;          ///< joint index (0-based) that scaled or stopped the motion, -1 if none
};

/// The arm.
class ArmModel {
 public:
  /// @throws std::invalid_argument with config.validate()'s message.
  explicit ArmModel(const ArmModelConfig& config);

  /// A typical ROV manipulator-like arm (own geometry, not a ViSP robot): shoulder yaw / pitch, elbow, forearm roll,
  /// wrist pitch, flange roll (spherical wrist), base frame z up with joint 1 about +z: d1 0.25, a1 0.10, a2 0.60,
  /// a3 0.05, d4 0.50, d6 0.12 m (reach 1.22 m from the shoulder pitch axis to the flange; wrist centre 1.10 m). At
  /// q = 0 the upper arm points forward (+x) and the forearm and the flange axis straight down.
  /// Limits: q1 +-170 deg, q2 +-110 deg, q3 +-150 deg, q4 +-180 deg, q5 +-135 deg, q6 +-350 deg;
  /// velocities 0.5 rad/s (q1-q3), 1.0 rad/s (q4-q6).
  static ArmModelConfig defaultConfig();

  /// base_T_flange at q.
  Eigen::Isometry3d forward(const JointVector& q) const;
  /// base_T_frame_i for i = 0 (base) .. 6 (flange).
  std::vector<Eigen::Isometry3d> frames(const JointVector& q) const;

  /// Geometric Jacobian in the BASE frame: [v; omega] = J dq, with v the velocity of the flange origin and omega the
  /// angular velocity, both expressed in base coordinates.
  ArmJacobian jacobianBase(const JointVector& q) const;
  /// The same in the FLANGE frame (the body twist of the flange): diag(R^T, R^T) jacobianBase.
  ArmJacobian jacobianFlange(const JointVector& q) const;

  /// Resolved-rate control: joint velocities producing the flange body twist `twist_flange` (flange frame, m/s and
  /// rad/s) by damped least squares, scaled uniformly (direction kept) so that every joint respects its velocity
  /// limit; then, if a joint would cross its position limit within dt_s while moving towards it, the motion stops
  /// (zero velocities, kJointLimit naming the joint and the limit). Precedence: kInvalidInput > kJointLimit >
  /// kSingular > kVelocityScaled > kOk.
  ResolvedRate resolvedRate(const JointVector& q, const Eigen::Matrix<double, 6, 1>& twist_flange, double dt_s) const;

  /// Whether every joint is within its limits (with a tolerance, rad); `message` names the first joint out.
  bool withinLimits(const JointVector& q, double tolerance_rad = 0.0, std::string* message = nullptr) const;
  /// q clamped into the limits.
  JointVector clampToLimits(const JointVector& q) const;

  /// Upper bound of the distance from the shoulder point (0, 0, d1) (fixed on joint 1's axis) to the flange origin:
  /// |a1| + sum over i >= 2 of sqrt(a_i^2 + d_i^2).
  double reachBoundM() const;
  Eigen::Vector3d shoulderPointM() const { return Eigen::Vector3d(0.0, 0.0, config_.joints[0].d_m); }

  JointVector minLimits() const;
  JointVector maxLimits() const;
  JointVector maxVelocities() const;
  const ArmModelConfig& config() const { return config_; }

 private:
  ArmModelConfig config_;
};

/// Adjoint matrix Ad(a_T_b) mapping a twist in frame b to the same rigid motion's twist in frame a (v first).
Eigen::Matrix<double, 6, 6> adjoint(const Eigen::Isometry3d& a_T_b);

}  // namespace arm
}  // namespace exocet_servo
