#include "exocet_servo/trajectory/acquisition_feasibility.h"

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <sstream>
#include <stdexcept>

#include <Eigen/SVD>

#include "exocet_servo/trajectory/acquisition_planner.h"
#include "exocet_servo/trajectory/screw_motion.h"
#include "exocet_servo/trajectory/se3.h"

namespace exocet_servo {
namespace trajectory {

namespace {

/// Appends "field must be in range" to a "; "-joined list when !ok.
void check(std::ostringstream& errors, bool ok, const std::string& field, const std::string& range) {
  if (ok) return;
  if (errors.tellp() > 0) errors << "; ";
  errors << field << " must be in " << range;
}

std::string jointLabel(const arm::ArmModel& arm, int i) {
  return "joint " + std::to_string(i + 1) + " (" + arm.config().joints[i].name + ")";
}

/// Where a checked pose lies, for messages: "pose 3 of 6" or "step 3 (pose 2 -> 3) at 40%".
std::string whereLabel(const PoseFeasibility& p, int pose_count) {
  std::ostringstream s;
  if (p.step == 0) {
    s << "pose 0 (the start, of " << pose_count << " poses)";
  } else if (p.fraction >= 1.0) {
    s << "pose " << p.step << " (end of step " << p.step << ", of " << pose_count << " poses)";
  } else {
    s << "step " << p.step << " (pose " << p.step - 1 << " -> " << p.step << ") at " << std::setprecision(3)
      << 100.0 * p.fraction << "%";
  }
  return s.str();
}

/// Fills margin, sigma and the verdict of a solved pose.
void assess(const arm::ArmModel& arm, const FeasibilityConfig& config, const arm::JointVector* previous_q,
            PoseFeasibility* p) {
  const arm::JointVector lo = arm.minLimits(), hi = arm.maxLimits();
  p->joint_margin_rad = 1e9;
  for (int i = 0; i < arm::kArmJoints; ++i) {
    const double m = std::min(p->q(i) - lo(i), hi(i) - p->q(i));
    if (m < p->joint_margin_rad) {
      p->joint_margin_rad = m;
      p->margin_joint = i;
    }
  }
  const Eigen::JacobiSVD<Eigen::Matrix<double, 6, 6>> svd(arm.jacobianBase(p->q), Eigen::ComputeFullV);
  p->sigma_min = svd.singularValues()(arm::kArmJoints - 1);
  p->joint_step_rad = previous_q != nullptr ? (p->q - *previous_q).cwiseAbs().maxCoeff() : 0.0;
  if (!p->reachable) {
    p->verdict = PoseVerdict::kUnreachable;
    return;
  }
  std::ostringstream m;
  m << std::setprecision(4);
  if (p->joint_step_rad > config.max_joint_step_rad) {
    int j = 0;
    (p->q - *previous_q).cwiseAbs().maxCoeff(&j);
    p->verdict = PoseVerdict::kBranchJump;
    m << "branch jump: " << jointLabel(arm, j) << " changes by " << p->joint_step_rad
      << " rad from the previous pose, more than max_joint_step_rad " << config.max_joint_step_rad
      << " rad (no continuous motion on one branch)";
  } else if (p->joint_margin_rad < config.min_joint_margin_rad) {
    const int j = p->margin_joint;
    p->verdict = PoseVerdict::kJointMargin;
    m << jointLabel(arm, j) << " at " << p->q(j) << " rad, " << p->joint_margin_rad << " rad from its limits [" << lo(j)
      << ", " << hi(j) << "], less than min_joint_margin_rad " << config.min_joint_margin_rad;
  } else if (p->sigma_min < config.min_sigma) {
    // The right singular vector of sigma_min says which joints lose a direction (4 and 6 aligned: the wrist).
    const Eigen::Matrix<double, 6, 1> v = svd.matrixV().col(arm::kArmJoints - 1).cwiseAbs();
    int a = 0, b = 0;
    v.maxCoeff(&a);
    Eigen::Matrix<double, 6, 1> rest = v;
    rest(a) = -1.0;
    rest.maxCoeff(&b);
    p->verdict = PoseVerdict::kSingular;
    m << "smallest singular value of the Jacobian " << p->sigma_min << " < min_sigma " << config.min_sigma
      << " (singular direction mostly joints " << std::min(a, b) + 1 << " and " << std::max(a, b) + 1
      << "; wrist pitch q5 = " << p->q(4) << " rad)";
  } else {
    p->verdict = PoseVerdict::kOk;
    return;
  }
  p->message = m.str();
}

}  // namespace

std::string FeasibilityConfig::validate() const {
  std::ostringstream e;
  check(e, samples_per_step >= 1 && samples_per_step <= 1000, "samples_per_step", "[1, 1000]");
  check(e, min_sigma > 0.0 && min_sigma <= 10.0, "min_sigma", "(0, 10]");
  check(e, min_joint_margin_rad >= 0.0 && min_joint_margin_rad <= M_PI, "min_joint_margin_rad", "[0, pi]");
  check(e, max_joint_step_rad > 0.0 && max_joint_step_rad <= 2.0 * M_PI, "max_joint_step_rad", "(0, 2 pi]");
  const std::string ik_errors = ik.validate();
  if (!ik_errors.empty()) check(e, false, "ik (" + ik_errors + ")", "IkConfig's ranges");
  return e.str();
}

std::string toString(PoseVerdict verdict) {
  switch (verdict) {
    case PoseVerdict::kOk:
      return "ok";
    case PoseVerdict::kUnreachable:
      return "unreachable";
    case PoseVerdict::kBranchJump:
      return "branch jump";
    case PoseVerdict::kJointMargin:
      return "joint margin";
    case PoseVerdict::kSingular:
      return "singular";
  }
  return "unknown";
}

std::vector<Eigen::Isometry3d> repeatedServoingPoses(const Eigen::Isometry3d& base_T_left_0,
                                                     const Eigen::Isometry3d& left_T_right, int servoings) {
  std::vector<Eigen::Isometry3d> poses;
  for (const Eigen::Isometry3d& t : composedPowers(left_T_right, std::max(0, servoings))) {
    poses.push_back(base_T_left_0 * t);
  }
  return poses;
}

FeasibilityReport checkFeasibility(const arm::ArmModel& arm, const Eigen::Isometry3d& flange_T_camera,
                                   const std::vector<Eigen::Isometry3d>& poses, const arm::JointVector& seed,
                                   const FeasibilityConfig& config) {
  const std::string errors = config.validate();
  if (!errors.empty()) throw std::invalid_argument("FeasibilityConfig: " + errors);
  FeasibilityReport report;
  if (poses.empty()) {
    report.reason = "no pose to check";
    return report;
  }
  report.steps = static_cast<int>(poses.size()) - 1;
  const int pose_count = static_cast<int>(poses.size());
  // Along the path: one branch, so restarts only near the previous solution.
  IkConfig path_ik = config.ik;
  path_ik.max_restart_distance_rad = config.max_joint_step_rad;

  arm::JointVector q_prev = seed;
  bool have_prev = false;  // q_prev is a solved pose (else the seed)
  int failing_step = -1;
  auto add = [&](int step, double fraction, const Eigen::Isometry3d& target) {
    PoseFeasibility p;
    p.step = step;
    p.fraction = fraction;
    p.base_T_camera = target;
    const IkResult r = solveCameraIk(arm, flange_T_camera, target, q_prev, have_prev ? path_ik : config.ik);
    p.ik_status = r.status;
    p.reachable = r.status == IkStatus::kConverged;
    p.q = r.q;
    assess(arm, config, have_prev ? &q_prev : nullptr, &p);
    if (!p.reachable) {
      std::ostringstream m;
      m << "inverse kinematics " << toString(r.status) << ": " << r.message;
      // Stalled in a singular configuration: the path left the workspace through its boundary (arm stretched).
      if (p.sigma_min < config.min_sigma) {
        m << "; the solver stalled where the smallest singular value is " << std::setprecision(3) << p.sigma_min
          << " (workspace boundary)";
      }
      p.message = m.str();
    }
    if (p.verdict != PoseVerdict::kOk) p.message = whereLabel(p, pose_count) + ": " + p.message;
    if (p.reachable) {
      q_prev = p.q;
      have_prev = true;
    }
    const int index = static_cast<int>(report.poses.size());
    // The worst figures describe the motion the arm can actually make: up to the first failing pose.
    if (p.reachable && report.first_failing < 0) {
      if (report.worst_sigma_index < 0 || p.sigma_min < report.worst_sigma_min) {
        report.worst_sigma_min = p.sigma_min;
        report.worst_sigma_index = index;
      }
      if (report.worst_margin_index < 0 || p.joint_margin_rad < report.worst_joint_margin_rad) {
        report.worst_joint_margin_rad = p.joint_margin_rad;
        report.worst_margin_index = index;
        report.worst_margin_joint = p.margin_joint;
      }
    }
    if (p.verdict != PoseVerdict::kOk && report.first_failing < 0) {
      report.first_failing = index;
      report.reason = p.message;
      failing_step = step;
    }
    report.poses.push_back(p);
    return p.verdict == PoseVerdict::kOk;
  };

  bool ok = add(0, 1.0, poses[0]);
  for (int k = 1; k < pose_count && (ok || !config.stop_at_first_failure); ++k) {
    // The geodesic from pose k - 1 to pose k in the moving frame: for a repeated rig transform, its screw T^s.
    const Twist xi = logSe3(poses[k - 1].inverse() * poses[k]);
    for (int s = 1; s <= config.samples_per_step && (ok || !config.stop_at_first_failure); ++s) {
      const double fraction = static_cast<double>(s) / config.samples_per_step;
      const Eigen::Isometry3d target = s == config.samples_per_step ? poses[k] : poses[k - 1] * expSe3(fraction * xi);
      ok = add(k, fraction, target) && ok;
    }
  }
  report.feasible =
      report.first_failing < 0 && static_cast<int>(report.poses.size()) == 1 + report.steps * config.samples_per_step;
  // A failure at the first pose leaves no step; a failure on step k leaves k - 1 complete steps.
  report.feasible_steps = report.feasible ? report.steps : std::max(0, failing_step - 1);
  return report;
}

std::string PlacementSearchConfig::validate() const {
  std::ostringstream e;
  check(e, servoings >= 1 && servoings <= 100, "servoings", "[1, 100]");
  auto bound = [](double v) { return std::isfinite(v) && std::abs(v) <= 10.0; };
  check(e, bound(x_min_m) && bound(x_max_m) && x_min_m <= x_max_m, "x_min_m, x_max_m", "[-10, 10] with min <= max");
  check(e, bound(y_min_m) && bound(y_max_m) && y_min_m <= y_max_m, "y_min_m, y_max_m", "[-10, 10] with min <= max");
  check(e, step_m >= 0.01 && step_m <= 5.0, "step_m", "[0.01, 5]");
  check(e, !base_z_m.empty() && std::all_of(base_z_m.begin(), base_z_m.end(), bound), "base_z_m",
        "at least one value, each in [-10, 10]");
  check(e, min_axis_distance_m >= 0.0 && min_axis_distance_m <= 10.0, "min_axis_distance_m", "[0, 10]");
  check(e, azimuth_samples >= 1 && azimuth_samples <= 3600, "azimuth_samples", "[1, 3600]");
  check(e, bound(camera_height_m), "camera_height_m", "[-10, 10]");
  const std::string f = feasibility.validate();
  if (!f.empty()) check(e, false, "feasibility (" + f + ")", "FeasibilityConfig's ranges");
  return e.str();
}

PlacementResult searchPlacement(const arm::ArmModel& arm, const Eigen::Isometry3d& flange_T_camera,
                                const Eigen::Isometry3d& left_T_right, const arm::JointVector& q_reference,
                                const PlacementSearchConfig& config) {
  const std::string errors = config.validate();
  if (!errors.empty()) throw std::invalid_argument("PlacementSearchConfig: " + errors);
  PlacementResult best;
  const ScrewMotion screw = screwFromTransform(left_T_right);
  // The camera upright (its y axis, down in the image, along world -z) when the screw axis is the world vertical.
  const Eigen::Vector3d axis_w = screw.axis.dot(Eigen::Vector3d::UnitY()) <= 0.0
                                     ? Eigen::Vector3d::UnitZ()
                                     : Eigen::Vector3d(-Eigen::Vector3d::UnitZ());
  const Eigen::Vector3d reference_camera = (arm.forward(q_reference) * flange_T_camera).translation();
  const double reference_bearing = std::atan2(reference_camera.y(), reference_camera.x());
  const Eigen::Isometry3d camera_T_flange = flange_T_camera.inverse();
  const int nx = static_cast<int>(std::floor((config.x_max_m - config.x_min_m) / config.step_m + 1e-9)) + 1;
  const int ny = static_cast<int>(std::floor((config.y_max_m - config.y_min_m) / config.step_m + 1e-9)) + 1;

  for (double z : config.base_z_m) {
    for (int ix = 0; ix < nx; ++ix) {
      for (int iy = 0; iy < ny; ++iy) {
        const Eigen::Vector3d axis_base(config.x_min_m + ix * config.step_m, config.y_min_m + iy * config.step_m, z);
        if (axis_base.head<2>().norm() < config.min_axis_distance_m) continue;
        for (int ia = 0; ia < config.azimuth_samples; ++ia) {
          ++best.candidates;
          const double azimuth = 2.0 * M_PI * ia / config.azimuth_samples;
          const Eigen::Isometry3d start =
              alignScrewWithAxis(screw, axis_base, axis_w, azimuth, config.camera_height_m * axis_w.z());
          const std::vector<Eigen::Isometry3d> poses = repeatedServoingPoses(start, left_T_right, config.servoings);
          // Cheap refusal first: a stop whose flange is beyond the reach bound.
          bool within = true;
          for (const Eigen::Isometry3d& p : poses) {
            within = within && ((p * camera_T_flange).translation() - arm.shoulderPointM()).norm() <= arm.reachBoundM();
          }
          if (!within) continue;
          ++best.solved_candidates;
          // The arm is symmetric about joint 1: turning the reference by the camera's bearing change keeps its
          // elbow and wrist configuration as the seed of the first pose.
          arm::JointVector seed = q_reference;
          const double bearing = std::atan2(start.translation().y(), start.translation().x());
          seed(0) = std::remainder(q_reference(0) + bearing - reference_bearing, 2.0 * M_PI);
          seed = arm.clampToLimits(seed);
          FeasibilityReport r = checkFeasibility(arm, flange_T_camera, poses, seed, config.feasibility);
          if (!r.feasible) continue;
          ++best.feasible_candidates;
          const bool better = !best.found || r.worst_sigma_min > best.report.worst_sigma_min + 1e-6 ||
                              (r.worst_sigma_min > best.report.worst_sigma_min - 1e-6 &&
                               r.worst_joint_margin_rad > best.report.worst_joint_margin_rad);
          if (!better) continue;
          best.found = true;
          best.axis_base_m = axis_base;
          best.start_azimuth_rad = azimuth;
          best.base_T_left_start = start;
          best.q_start = r.poses.front().q;
          best.report = std::move(r);
        }
      }
    }
  }
  std::ostringstream m;
  m << std::setprecision(4);
  if (best.found) {
    m << "axis base at (" << best.axis_base_m.transpose() << ") m, start azimuth "
      << best.start_azimuth_rad * 180.0 / M_PI << " deg: " << config.servoings
      << " servoings feasible, worst smallest singular value " << best.report.worst_sigma_min << ", worst joint margin "
      << best.report.worst_joint_margin_rad << " rad (" << best.feasible_candidates << " feasible of "
      << best.candidates << " candidates, " << best.solved_candidates << " solved)";
  } else {
    m << "no placement on the grid makes " << config.servoings << " servoings feasible (" << best.candidates
      << " candidates, " << best.solved_candidates << " within reach of every stop)";
  }
  best.message = m.str();
  return best;
}

}  // namespace trajectory
}  // namespace exocet_servo
