#include "exocet_servo/sim/arm_rig_simulator.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace exocet_servo {
namespace sim {

arm::JointVector ArmRigConfig::defaultJointAngles() {
  // Solved once with trajectory::solveCameraIk (the best-conditioned elbow-up solution); to 1e-10 rad.
  arm::JointVector q;
  q << -0.2914567945, -0.3036736148, 0.7075826540, -0.3153647979, -1.9567479010, 1.4485933150;
  return q;
}

std::string ArmRigConfig::validate() const {
  std::ostringstream errors;
  auto add = [&errors](const std::string& what) {
    if (what.empty()) return;
    if (errors.tellp() > 0) errors << "; ";
    errors << what;
  };
  add(arm.validate().empty() ? "" : "arm: " + arm.validate());
  add(rig.validate().empty() ? "" : "rig: " + rig.validate());
  add(scene.validate().empty() ? "" : "scene: " + scene.validate());
  const Eigen::Matrix3d r = flange_T_left.linear();
  if (!flange_T_left.matrix().allFinite() || (r.transpose() * r - Eigen::Matrix3d::Identity()).norm() > 1e-6 ||
      r.determinant() < 0.0 || flange_T_left.translation().norm() > 2.0) {
    add("flange_T_left must be a rigid transform (rotation within 1e-6 of orthonormal) with |translation| in [0, 2] m");
  }
  auto camera_ok = [](const PinholeCamera& c) {
    return c.k.allFinite() && c.k(0, 0) > 0.0 && c.k(1, 1) > 0.0 && c.width_px >= 16 && c.height_px >= 16 &&
           c.width_px <= 10000 && c.height_px <= 10000;
  };
  if (!camera_ok(left_camera)) add("left_camera must have fx, fy > 0 and width_px, height_px in [16, 10000]");
  if (!camera_ok(right_camera)) add("right_camera must have fx, fy > 0 and width_px, height_px in [16, 10000]");
  if (!q_initial.allFinite()) add("q_initial must be finite");
  return errors.str();
}

ArmRigSimulator::ArmRigSimulator(const ArmRigConfig& config)
    : config_(config), arm_(config.arm.validate().empty() ? config.arm : arm::ArmModel::defaultConfig()) {
  const std::string errors = config.validate();
  if (!errors.empty()) throw std::invalid_argument("ArmRigConfig: " + errors);
  std::string why;
  if (!arm_.withinLimits(config.q_initial, 0.0, &why)) throw std::invalid_argument("ArmRigConfig: q_initial: " + why);
  renderer_ = std::make_unique<VentRenderer>(config.scene);
  left_T_right_ = config.rig.leftFromRight();
  flange_ad_left_ = arm::adjoint(config.flange_T_left);
  q_ = config.q_initial;
}

arm::ResolvedRate ArmRigSimulator::command(const Eigen::Matrix<double, 6, 1>& twist_left, double dt_s) {
  // The same rigid motion seen from the flange: v_f = R v_c + t x (R omega_c), omega_f = R omega_c.
  const Eigen::Matrix<double, 6, 1> twist_flange = flange_ad_left_ * twist_left;
  arm::ResolvedRate r = arm_.resolvedRate(q_, twist_flange, dt_s);
  dq_ = r.joint_velocities_rad_s;
  if (r.status != arm::ArmStatus::kJointLimit && r.status != arm::ArmStatus::kInvalidInput) q_ += dq_ * dt_s;
  return r;
}

bool ArmRigSimulator::stepTowards(const arm::JointVector& q_target, double dt_s, arm::ArmStatus* status, std::string* message) {
  auto report = [&](arm::ArmStatus s, const std::string& m) {
    if (status != nullptr) *status = s;
    if (message != nullptr) *message = m;
  };
  dq_.setZero();
  if (!q_target.allFinite() || !(dt_s > 0.0)) {
    report(arm::ArmStatus::kInvalidInput, "invalid input: q_target must be finite and dt_s > 0");
    return false;
  }
  std::string why;
  if (!arm_.withinLimits(q_target, 1e-12, &why)) {
    report(arm::ArmStatus::kJointLimit, "target refused: " + why);
    return false;
  }
  const arm::JointVector delta = q_target - q_;
  // Uniform scale: every joint arrives at the same time (straight line in joint space).
  double scale = 1.0;
  int limiting = -1;
  const arm::JointVector vmax = arm_.maxVelocities();
  for (int i = 0; i < arm::kArmJoints; ++i) {
    const double need = std::abs(delta(i)) / dt_s;
    if (need > vmax(i) && vmax(i) / need < scale) {
      scale = vmax(i) / need;
      limiting = i;
    }
  }
  dq_ = delta / dt_s * scale;
  q_ += dq_ * dt_s;
  if (scale < 1.0) {
    std::ostringstream m;
    m << "joint " << (limiting + 1) << " (" << arm_.config().joints[limiting].name << ") at its velocity limit "
      << vmax(limiting) << " rad/s";
    report(arm::ArmStatus::kVelocityScaled, m.str());
    return false;
  }
  q_ = q_target;  // exact arrival, no rounding residue
  report(arm::ArmStatus::kOk, "");
  return true;
}

void ArmRigSimulator::setJointPositions(const arm::JointVector& q) {
  std::string why;
  if (!q.allFinite() || !arm_.withinLimits(q, 1e-12, &why)) {
    throw std::invalid_argument("ArmRigSimulator::setJointPositions: " + (why.empty() ? "q must be finite" : why));
  }
  q_ = q;
  dq_.setZero();
}

Eigen::Isometry3d ArmRigSimulator::worldFromLeftAt(const arm::JointVector& q) const {
  return arm_.forward(q) * config_.flange_T_left;
}

Eigen::Isometry3d ArmRigSimulator::worldFromLeft() const { return worldFromLeftAt(q_); }

Eigen::Isometry3d ArmRigSimulator::worldFromRight() const { return worldFromLeft() * left_T_right_; }

StereoViews ArmRigSimulator::render() const {
  StereoViews v;
  v.left = renderer_->render(config_.left_camera, worldFromLeft());
  v.right = renderer_->render(config_.right_camera, worldFromRight());
  return v;
}

}  // namespace sim
}  // namespace exocet_servo
