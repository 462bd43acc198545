/**
 * @file servo_simulation.h
 * @brief Point-level simulation of one intrinsics-free servoing (2D4 report 2.4): the reference image is taken by the
 * reference (right) camera at its pose, the current images by the controlled (left) camera whose pose integrates the
 * commanded camera velocity through the exponential map (as vpSimulatorCamera); gaussian pixel noise on every image.
 * Also the repeated servoing that walks the rig along the cylinder of screw_motion.h. No ROS in it.
 */
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "exocet_servo/control/invariant_servo.h"
#include "exocet_servo/sim/point_scene.h"

namespace exocet_servo {
namespace sim {

/// Which depths the servo's interaction matrix gets.
enum class DepthSource {
  kTrue,   ///< the exact depths
  kNoisy,  ///< the exact depths times (1 + N(0, depth_noise_fraction^2)), fixed per point (a rough triangulation)
  /// ServoConfig::default_depth_m for every point. It makes L_hat rank deficient: with equal depths the translations
  /// move the points like a change of principal point or focal length, which the invariant space removes; the servo
  /// stops with kDegenerate.
  kConstant,
};

/// Simulation parameters; validate() lists the allowed ranges.
struct ServoSimConfig {
  double noise_px = 0.5;  ///< standard deviation of the pixel noise on each coordinate, [0, 50]
  unsigned seed = 1;      ///< of the noise
  double dt_s = 1.0;      ///< integration period of the velocity, (0, 100]
  DepthSource depth_source = DepthSource::kTrue;
  double depth_noise_fraction = 0.1;  ///< for kNoisy, [0, 0.5]
  /// Drift of the object in the world (the vehicle moving under the arm), m/s; zero for a still scene.
  Eigen::Vector3d object_drift_m_per_s = Eigen::Vector3d::Zero();
  std::string validate() const;
};

/// Outcome of one simulated servoing.
struct ServoSimResult {
  control::ServoStatus status = control::ServoStatus::kInvalidInput;
  std::string message;
  int iterations = 0;                                            ///< control steps taken
  Eigen::Isometry3d final_pose = Eigen::Isometry3d::Identity();  ///< world_T_camera of the controlled camera
  PoseError final_error;                          ///< to the reference camera's pose (moved with the object drift)
  std::vector<double> error_norms;                ///< |e| per step
  std::vector<Eigen::Vector3d> camera_positions;  ///< controlled camera centre before each step, then the final one
};

/// Simulates one servoing of `controlled` from world_T_start to the pose world_T_reference where `reference` took the
/// reference image.
/// @param servo_config its image size is replaced by the controlled camera's.
/// @param k_estimate_reference, k_estimate_controlled the intrinsics the servo believes (for L_hat only).
/// @throws std::invalid_argument when a config is invalid.
ServoSimResult simulateServo(const std::vector<Eigen::Vector3d>& points_w, const PinholeCamera& reference,
                             const Eigen::Isometry3d& world_T_reference, const PinholeCamera& controlled,
                             const Eigen::Isometry3d& world_T_start, const control::ServoConfig& servo_config,
                             const ServoSimConfig& sim_config, const Eigen::Matrix3d& k_estimate_reference,
                             const Eigen::Matrix3d& k_estimate_controlled);

/// Repeated servoing on a stereo rig: at each round the right camera (`right`, at world_T_left * left_T_right) takes
/// the reference, then the left camera (`left`) servoes to it; the rig follows. The noise seed changes per round
/// (sim_config.seed + round).
/// @return the left camera poses after each round (first: world_T_left_start), and in `results` each servoing.
std::vector<Eigen::Isometry3d> simulateRepeatedServoing(const std::vector<Eigen::Vector3d>& points_w,
                                                        const PinholeCamera& left, const PinholeCamera& right,
                                                        const Eigen::Isometry3d& left_T_right,
                                                        const Eigen::Isometry3d& world_T_left_start, int rounds,
                                                        const control::ServoConfig& servo_config,
                                                        const ServoSimConfig& sim_config,
                                                        std::vector<ServoSimResult>* results = nullptr);

}  // namespace sim
}  // namespace exocet_servo
