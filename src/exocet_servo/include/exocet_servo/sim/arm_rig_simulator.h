/**
 * @file arm_rig_simulator.h
 * @brief The stereo rig on the arm (issue 6): the 6-DOF arm of arm_kinematics.h carries the rig (left camera at
 * flange_T_left, right camera at left_T_right from trajectory/rig_geometry.h), two pinhole cameras with different
 * intrinsics and the ray-cast vent scene (vent_renderer.h). The servo commands the left camera's velocity in its own
 * frame; the simulator maps it to joint velocities by resolved rate (velocity scaling, joint-limit stop) and integrates
 * the joints (Euler, dq dt). The pre-programmed alternative moves the joints straight to targets at their velocity
 * limits. No ROS in it.
 *
 * World = the arm's base frame, z up (the arm's base 0.2 m above the seabed, on a vehicle landed in front of the
 * vent). Default scene: the vent's base at (1.3, 0, -0.2) m (seabed plane z = -0.2), 0.3 m high, 0.1 m radius; the
 * default joint angles put the left camera 0.6 m from the vent's axis on the arm's side (at (0.7, 0, -0.05), azimuth
 * 180 deg), at mid-height, looking at the axis, elbow up. Acquisition legs of 60 deg centred on azimuth 180 deg at
 * 0.5-0.7 m from the axis over the vent's height are all within reach and limits; legs of 90 deg lose their far
 * ends (the wrist centre beyond its 1.10 m reach).
 */
#pragma once

#include <memory>
#include <string>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "exocet_servo/arm/arm_kinematics.h"
#include "exocet_servo/sim/point_scene.h"
#include "exocet_servo/sim/vent_renderer.h"
#include "exocet_servo/trajectory/rig_geometry.h"

namespace exocet_servo {
namespace sim {

/// The arm, the rig and the scene; validate() lists the allowed ranges.
struct ArmRigConfig {
  arm::ArmModelConfig arm = arm::ArmModel::defaultConfig();
  /// Left camera on the flange: camera axes = flange axes (optical axis = flange z), the rig's centre on the flange
  /// axis: the left camera half a baseline to the left (-x) and 0.08 m ahead of the flange.
  Eigen::Isometry3d flange_T_left = Eigen::Translation3d(-0.15, 0.0, 0.08) * Eigen::Isometry3d::Identity();
  trajectory::RigGeometry rig;  ///< right camera relative to the left one (0.3 m, 18 deg toe-in)
  PinholeCamera left_camera;    ///< 800 px focal length, 640 x 480
  PinholeCamera right_camera = [] {
    PinholeCamera c;
    c.k = intrinsics(720.0, 725.0, 330.0, 245.0);  // another lens: the servo is intrinsics-free
    return c;
  }();
  VentSceneConfig scene = [] {
    VentSceneConfig s;
    s.base_m = Eigen::Vector3d(1.3, 0.0, -0.2);
    return s;
  }();
  arm::JointVector q_initial = defaultJointAngles();
  /// Joint angles of the default start: left camera at lookAt((0.7, 0, -0.05), (1.3, 0, -0.05)) with the default
  /// flange_T_left, elbow up (0.3 rad or more from every joint limit, smallest singular value of J 0.30).
  static arm::JointVector defaultJointAngles();
  /// "" or every bad field with its allowed range ("; "-joined).
  std::string validate() const;
};

/// Both cameras' views.
struct StereoViews {
  RenderedView left;
  RenderedView right;
};

/// The simulator. Not thread-safe.
class ArmRigSimulator {
 public:
  /// Builds the arm and the renderer (a few hundred ms for the textures).
  /// @throws std::invalid_argument with config.validate()'s message, or when q_initial is out of the joint limits.
  explicit ArmRigSimulator(const ArmRigConfig& config);

  /// Moves the left camera with the twist (v [m/s], omega [rad/s]) in its own frame for dt_s: converted to the flange
  /// body twist (adjoint of flange_T_left), resolved rate, then q += dq dt. On kJointLimit or kInvalidInput the arm
  /// does not move. The returned joint velocities are those applied.
  arm::ResolvedRate command(const Eigen::Matrix<double, 6, 1>& twist_left, double dt_s);

  /// Open-loop joint motion towards q_target for dt_s: every joint at most at its velocity limit, all scaled by the
  /// same factor so that they arrive together (a straight line in joint space). kJointLimit (no motion) when the
  /// target is outside the limits; kVelocityScaled while limited by a velocity.
  /// @return true once q equals q_target.
  bool stepTowards(const arm::JointVector& q_target, double dt_s, arm::ArmStatus* status = nullptr,
                   std::string* message = nullptr);

  /// Sets the joint angles (teleport; velocities zeroed). @throws std::invalid_argument outside the limits.
  void setJointPositions(const arm::JointVector& q);

  const arm::JointVector& jointPositions() const { return q_; }
  const arm::JointVector& jointVelocities() const { return dq_; }  ///< last applied, rad/s
  Eigen::Isometry3d worldFromFlange() const { return arm_.forward(q_); }
  Eigen::Isometry3d worldFromLeft() const;
  Eigen::Isometry3d worldFromRight() const;
  /// Pose of the left camera at arbitrary joint angles (same model).
  Eigen::Isometry3d worldFromLeftAt(const arm::JointVector& q) const;

  /// Renders both cameras at the current joint angles.
  StereoViews render() const;

  const arm::ArmModel& arm() const { return arm_; }
  const VentRenderer& renderer() const { return *renderer_; }
  const ArmRigConfig& config() const { return config_; }
  Eigen::Isometry3d leftFromRight() const { return left_T_right_; }

 private:
  ArmRigConfig config_;
  arm::ArmModel arm_;
  std::unique_ptr<VentRenderer> renderer_;
  Eigen::Isometry3d left_T_right_;
  Eigen::Matrix<double, 6, 6> flange_ad_left_;  ///< twist in the left frame -> flange body twist
  arm::JointVector q_;
  arm::JointVector dq_ = arm::JointVector::Zero();
};

}  // namespace sim
}  // namespace exocet_servo
