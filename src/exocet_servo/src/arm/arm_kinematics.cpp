#include "exocet_servo/arm/arm_kinematics.h"

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <sstream>
#include <stdexcept>

#include <Eigen/Dense>

#include "exocet_servo/trajectory/se3.h"

namespace exocet_servo {
namespace arm {

namespace {

double deg(double d) { return d * M_PI / 180.0; }

/// Transform of one standard DH link at joint angle q.
Eigen::Isometry3d dhLink(const DhJoint& j, double q) {
  const double theta = q + j.theta_offset_rad;
  const double ct = std::cos(theta), st = std::sin(theta);
  const double ca = std::cos(j.alpha_rad), sa = std::sin(j.alpha_rad);
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.linear() << ct, -st * ca, st * sa,  //
      st, ct * ca, -ct * sa,            //
      0.0, sa, ca;
  t.translation() << j.a_m * ct, j.a_m * st, j.d_m;
  return t;
}

std::string jointLabel(const ArmModelConfig& config, int i) {
  std::ostringstream s;
  s << "joint " << (i + 1) << " (" << config.joints[i].name << ")";
  return s.str();
}

}  // namespace

std::string toString(ArmStatus status) {
  switch (status) {
    case ArmStatus::kOk:
      return "ok";
    case ArmStatus::kVelocityScaled:
      return "velocity scaled";
    case ArmStatus::kJointLimit:
      return "joint limit";
    case ArmStatus::kSingular:
      return "singular";
    case ArmStatus::kInvalidInput:
      return "invalid input";
  }
  return "unknown";
}

std::string ArmModelConfig::validate() const {
  std::ostringstream errors;
  auto check = [&errors](bool ok, const std::string& field, const std::string& range) {
    if (ok) return;
    if (errors.tellp() > 0) errors << "; ";
    errors << field << " must be in " << range;
  };
  for (int i = 0; i < kArmJoints; ++i) {
    const DhJoint& j = joints[i];
    const std::string p = "joints[" + std::to_string(i) + "].";
    check(std::isfinite(j.a_m) && std::abs(j.a_m) <= 100.0, p + "a_m", "[-100, 100]");
    check(std::isfinite(j.d_m) && std::abs(j.d_m) <= 100.0, p + "d_m", "[-100, 100]");
    check(std::isfinite(j.alpha_rad) && std::abs(j.alpha_rad) <= M_PI, p + "alpha_rad", "[-pi, pi]");
    check(std::isfinite(j.theta_offset_rad) && std::abs(j.theta_offset_rad) <= 2 * M_PI, p + "theta_offset_rad",
          "[-2 pi, 2 pi]");
    check(std::isfinite(j.min_rad) && std::isfinite(j.max_rad) && j.min_rad < j.max_rad && j.min_rad >= -4 * M_PI &&
              j.max_rad <= 4 * M_PI,
          p + "min_rad, max_rad", "-4 pi <= min_rad < max_rad <= 4 pi");
    check(j.max_velocity_rad_s > 0.0 && j.max_velocity_rad_s <= 100.0, p + "max_velocity_rad_s", "(0, 100]");
  }
  check(singular_threshold > 0.0 && singular_threshold <= 1.0, "singular_threshold", "(0, 1]");
  check(max_damping > 0.0 && max_damping <= 1.0, "max_damping", "(0, 1]");
  return errors.str();
}

ArmModel::ArmModel(const ArmModelConfig& config) : config_(config) {
  const std::string errors = config.validate();
  if (!errors.empty()) throw std::invalid_argument("ArmModelConfig: " + errors);
}

ArmModelConfig ArmModel::defaultConfig() {
  ArmModelConfig c;
  // name, a, alpha, d, offset, min, max, max velocity
  c.joints[0] = {"shoulder yaw", 0.10, -M_PI / 2, 0.25, 0.0, deg(-170), deg(170), 0.5};
  c.joints[1] = {"shoulder pitch", 0.60, 0.0, 0.0, 0.0, deg(-110), deg(110), 0.5};
  c.joints[2] = {"elbow", 0.05, -M_PI / 2, 0.0, 0.0, deg(-150), deg(150), 0.5};
  c.joints[3] = {"forearm roll", 0.0, M_PI / 2, 0.50, 0.0, deg(-180), deg(180), 1.0};
  c.joints[4] = {"wrist pitch", 0.0, -M_PI / 2, 0.0, 0.0, deg(-135), deg(135), 1.0};
  c.joints[5] = {"flange roll", 0.0, 0.0, 0.12, 0.0, deg(-350), deg(350), 1.0};
  return c;
}

std::vector<Eigen::Isometry3d> ArmModel::frames(const JointVector& q) const {
  std::vector<Eigen::Isometry3d> f(kArmJoints + 1, Eigen::Isometry3d::Identity());
  for (int i = 0; i < kArmJoints; ++i) f[i + 1] = f[i] * dhLink(config_.joints[i], q(i));
  return f;
}

Eigen::Isometry3d ArmModel::forward(const JointVector& q) const {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  for (int i = 0; i < kArmJoints; ++i) t = t * dhLink(config_.joints[i], q(i));
  return t;
}

ArmJacobian ArmModel::jacobianBase(const JointVector& q) const {
  const std::vector<Eigen::Isometry3d> f = frames(q);
  const Eigen::Vector3d p_end = f[kArmJoints].translation();
  ArmJacobian j;
  for (int i = 0; i < kArmJoints; ++i) {
    // Joint i + 1 turns about z of frame i (standard DH).
    const Eigen::Vector3d z = f[i].linear().col(2);
    j.block<3, 1>(0, i) = z.cross(p_end - f[i].translation());
    j.block<3, 1>(3, i) = z;
  }
  return j;
}

ArmJacobian ArmModel::jacobianFlange(const JointVector& q) const {
  const Eigen::Matrix3d rt = forward(q).linear().transpose();
  ArmJacobian j = jacobianBase(q);
  j.topRows<3>() = rt * j.topRows<3>();
  j.bottomRows<3>() = rt * j.bottomRows<3>();
  return j;
}

ResolvedRate ArmModel::resolvedRate(const JointVector& q, const Eigen::Matrix<double, 6, 1>& twist_flange,
                                    double dt_s) const {
  ResolvedRate r;
  if (!q.allFinite() || !twist_flange.allFinite() || !(dt_s > 0.0)) {
    // A stop is the only safe answer to a corrupt input.
    r.status = ArmStatus::kInvalidInput;
    r.message = "invalid input: q and the twist must be finite and dt_s > 0";
    r.scale = 0.0;
    return r;
  }
  const ArmJacobian j = jacobianFlange(q);
  const Eigen::JacobiSVD<Eigen::Matrix<double, 6, 6>> svd(j, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Matrix<double, 6, 1> sigma = svd.singularValues();
  r.min_singular_value = sigma(kArmJoints - 1);
  // Damping only near the singularity, so that the twist is followed exactly elsewhere.
  double lambda2 = 0.0;
  const double eps = config_.singular_threshold;
  if (r.min_singular_value < eps) {
    const double ratio = r.min_singular_value / eps;
    lambda2 = (1.0 - ratio * ratio) * config_.max_damping * config_.max_damping;
  }
  // dq = V diag(s / (s^2 + lambda^2)) U^T twist.
  Eigen::Matrix<double, 6, 1> inv;
  for (int i = 0; i < kArmJoints; ++i) {
    const double s = sigma(i);
    inv(i) = (s * s + lambda2) > 0.0 ? s / (s * s + lambda2) : 0.0;
  }
  JointVector dq = svd.matrixV() * inv.asDiagonal() * svd.matrixU().transpose() * twist_flange;
  if (lambda2 > 0.0) {
    r.status = ArmStatus::kSingular;
    std::ostringstream m;
    m << "near a singularity: smallest singular value " << r.min_singular_value << " < " << eps
      << ", damped least squares (the twist is not followed exactly)";
    r.message = m.str();
  }

  // Uniform scaling keeps the direction of the twist (a per-joint clip would bend the path).
  double scale = 1.0;
  for (int i = 0; i < kArmJoints; ++i) {
    const double v = std::abs(dq(i));
    const double vmax = config_.joints[i].max_velocity_rad_s;
    if (v > vmax && vmax / v < scale) {
      scale = vmax / v;
      r.limiting_joint = i;
    }
  }
  if (scale < 1.0) {
    dq *= scale;
    r.scale = scale;
    if (r.status == ArmStatus::kOk) {
      const int i = r.limiting_joint;
      std::ostringstream m;
      m << "joint velocities scaled by " << scale << ": " << jointLabel(config_, i) << " would turn at "
        << std::abs(dq(i)) / scale << " rad/s, limit " << config_.joints[i].max_velocity_rad_s << " rad/s";
      r.status = ArmStatus::kVelocityScaled;
      r.message = m.str();
    }
  }

  // A joint that would cross its limit within dt while moving towards it stops everything: continuing with the other
  // joints would leave the commanded direction.
  for (int i = 0; i < kArmJoints; ++i) {
    const DhJoint& jt = config_.joints[i];
    const double next = q(i) + dq(i) * dt_s;
    const bool upper = next > jt.max_rad && dq(i) > 0.0;
    const bool lower = next < jt.min_rad && dq(i) < 0.0;
    if (!upper && !lower) continue;
    std::ostringstream m;
    m << std::fixed << std::setprecision(4) << jointLabel(config_, i) << " would cross its "
      << (upper ? "upper" : "lower") << " limit " << (upper ? jt.max_rad : jt.min_rad) << " rad ("
      << std::setprecision(1) << (upper ? jt.max_rad : jt.min_rad) * 180.0 / M_PI << " deg) within " << dt_s
      << " s: q = " << std::setprecision(4) << q(i) << " rad, dq/dt = " << dq(i) << " rad/s; motion stopped";
    r.status = ArmStatus::kJointLimit;
    r.message = m.str();
    r.limiting_joint = i;
    r.joint_velocities_rad_s.setZero();
    return r;
  }
  r.joint_velocities_rad_s = dq;
  return r;
}

bool ArmModel::withinLimits(const JointVector& q, double tolerance_rad, std::string* message) const {
  for (int i = 0; i < kArmJoints; ++i) {
    const DhJoint& j = config_.joints[i];
    if (q(i) >= j.min_rad - tolerance_rad && q(i) <= j.max_rad + tolerance_rad) continue;
    if (message != nullptr) {
      std::ostringstream m;
      m << jointLabel(config_, i) << " at " << q(i) << " rad is outside [" << j.min_rad << ", " << j.max_rad << "] rad";
      *message = m.str();
    }
    return false;
  }
  return true;
}

JointVector ArmModel::clampToLimits(const JointVector& q) const {
  return q.cwiseMax(minLimits()).cwiseMin(maxLimits());
}

double ArmModel::reachBoundM() const {
  double r = std::abs(config_.joints[0].a_m);
  for (int i = 1; i < kArmJoints; ++i) r += std::hypot(config_.joints[i].a_m, config_.joints[i].d_m);
  return r;
}

JointVector ArmModel::minLimits() const {
  JointVector v;
  for (int i = 0; i < kArmJoints; ++i) v(i) = config_.joints[i].min_rad;
  return v;
}

JointVector ArmModel::maxLimits() const {
  JointVector v;
  for (int i = 0; i < kArmJoints; ++i) v(i) = config_.joints[i].max_rad;
  return v;
}

JointVector ArmModel::maxVelocities() const {
  JointVector v;
  for (int i = 0; i < kArmJoints; ++i) v(i) = config_.joints[i].max_velocity_rad_s;
  return v;
}

Eigen::Matrix<double, 6, 6> adjoint(const Eigen::Isometry3d& a_T_b) {
  Eigen::Matrix<double, 6, 6> ad = Eigen::Matrix<double, 6, 6>::Zero();
  const Eigen::Matrix3d r = a_T_b.linear();
  ad.topLeftCorner<3, 3>() = r;
  ad.topRightCorner<3, 3>() = trajectory::skew(a_T_b.translation()) * r;
  ad.bottomRightCorner<3, 3>() = r;
  return ad;
}

}  // namespace arm
}  // namespace exocet_servo
