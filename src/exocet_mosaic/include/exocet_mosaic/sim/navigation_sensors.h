/**
 * @file navigation_sensors.h
 * @brief Simulated navigation sensors of an ROV: gyro/attitude (IMU), DVL, dead reckoning, depth, altimeter, USBL.
 *
 * Each sensor's errors are configurable and statistically exact (the tests check each sigma over a long run).
 * Dead reckoning integrates the DVL velocity rotated by the gyro-integrated heading, so it drifts as at sea:
 * heading error from the gyro bias (constant part plus random walk), velocity scale factor and noise.
 */
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "exocet_mosaic/dive/dive_records.h"
#include "exocet_mosaic/sim/random.h"
#include "exocet_mosaic/sim/vehicle_trajectory.h"

namespace exocet_mosaic {
namespace sim {

struct NavigationSensorConfig {
  double imu_rate_hz = 50.0;           ///< IMU and dead-reckoning integration rate
  double gyro_noise_rps = 0.0005;      ///< white noise of each rate axis (rad/s)
  double gyro_bias_rps = 0.0002;       ///< 1-sigma of the initial (turn-on) bias of each axis (rad/s)
  double gyro_bias_walk_rps_sqrt_s = 2e-5;  ///< bias random walk (rad/s per sqrt(s))
  double attitude_noise_rad = 0.002;   ///< roll and pitch white noise (gravity-referenced, no drift)
  double accel_noise_mps2 = 0.01;      ///< accelerometer white noise
  double dvl_rate_hz = 5.0;
  double dvl_noise_mps = 0.01;         ///< white noise of each velocity axis
  double dvl_scale_error = 0.003;      ///< 1-sigma of the velocity scale factor error (dimensionless)
  double nav_rate_hz = 10.0;           ///< dead-reckoning output rate
  double dr_sigma_per_m = 0.01;        ///< reported position sigma growth per metre travelled (for the covariance)
  double dr_launch_sigma_m = 0.01;     ///< 1-sigma of the launch point's horizontal error, each axis (DR start)
  /// 1-sigma of the heading's error at launch (rad): the attitude sensor's alignment, shared by the DR and the images.
  double heading_alignment_sigma_rad = 0.0;
  double depth_rate_hz = 10.0;
  double depth_noise_m = 0.02;
  double altimeter_rate_hz = 10.0;
  double altimeter_noise_m = 0.02;
  double altimeter_max_range_m = 30.0;
  double usbl_rate_hz = 1.0;
  double usbl_noise_m = 0.5;           ///< horizontal 1-sigma, each axis
  double usbl_vertical_noise_m = 0.3;
  double usbl_latency_s = 1.5;         ///< measurement to arrival at the surface computer
  double usbl_outlier_probability = 0.0;  ///< probability that a fix is an outlier (multipath)
  double usbl_outlier_scale = 10.0;    ///< outlier error magnitude, in usbl_noise_m
  std::vector<std::pair<double, double>> usbl_dropouts_s;  ///< [start, end) intervals without fixes

  /// "" if valid, otherwise each problem naming the field (navigation.<name>) and its allowed range.
  std::string validate() const;
};

/// Callbacks receiving each measurement as it is produced, in time order of measurement.
struct NavigationSinks {
  std::function<void(const dive::ImuRecord&)> imu;
  std::function<void(const dive::DvlRecord&)> dvl;
  std::function<void(const dive::PoseRecord&)> dead_reckoning;
  std::function<void(const dive::DepthRecord&)> depth;
  std::function<void(const dive::AltitudeRecord&)> altitude;
  std::function<void(const dive::FixRecord&)> usbl;
};

/**
 * @brief Steps the sensors along a trajectory. The world frame of the records it emits is the UTM grid of `geo`
 * (E = origin_easting + x, N = origin_northing + y, up = z - seabed_depth_m).
 */
class NavigationSensorSimulator {
 public:
  /// `seabed_height` gives the relief above the reference plane at (x, y) for the altimeter (may be empty: flat).
  NavigationSensorSimulator(const NavigationSensorConfig& config, const exocet_common::GeoReference& geo, double seabed_depth_m,
                            double start_time_unix_s, uint64_t seed,
                            std::function<double(double, double)> seabed_height = {});

  /// Advances to dive time t_s (seconds from the start), emitting every measurement due on the way.
  void advanceTo(const VehicleTrajectory& trajectory, double t_s, const NavigationSinks& sinks);

  /// Converts a true state to the world (UTM) pose record used for ground truth.
  dive::PoseRecord groundTruth(const VehicleState& state) const;
  /// Current gyro bias (rad/s, body axes): for tests.
  const Eigen::Vector3d& gyroBias() const { return gyro_bias_; }
  /// Current heading error of the dead reckoning (rad): for tests.
  double headingError_rad() const { return heading_error_rad_; }

 private:
  void stepImu(const VehicleTrajectory& trajectory, double t_s, const NavigationSinks& sinks);
  double trueAltitude(const VehicleState& s) const;
  Eigen::Vector3d toWorld(const Eigen::Vector3d& local) const;

  NavigationSensorConfig config_;
  exocet_common::GeoReference geo_;
  double seabed_depth_m_;
  double t0_unix_s_;
  std::function<double(double, double)> seabed_height_;
  RandomStream rng_imu_, rng_dvl_, rng_depth_, rng_alt_, rng_usbl_;
  Eigen::Vector3d gyro_bias_ = Eigen::Vector3d::Zero();
  double dvl_scale_ = 1.0;
  Eigen::Vector2d launch_error_m_ = Eigen::Vector2d::Zero();  ///< where the DR starts, relative to the truth
  double heading_error_rad_ = 0.0;
  Eigen::Vector3d dr_position_local_ = Eigen::Vector3d::Zero();
  Eigen::Vector3d dvl_measured_ = Eigen::Vector3d::Zero();
  /// The dead reckoning's velocity (world): the last DVL velocity carried forward with the accelerometers between
  /// pings, as a DVL-aided INS does (holding the last ping would lag by half a DVL period whenever the speed changes).
  Eigen::Vector3d dr_velocity_world_ = Eigen::Vector3d::Zero();
  double dr_distance_m_ = 0.0;
  double last_depth_m_ = 0.0;
  long imu_ticks_ = -1;  ///< index of the last IMU tick processed
  double next_dvl_s_ = 0.0, next_nav_s_ = 0.0, next_depth_s_ = 0.0, next_alt_s_ = 0.0, next_usbl_s_ = 0.0;
  bool initialised_ = false;
};

}  // namespace sim
}  // namespace exocet_mosaic
