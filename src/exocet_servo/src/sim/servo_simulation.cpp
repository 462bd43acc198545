#include "exocet_servo/sim/servo_simulation.h"

#include <algorithm>
#include <random>
#include <sstream>
#include <stdexcept>

#include "exocet_servo/trajectory/se3.h"

namespace exocet_servo {
namespace sim {

std::string ServoSimConfig::validate() const {
  std::ostringstream errors;
  auto check = [&errors](bool ok, const char* field, const std::string& range) {
    if (ok) return;
    if (errors.tellp() > 0) errors << "; ";
    errors << field << " must be in " << range;
  };
  check(noise_px >= 0.0 && noise_px <= 50.0, "noise_px", "[0, 50]");
  check(dt_s > 0.0 && dt_s <= 100.0, "dt_s", "(0, 100]");
  check(depth_noise_fraction >= 0.0 && depth_noise_fraction <= 0.5, "depth_noise_fraction", "[0, 0.5]");
  check(object_drift_m_per_s.allFinite() && object_drift_m_per_s.norm() <= 10.0, "object_drift_m_per_s",
        "finite vectors of norm [0, 10]");
  return errors.str();
}

ServoSimResult simulateServo(const std::vector<Eigen::Vector3d>& points_w, const PinholeCamera& reference,
                             const Eigen::Isometry3d& world_T_reference, const PinholeCamera& controlled,
                             const Eigen::Isometry3d& world_T_start, const control::ServoConfig& servo_config,
                             const ServoSimConfig& sim, const Eigen::Matrix3d& k_estimate_reference,
                             const Eigen::Matrix3d& k_estimate_controlled) {
  const std::string errors = sim.validate();
  if (!errors.empty()) throw std::invalid_argument("ServoSimConfig: " + errors);
  control::ServoConfig config = servo_config;
  config.image_width_px = controlled.width_px;
  config.image_height_px = controlled.height_px;
  control::InvariantServo servo(config);

  std::mt19937 rng(sim.seed);
  ServoSimResult result;
  // Relative depth errors, one per point and per camera, fixed over the servoing (a triangulation bias).
  std::normal_distribution<double> depth_noise(0.0, 1.0);
  std::vector<double> ref_depth_factor(points_w.size(), 1.0), cur_depth_factor(points_w.size(), 1.0);
  if (sim.depth_source == DepthSource::kNoisy) {
    for (auto& f : ref_depth_factor) f = std::max(0.1, 1.0 + sim.depth_noise_fraction * depth_noise(rng));
    for (auto& f : cur_depth_factor) f = std::max(0.1, 1.0 + sim.depth_noise_fraction * depth_noise(rng));
  }
  auto depths = [&sim](const Projection& p, const std::vector<double>& factor) {
    if (sim.depth_source == DepthSource::kConstant) return std::vector<double>{};
    std::vector<double> d = p.depths_m;
    for (size_t i = 0; i < d.size(); ++i) d[i] *= factor[i];
    return d;
  };
  const Projection ref = project(reference, world_T_reference, points_w, sim.noise_px, &rng);
  std::string err = servo.setReference(ref.points_px, k_estimate_reference, depths(ref, ref_depth_factor));
  if (!err.empty()) {
    result.message = err;
    return result;
  }
  Eigen::Isometry3d pose = world_T_start;
  std::vector<Eigen::Vector3d> moved = points_w;
  Eigen::Vector3d drift = Eigen::Vector3d::Zero();
  while (true) {
    result.camera_positions.push_back(pose.translation());
    const Projection cur = project(controlled, pose, moved, sim.noise_px, &rng);
    const control::ServoStep step = servo.step(cur.points_px, k_estimate_controlled, depths(cur, cur_depth_factor));
    result.iterations = step.iteration;
    result.error_norms.push_back(step.error_norm);
    if (step.status != control::ServoStatus::kRunning) {
      result.status = step.status;
      result.message = step.message;
      break;
    }
    pose = pose * trajectory::expSe3(step.velocity * sim.dt_s);
    if (!sim.object_drift_m_per_s.isZero()) {
      const Eigen::Vector3d d = sim.object_drift_m_per_s * sim.dt_s;
      drift += d;
      for (auto& p : moved) p += d;
    }
  }
  result.final_pose = pose;
  result.camera_positions.push_back(pose.translation());
  Eigen::Isometry3d target = world_T_reference;
  target.translation() += drift;
  result.final_error = poseError(pose, target);
  return result;
}

std::vector<Eigen::Isometry3d> simulateRepeatedServoing(
    const std::vector<Eigen::Vector3d>& points_w, const PinholeCamera& left, const PinholeCamera& right,
    const Eigen::Isometry3d& left_T_right, const Eigen::Isometry3d& world_T_left_start, int rounds,
    const control::ServoConfig& servo_config, const ServoSimConfig& sim_config, std::vector<ServoSimResult>* results) {
  std::vector<Eigen::Isometry3d> poses{world_T_left_start};
  for (int r = 0; r < rounds; ++r) {
    ServoSimConfig sim = sim_config;
    sim.seed = sim_config.seed + static_cast<unsigned>(r);
    const Eigen::Isometry3d world_T_right = poses.back() * left_T_right;
    const ServoSimResult res =
        simulateServo(points_w, right, world_T_right, left, poses.back(), servo_config, sim, right.k, left.k);
    poses.push_back(res.final_pose);
    if (results != nullptr) results->push_back(res);
  }
  return poses;
}

}  // namespace sim
}  // namespace exocet_servo
