#include "exocet_mosaic/sim/navigation_sensors.h"

#include <cmath>
#include <sstream>
#include <stdexcept>

#include "exocet_common/geo_reference.h"

namespace exocet_mosaic {
namespace sim {

namespace {
constexpr double kGravity_mps2 = 9.80665;

void checkRange(std::ostringstream& err, const char* field, double v, double lo, double hi, const char* unit) {
  if (!std::isfinite(v) || v < lo || v > hi)
    err << "navigation." << field << " = " << v << " out of range [" << lo << ", " << hi << "] " << unit << "; ";
}

/// Number of periods of `rate_hz` elapsed at t (with a tolerance for rounding of tick times).
long dueCount(double t_s, double rate_hz) { return static_cast<long>(std::floor(t_s * rate_hz + 1e-6)); }
}  // namespace

std::string NavigationSensorConfig::validate() const {
  std::ostringstream err;
  checkRange(err, "imu_rate_hz", imu_rate_hz, 1.0, 1000.0, "Hz");
  checkRange(err, "gyro_noise_rps", gyro_noise_rps, 0.0, 0.1, "rad/s");
  checkRange(err, "gyro_bias_rps", gyro_bias_rps, 0.0, 0.1, "rad/s");
  checkRange(err, "gyro_bias_walk_rps_sqrt_s", gyro_bias_walk_rps_sqrt_s, 0.0, 0.01, "rad/s/sqrt(s)");
  checkRange(err, "attitude_noise_rad", attitude_noise_rad, 0.0, 0.2, "rad");
  checkRange(err, "accel_noise_mps2", accel_noise_mps2, 0.0, 5.0, "m/s^2");
  checkRange(err, "dvl_rate_hz", dvl_rate_hz, 0.1, imu_rate_hz, "Hz (at most imu_rate_hz)");
  checkRange(err, "dvl_noise_mps", dvl_noise_mps, 0.0, 1.0, "m/s");
  checkRange(err, "dvl_scale_error", dvl_scale_error, 0.0, 0.2, "");
  checkRange(err, "nav_rate_hz", nav_rate_hz, 0.1, imu_rate_hz, "Hz (at most imu_rate_hz)");
  checkRange(err, "dr_sigma_per_m", dr_sigma_per_m, 0.0, 1.0, "m/m");
  checkRange(err, "dr_launch_sigma_m", dr_launch_sigma_m, 0.0, 100.0, "m");
  checkRange(err, "heading_alignment_sigma_rad", heading_alignment_sigma_rad, 0.0, 0.5, "rad");
  checkRange(err, "depth_rate_hz", depth_rate_hz, 0.1, imu_rate_hz, "Hz (at most imu_rate_hz)");
  checkRange(err, "depth_noise_m", depth_noise_m, 0.0, 10.0, "m");
  checkRange(err, "altimeter_rate_hz", altimeter_rate_hz, 0.1, imu_rate_hz, "Hz (at most imu_rate_hz)");
  checkRange(err, "altimeter_noise_m", altimeter_noise_m, 0.0, 10.0, "m");
  checkRange(err, "altimeter_max_range_m", altimeter_max_range_m, 1.0, 1000.0, "m");
  checkRange(err, "usbl_rate_hz", usbl_rate_hz, 0.01, imu_rate_hz, "Hz (at most imu_rate_hz)");
  checkRange(err, "usbl_noise_m", usbl_noise_m, 0.0, 100.0, "m");
  checkRange(err, "usbl_vertical_noise_m", usbl_vertical_noise_m, 0.0, 100.0, "m");
  checkRange(err, "usbl_latency_s", usbl_latency_s, 0.0, 60.0, "s");
  checkRange(err, "usbl_outlier_probability", usbl_outlier_probability, 0.0, 0.5, "");
  checkRange(err, "usbl_outlier_scale", usbl_outlier_scale, 1.0, 1000.0, "x usbl_noise_m");
  for (const auto& d : usbl_dropouts_s)
    if (!(d.second > d.first) || !std::isfinite(d.first) || !std::isfinite(d.second))
      err << "navigation.usbl_dropouts_s: interval [" << d.first << ", " << d.second << ") must have end > start; ";
  std::string s = err.str();
  if (!s.empty()) s.resize(s.size() - 2);
  return s;
}

NavigationSensorSimulator::NavigationSensorSimulator(const NavigationSensorConfig& config, const exocet_common::GeoReference& geo,
                                                     double seabed_depth_m, double start_time_unix_s, uint64_t seed,
                                                     std::function<double(double, double)> seabed_height)
    : config_(config),
      geo_(geo),
      seabed_depth_m_(seabed_depth_m),
      t0_unix_s_(start_time_unix_s),
      seabed_height_(std::move(seabed_height)),
      rng_imu_(seed, 101),
      rng_dvl_(seed, 102),
      rng_depth_(seed, 103),
      rng_alt_(seed, 104),
      rng_usbl_(seed, 105) {
  const std::string problem = config_.validate();
  if (!problem.empty()) throw std::invalid_argument(problem);
  RandomStream init(seed, 100);
  gyro_bias_ = Eigen::Vector3d(init.gaussian(config_.gyro_bias_rps), init.gaussian(config_.gyro_bias_rps),
                               init.gaussian(config_.gyro_bias_rps));
  dvl_scale_ = 1.0 + init.gaussian(config_.dvl_scale_error);
  launch_error_m_ = Eigen::Vector2d(init.gaussian(config_.dr_launch_sigma_m), init.gaussian(config_.dr_launch_sigma_m));
  heading_error_rad_ = init.gaussian(config_.heading_alignment_sigma_rad);
}

Eigen::Vector3d NavigationSensorSimulator::toWorld(const Eigen::Vector3d& local) const {
  return {geo_.origin_easting_m + local.x(), geo_.origin_northing_m + local.y(), local.z() - seabed_depth_m_};
}

dive::PoseRecord NavigationSensorSimulator::groundTruth(const VehicleState& s) const {
  dive::PoseRecord p;
  p.stamp_s = t0_unix_s_ + s.t_s;
  p.position_m = toWorld(s.position_m);
  const Eigen::Matrix3d R = s.rotation();
  p.orientation = Eigen::Quaterniond(R);
  p.linear_velocity_mps = R.transpose() * s.velocity_mps;
  p.angular_velocity_rps = s.angular_velocity_rps;
  return p;
}

double NavigationSensorSimulator::trueAltitude(const VehicleState& s) const {
  const Eigen::Vector3d dir = -s.rotation().col(2);  // the altimeter looks along the body's -z axis
  if (dir.z() > -0.1) return config_.altimeter_max_range_m;
  double t = s.position_m.z() / -dir.z();
  if (seabed_height_) {
    // Fixed-point iteration on the intersection with the relief; contracts for the slopes the relief allows.
    for (int i = 0; i < 50; ++i) {
      const Eigen::Vector3d p = s.position_m + t * dir;
      const double t_next = (s.position_m.z() - seabed_height_(p.x(), p.y())) / -dir.z();
      if (std::abs(t_next - t) < 1e-7) {
        t = t_next;
        break;
      }
      t = t_next;
    }
  }
  return t;
}

void NavigationSensorSimulator::advanceTo(const VehicleTrajectory& trajectory, double t_s, const NavigationSinks& sinks) {
  const long last_tick = static_cast<long>(std::floor(t_s * config_.imu_rate_hz + 1e-9));
  while (imu_ticks_ < last_tick) {
    ++imu_ticks_;
    stepImu(trajectory, imu_ticks_ / config_.imu_rate_hz, sinks);
  }
}

void NavigationSensorSimulator::stepImu(const VehicleTrajectory& trajectory, double tau, const NavigationSinks& sinks) {
  const double dt = 1.0 / config_.imu_rate_hz;
  const VehicleState s = trajectory.stateAt(tau);
  const double stamp = t0_unix_s_ + tau;
  const Eigen::Matrix3d R = s.rotation();
  if (!initialised_) {
    // Dead reckoning starts from the launch point, known to dr_launch_sigma_m (its reported covariance says so).
    dr_position_local_ = s.position_m;
    dr_position_local_.head<2>() += launch_error_m_;
    dvl_measured_ = R.transpose() * s.velocity_mps;
    dr_velocity_world_ = s.velocity_mps;
    initialised_ = true;
  } else {
    for (int i = 0; i < 3; ++i) gyro_bias_[i] += rng_imu_.gaussian(config_.gyro_bias_walk_rps_sqrt_s * std::sqrt(dt));
  }

  // Gyro and the heading its integration gives: the rate error maps to a yaw error rate through the attitude.
  Eigen::Vector3d gyro_noise(rng_imu_.gaussian(config_.gyro_noise_rps), rng_imu_.gaussian(config_.gyro_noise_rps),
                             rng_imu_.gaussian(config_.gyro_noise_rps));
  const Eigen::Vector3d rate_error = gyro_bias_ + gyro_noise;
  const Eigen::Vector3d measured_rate = s.angular_velocity_rps + rate_error;
  const double yaw_error_rate =
      (std::sin(s.roll_rad) * rate_error.y() + std::cos(s.roll_rad) * rate_error.z()) / std::cos(s.pitch_rad);
  heading_error_rad_ += yaw_error_rate * dt;
  const double roll_m = s.roll_rad + rng_imu_.gaussian(config_.attitude_noise_rad);
  const double pitch_m = s.pitch_rad + rng_imu_.gaussian(config_.attitude_noise_rad);
  const double yaw_m = s.yaw_rad + heading_error_rad_;
  const Eigen::Matrix3d R_measured = rotationFromRpy(roll_m, pitch_m, yaw_m);

  // Specific force, drawn whether or not it is recorded (the dead reckoning uses it between DVL pings).
  const Eigen::Vector3d specific_force_mps2 =
      R.transpose() * (s.acceleration_mps2 + Eigen::Vector3d(0, 0, kGravity_mps2)) +
      Eigen::Vector3d(rng_imu_.gaussian(config_.accel_noise_mps2), rng_imu_.gaussian(config_.accel_noise_mps2),
                      rng_imu_.gaussian(config_.accel_noise_mps2));
  if (sinks.imu) {
    dive::ImuRecord imu;
    imu.stamp_s = stamp;
    imu.orientation = Eigen::Quaterniond(R_measured);
    imu.angular_velocity_rps = measured_rate;
    imu.linear_acceleration_mps2 = specific_force_mps2;
    imu.orientation_sigma_rad = config_.attitude_noise_rad;
    imu.angular_velocity_sigma_rps = config_.gyro_noise_rps;
    imu.linear_acceleration_sigma_mps2 = config_.accel_noise_mps2;
    sinks.imu(imu);
  }

  const long tick = imu_ticks_;
  auto due = [&](double rate_hz) {
    // A sensor at rate r fires on the IMU ticks where the count of its periods increases.
    return tick == 0 || dueCount(tau, rate_hz) > dueCount(tau - dt, rate_hz);
  };

  if (due(config_.dvl_rate_hz)) {
    const Eigen::Vector3d v_body = R.transpose() * s.velocity_mps;
    dvl_measured_ = dvl_scale_ * v_body + Eigen::Vector3d(rng_dvl_.gaussian(config_.dvl_noise_mps),
                                                          rng_dvl_.gaussian(config_.dvl_noise_mps),
                                                          rng_dvl_.gaussian(config_.dvl_noise_mps));
    if (sinks.dvl) sinks.dvl({stamp, dvl_measured_, config_.dvl_noise_mps});
    dr_velocity_world_ = R_measured * dvl_measured_;
  } else if (tick > 0) {
    dr_velocity_world_ += (R_measured * specific_force_mps2 - Eigen::Vector3d(0, 0, kGravity_mps2)) * dt;
  }
  if (tick > 0) {
    const Eigen::Vector3d& v_world = dr_velocity_world_;
    dr_position_local_.x() += v_world.x() * dt;
    dr_position_local_.y() += v_world.y() * dt;
    dr_distance_m_ += v_world.head<2>().norm() * dt;
  }
  if (due(config_.depth_rate_hz)) {
    last_depth_m_ = seabed_depth_m_ - s.position_m.z() + rng_depth_.gaussian(config_.depth_noise_m);
    if (sinks.depth) sinks.depth({stamp, last_depth_m_, config_.depth_noise_m});
  }
  if (due(config_.altimeter_rate_hz) && sinks.altitude) {
    dive::AltitudeRecord a;
    a.stamp_s = stamp;
    a.range_m = trueAltitude(s) + rng_alt_.gaussian(config_.altimeter_noise_m);
    if (a.range_m > config_.altimeter_max_range_m) a.range_m = std::numeric_limits<double>::infinity();  // REP-117
    a.sigma_m = config_.altimeter_noise_m;
    a.max_range_m = config_.altimeter_max_range_m;
    sinks.altitude(a);
  }
  if (due(config_.nav_rate_hz) && sinks.dead_reckoning) {
    dive::PoseRecord p;
    p.stamp_s = stamp;
    dr_position_local_.z() = seabed_depth_m_ - last_depth_m_;  // vertical from the pressure sensor
    p.position_m = toWorld(dr_position_local_);
    p.orientation = Eigen::Quaterniond(R_measured);
    p.linear_velocity_mps = dvl_measured_;
    p.angular_velocity_rps = measured_rate;
    const double sigma_xy = std::hypot(config_.dr_launch_sigma_m, config_.dr_sigma_per_m * dr_distance_m_);
    p.pose_covariance.diagonal() << sigma_xy * sigma_xy, sigma_xy * sigma_xy,
        config_.depth_noise_m * config_.depth_noise_m, std::pow(config_.attitude_noise_rad, 2),
        std::pow(config_.attitude_noise_rad, 2), std::pow(config_.gyro_bias_rps * std::max(1.0, tau), 2);
    p.twist_covariance.diagonal() << std::pow(config_.dvl_noise_mps, 2), std::pow(config_.dvl_noise_mps, 2),
        std::pow(config_.dvl_noise_mps, 2), std::pow(config_.gyro_noise_rps, 2), std::pow(config_.gyro_noise_rps, 2),
        std::pow(config_.gyro_noise_rps, 2);
    sinks.dead_reckoning(p);
  }
  if (due(config_.usbl_rate_hz)) {
    bool dropped = false;
    for (const auto& d : config_.usbl_dropouts_s) dropped |= tau >= d.first && tau < d.second;
    // Draw the noise even when dropped, so that a dropout does not change the other fixes.
    Eigen::Vector3d err(rng_usbl_.gaussian(config_.usbl_noise_m), rng_usbl_.gaussian(config_.usbl_noise_m),
                        rng_usbl_.gaussian(config_.usbl_vertical_noise_m));
    const bool outlier = rng_usbl_.chance(config_.usbl_outlier_probability);
    const double outlier_dir = rng_usbl_.uniform(0.0, 2 * M_PI);
    if (outlier) {
      const double magnitude = config_.usbl_outlier_scale * std::max(config_.usbl_noise_m, 0.1);
      err.x() += magnitude * std::cos(outlier_dir);
      err.y() += magnitude * std::sin(outlier_dir);
    }
    if (!dropped && sinks.usbl) {
      const Eigen::Vector3d w = toWorld(s.position_m) + err;
      const Eigen::Vector2d ll = exocet_common::gridToLatLon(geo_, w.x(), w.y());
      dive::FixRecord f;
      f.stamp_s = stamp;
      f.arrival_s = stamp + config_.usbl_latency_s;
      f.latitude_deg = ll.x();
      f.longitude_deg = ll.y();
      f.altitude_m = w.z();
      f.horizontal_sigma_m = config_.usbl_noise_m;
      f.vertical_sigma_m = config_.usbl_vertical_noise_m;
      sinks.usbl(f);
    }
  }
}

}  // namespace sim
}  // namespace exocet_mosaic
