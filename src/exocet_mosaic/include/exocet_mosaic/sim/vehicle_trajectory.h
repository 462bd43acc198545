/**
 * @file vehicle_trajectory.h
 * @brief Ground-truth motion of the vehicle: lawnmower survey, out-and-back line, or CSV waypoints.
 *
 * Positions are in the dive's local frame (x east, y north, metres) with z the height above the reference seabed
 * plane (the seabed's relief is added on top of that plane). Attitude is body (x forward, y left, z up) to world,
 * R = Rz(yaw) Ry(pitch) Rx(roll), yaw counter-clockwise from east (REP-103); the user-facing configuration uses
 * compass headings (clockwise from grid north), converted here once.
 */
#pragma once

#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace exocet_mosaic {
namespace sim {

/// The vehicle's true state at one instant.
struct VehicleState {
  double t_s = 0.0;  ///< seconds since the start of the dive
  Eigen::Vector3d position_m = Eigen::Vector3d::Zero();        ///< x east, y north, z above the reference plane
  Eigen::Vector3d velocity_mps = Eigen::Vector3d::Zero();      ///< world frame
  Eigen::Vector3d acceleration_mps2 = Eigen::Vector3d::Zero();  ///< world frame
  double roll_rad = 0.0, pitch_rad = 0.0, yaw_rad = 0.0;
  Eigen::Vector3d angular_velocity_rps = Eigen::Vector3d::Zero();  ///< body frame
  Eigen::Matrix3d rotation() const;  ///< body to world
};

/// Builds R = Rz(yaw) Ry(pitch) Rx(roll).
Eigen::Matrix3d rotationFromRpy(double roll_rad, double pitch_rad, double yaw_rad);
/// Inverse of rotationFromRpy (ZYX Euler angles).
Eigen::Vector3d rpyFromRotation(const Eigen::Matrix3d& R);

/// A waypoint of a user-supplied path (local metres; altitude and speed optional, <= 0 meaning "default").
struct Waypoint {
  double x_m = 0.0, y_m = 0.0;
  double altitude_m = -1.0;
  double speed_mps = -1.0;
};

/// Reads waypoints from a CSV with a header: x_m,y_m[,altitude_m][,speed_mps]. Throws naming the line on error.
std::vector<Waypoint> loadWaypointsCsv(const std::string& path);

struct TrajectoryConfig {
  enum class Kind { kLawnmower, kOutAndBack, kWaypoints };
  Kind kind = Kind::kLawnmower;
  double start_x_m = 0.0, start_y_m = 0.0;   ///< first point, local frame
  double heading_deg = 0.0;                  ///< compass heading of the first leg, clockwise from grid north
  double speed_mps = 0.5;                    ///< cruise speed over ground
  double acceleration_mps2 = 0.1;            ///< when starting and stopping
  double line_length_m = 20.0;               ///< lawnmower and out-and-back leg length
  double line_spacing_m = 2.0;               ///< lawnmower: distance between legs
  int line_count = 4;                        ///< lawnmower: number of legs
  bool turn_to_starboard = true;             ///< lawnmower: side of the first turn
  double turn_rate_deg_s = 15.0;             ///< turns in place (out-and-back, waypoints)
  double altitude_m = 2.5;                   ///< nominal altitude above the reference seabed plane
  double altitude_variation_m = 0.0;         ///< amplitude of slow altitude changes
  double altitude_period_s = 40.0;
  double roll_amplitude_deg = 0.0, roll_period_s = 7.0;
  double pitch_amplitude_deg = 0.0, pitch_period_s = 9.0;
  double yaw_oscillation_deg = 0.0, yaw_period_s = 12.0;  ///< heading wobble about the path direction
  std::vector<Waypoint> waypoints;           ///< kWaypoints

  /// "" if valid, otherwise every problem, naming the field and its allowed range.
  std::string validate() const;
};

/**
 * @brief A continuous, deterministic trajectory: a chain of straight legs (trapezoidal speed), arcs and turns in
 * place, with altitude, roll, pitch and heading oscillations superposed.
 */
class VehicleTrajectory {
 public:
  explicit VehicleTrajectory(const TrajectoryConfig& config);
  ~VehicleTrajectory();
  double duration_s() const { return duration_s_; }
  /// State at time t (clamped to [0, duration]); velocities and accelerations by central differences.
  VehicleState stateAt(double t_s) const;
  /// Horizontal path length (m).
  double pathLength_m() const { return path_length_m_; }
  const TrajectoryConfig& config() const { return config_; }

  struct Segment;

 private:
  struct Pose2D {
    Eigen::Vector2d xy;
    double yaw_rad;
    double altitude_m;
  };
  Pose2D pathPose(double t_s) const;
  VehicleState exactState(double t_s) const;

  TrajectoryConfig config_;
  std::vector<std::unique_ptr<Segment>> segments_;
  std::vector<double> segment_start_s_;
  double duration_s_ = 0.0;
  double path_length_m_ = 0.0;
};

}  // namespace sim
}  // namespace exocet_mosaic
