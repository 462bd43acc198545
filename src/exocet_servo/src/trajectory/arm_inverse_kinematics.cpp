#include "exocet_servo/trajectory/arm_inverse_kinematics.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <sstream>
#include <stdexcept>

#include <Eigen/Dense>

#include "exocet_servo/trajectory/se3.h"

namespace exocet_servo {
namespace trajectory {

namespace {

using Vector6 = Eigen::Matrix<double, 6, 1>;

/// Pose error (position, rotation vector of R_target R^T), both in the base frame: to first order it is the base
/// twist J dq that the step must produce.
Vector6 poseError(const Eigen::Isometry3d& target, const Eigen::Isometry3d& current) {
  Vector6 e;
  e.head<3>() = target.translation() - current.translation();
  // Through the quaternion: full precision at small angles (the solver's last iterations).
  const Eigen::AngleAxisd aa(Eigen::Quaterniond(target.linear() * current.linear().transpose()).normalized());
  e.tail<3>() = aa.angle() * aa.axis();
  if (!e.tail<3>().allFinite()) e.tail<3>().setZero();
  return e;
}

/// One Levenberg-Marquardt attempt from q0 (already within the limits).
IkResult solveOnce(const arm::ArmModel& arm, const Eigen::Isometry3d& target, const arm::JointVector& q0,
                   const IkConfig& config) {
  const arm::JointVector lo = arm.minLimits(), hi = arm.maxLimits();
  IkResult r;
  r.attempts = 1;
  arm::JointVector q = q0;
  Vector6 e = poseError(target, arm.forward(q));
  double cost = e.squaredNorm();
  double lambda = config.initial_damping;
  bool stalled = false;
  auto converged = [&config](const Vector6& err) {
    return err.head<3>().norm() < config.position_tolerance_m && err.tail<3>().norm() < config.rotation_tolerance_rad;
  };
  double cost_window_start = cost;
  while (!converged(e)) {
    if (r.iterations >= config.max_iterations) break;
    // No real progress over a window: pressed against a limit or in a local minimum; more iterations will not help.
    if (r.iterations > 0 && r.iterations % 10 == 0) {
      if (cost > (1.0 - 1e-6) * cost_window_start) {
        stalled = true;
        break;
      }
      cost_window_start = cost;
    }
    ++r.iterations;
    const arm::ArmJacobian j = arm.jacobianBase(q);
    const Eigen::Matrix<double, 6, 6> jtj = j.transpose() * j;
    const arm::JointVector g = j.transpose() * e;
    bool accepted = false;
    while (lambda < 1e10) {
      const arm::JointVector dq = (jtj + lambda * Eigen::Matrix<double, 6, 6>::Identity()).ldlt().solve(g);
      // Projection on the limits: the joints stay physical at every iterate.
      const arm::JointVector q_new = (q + dq).cwiseMax(lo).cwiseMin(hi);
      const Vector6 e_new = poseError(target, arm.forward(q_new));
      const double cost_new = e_new.squaredNorm();
      if (cost_new < cost) {
        q = q_new;
        e = e_new;
        cost = cost_new;
        lambda = std::max(lambda / 10.0, 1e-12);
        accepted = true;
        break;
      }
      if ((q_new - q).norm() < 1e-15) break;  // the projection cancels the step: nothing left to try
      lambda *= 10.0;
    }
    if (!accepted) {
      stalled = true;
      break;
    }
  }
  r.q = q;
  r.position_residual_m = e.head<3>().norm();
  r.rotation_residual_rad = e.tail<3>().norm();
  if (converged(e)) {
    r.status = IkStatus::kConverged;
    return r;
  }
  std::ostringstream m;
  m << "position residual " << r.position_residual_m << " m, rotation residual " << r.rotation_residual_rad
    << " rad after " << r.iterations << " iterations";
  // On a limit when the gradient of the cost pushes a joint sitting on it outwards (checked on a budget stop too: the
  // projected steps can creep along a limit without stalling).
  const arm::JointVector g = arm.jacobianBase(q).transpose() * e;  // descent direction of the cost
  std::vector<int> blocked;
  for (int i = 0; i < arm::kArmJoints; ++i) {
    const double tol = 1e-9;
    if ((q(i) >= hi(i) - tol && g(i) > 0.0) || (q(i) <= lo(i) + tol && g(i) < 0.0)) blocked.push_back(i);
  }
  if (!blocked.empty()) {
    r.status = IkStatus::kJointLimits;
    m << ": stalled with";
    for (int i : blocked) {
      m << " joint " << (i + 1) << " (" << arm.config().joints[i].name << ") on its "
        << (q(i) >= hi(i) - 1e-9 ? "upper" : "lower") << " limit " << (q(i) >= hi(i) - 1e-9 ? hi(i) : lo(i)) << " rad;";
    }
    m << " the target needs them beyond";
  } else if (!stalled) {
    r.status = IkStatus::kMaxIterations;
    m << ": iteration budget " << config.max_iterations << " spent";
  } else {
    r.status = IkStatus::kUnreachable;
    m << ": stalled away from the target with every joint free (out of the dexterous workspace)";
  }
  r.message = m.str();
  return r;
}

/// Better of two failed attempts: the smaller residual.
bool better(const IkResult& a, const IkResult& b) {
  return a.position_residual_m + a.rotation_residual_rad < b.position_residual_m + b.rotation_residual_rad;
}

}  // namespace

std::string IkConfig::validate() const {
  std::ostringstream errors;
  auto check = [&errors](bool ok, const char* field, const std::string& range) {
    if (ok) return;
    if (errors.tellp() > 0) errors << "; ";
    errors << field << " must be in " << range;
  };
  check(position_tolerance_m > 0.0 && position_tolerance_m <= 0.1, "position_tolerance_m", "(0, 0.1]");
  check(rotation_tolerance_rad > 0.0 && rotation_tolerance_rad <= 0.1, "rotation_tolerance_rad", "(0, 0.1]");
  check(max_iterations >= 1 && max_iterations <= 100000, "max_iterations", "[1, 100000]");
  check(initial_damping > 0.0 && initial_damping <= 1e6, "initial_damping", "(0, 1e6]");
  check(restarts >= 0 && restarts <= 1000, "restarts", "[0, 1000]");
  check(max_restart_distance_rad >= 0.0 && max_restart_distance_rad <= 100.0, "max_restart_distance_rad", "[0, 100]");
  return errors.str();
}

std::string toString(IkStatus status) {
  switch (status) {
    case IkStatus::kConverged:
      return "converged";
    case IkStatus::kUnreachable:
      return "unreachable";
    case IkStatus::kJointLimits:
      return "joint limits";
    case IkStatus::kMaxIterations:
      return "max iterations";
  }
  return "unknown";
}

IkResult solveFlangeIk(const arm::ArmModel& arm, const Eigen::Isometry3d& target, const arm::JointVector& seed,
                       const IkConfig& config) {
  const std::string errors = config.validate();
  if (!errors.empty()) throw std::invalid_argument("IkConfig: " + errors);
  IkResult best;
  if (!seed.allFinite() || !target.matrix().allFinite()) {
    best.status = IkStatus::kUnreachable;
    best.message = "invalid input: the seed and the target must be finite";
    return best;
  }
  // Beyond the reach bound no joint angles can help: refuse before iterating.
  const double distance_m = (target.translation() - arm.shoulderPointM()).norm();
  if (distance_m > arm.reachBoundM()) {
    std::ostringstream m;
    m << "target flange position at " << distance_m << " m from the shoulder, beyond the arm's reach "
      << arm.reachBoundM() << " m";
    best.status = IkStatus::kUnreachable;
    best.message = m.str();
    best.q = arm.clampToLimits(seed);
    const Eigen::Isometry3d f = arm.forward(best.q);
    best.position_residual_m = (target.translation() - f.translation()).norm();
    best.rotation_residual_rad = rotationAngleRad(target.linear() * f.linear().transpose());
    return best;
  }
  const arm::JointVector q0 = arm.clampToLimits(seed);
  best = solveOnce(arm, target, q0, config);
  if (best.status == IkStatus::kConverged || config.restarts == 0) return best;

  // Restarts: deterministic seeds within the limits, nearest to the caller's seed first (keeps the configuration).
  std::mt19937 rng(config.restart_seed);
  std::vector<arm::JointVector> seeds;
  const arm::JointVector lo = arm.minLimits(), hi = arm.maxLimits();
  for (int k = 0; k < config.restarts; ++k) {
    arm::JointVector s;
    for (int i = 0; i < arm::kArmJoints; ++i) s(i) = std::uniform_real_distribution<double>(lo(i), hi(i))(rng);
    // Alternate full-range seeds with seeds near q0 (a local perturbation often suffices).
    if (k % 2 == 0) s = (q0 + 0.25 * (s - q0)).eval();
    seeds.push_back(s);
  }
  std::stable_sort(seeds.begin(), seeds.end(), [&q0](const arm::JointVector& a, const arm::JointVector& b) {
    return (a - q0).cwiseAbs().maxCoeff() < (b - q0).cwiseAbs().maxCoeff();
  });
  int iterations = best.iterations, attempts = 1;
  for (const arm::JointVector& s : seeds) {
    if (config.max_restart_distance_rad > 0.0 && (s - q0).cwiseAbs().maxCoeff() > config.max_restart_distance_rad) {
      continue;
    }
    IkResult r = solveOnce(arm, target, s, config);
    iterations += r.iterations;
    ++attempts;
    if (r.status == IkStatus::kConverged || better(r, best)) best = r;
    if (best.status == IkStatus::kConverged) break;
  }
  best.iterations = iterations;
  best.attempts = attempts;
  if (best.status != IkStatus::kConverged) best.message += " (best of " + std::to_string(attempts) + " attempts)";
  return best;
}

IkResult solveCameraIk(const arm::ArmModel& arm, const Eigen::Isometry3d& flange_T_camera,
                       const Eigen::Isometry3d& base_T_camera_target, const arm::JointVector& seed,
                       const IkConfig& config) {
  return solveFlangeIk(arm, base_T_camera_target * flange_T_camera.inverse(), seed, config);
}

std::vector<IkResult> planJointTargets(const arm::ArmModel& arm, const Eigen::Isometry3d& flange_T_camera,
                                       const std::vector<Eigen::Isometry3d>& base_T_camera_poses,
                                       const arm::JointVector& q0, const IkConfig& config) {
  std::vector<IkResult> results;
  results.reserve(base_T_camera_poses.size());
  arm::JointVector seed = q0;
  for (size_t i = 0; i < base_T_camera_poses.size(); ++i) {
    IkResult r = solveCameraIk(arm, flange_T_camera, base_T_camera_poses[i], seed, config);
    if (r.status == IkStatus::kConverged) {
      seed = r.q;
    } else {
      r.message = "pose " + std::to_string(i) + ": " + r.message;
    }
    results.push_back(r);
  }
  return results;
}

}  // namespace trajectory
}  // namespace exocet_servo
