#include "exocet_mosaic/fusion/fusion_front_end.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <utility>
#include <vector>

#include <Eigen/Dense>

#include "exocet_mosaic/fusion/image_heading.h"

namespace exocet_mosaic {
namespace fusion {
namespace {

Eigen::Quaterniond levelAttitude(double enu_yaw_rad) {
  return Eigen::Quaterniond(Eigen::AngleAxisd(enu_yaw_rad, Eigen::Vector3d::UnitZ()));
}

/// Roll, pitch, yaw (ZYX: R = Rz(yaw) Ry(pitch) Rx(roll)) of a rotation.
Eigen::Vector3d rollPitchYaw(const Eigen::Matrix3d& r) {
  return {std::atan2(r(2, 1), r(2, 2)), std::asin(std::clamp(-r(2, 0), -1.0, 1.0)), std::atan2(r(1, 0), r(0, 0))};
}

Eigen::Matrix3d fromRollPitchYaw(double roll_rad, double pitch_rad, double yaw_rad) {
  return (Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ()) *
          Eigen::AngleAxisd(pitch_rad, Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(roll_rad, Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

/// Value at t = 0 of a least-squares polynomial in t (quadratic from 5 samples, linear from 2, else the mean) and
/// the factor by which one sample's variance scales to that value's.
std::pair<double, double> polynomialAtZero(const std::vector<double>& t, const std::vector<double>& y) {
  const int n = static_cast<int>(t.size());
  const int degree = n >= 5 ? 2 : (n >= 2 ? 1 : 0);
  Eigen::MatrixXd a(n, degree + 1);
  Eigen::VectorXd b(n);
  for (int i = 0; i < n; ++i) {
    for (int d = 0; d <= degree; ++d) a(i, d) = std::pow(t[i], d);
    b(i) = y[i];
  }
  const Eigen::MatrixXd ata_inv = (a.transpose() * a).inverse();
  const Eigen::VectorXd c = ata_inv * a.transpose() * b;
  return {c[0], ata_inv(0, 0)};
}

const FusionFrontEndConfig& validated(const FusionFrontEndConfig& config) {
  const std::string error = config.validate();
  if (!error.empty()) throw std::invalid_argument("fusion: " + error);
  return config;
}

}  // namespace

std::string FusionFrontEndConfig::validate() const {
  std::ostringstream why;
  const std::string filter_error = filter.validate();
  if (!filter_error.empty())
    why << filter_error;
  else if (!(attitude_max_gap_s > 0.0 && attitude_max_gap_s <= 60.0))
    why << "attitude_max_gap_s = " << attitude_max_gap_s << " is outside (0, 60] s";
  else if (!(altitude_max_gap_s > 0.0 && altitude_max_gap_s <= 600.0))
    why << "altitude_max_gap_s = " << altitude_max_gap_s << " is outside (0, 600] s";
  else if (!(history_window_s >= 1.0 && history_window_s <= 3600.0))
    why << "history_window_s = " << history_window_s << " is outside [1, 3600] s";
  else if (!(view_half_window_s >= 0.0 && view_half_window_s <= 10.0))
    why << "view_half_window_s = " << view_half_window_s << " is outside [0, 10] s";
  else if (!(altimeter_sigma_m >= 0.0 && altimeter_sigma_m <= 10.0))
    why << "altimeter_sigma_m = " << altimeter_sigma_m << " is outside [0, 10] m";
  else if (!std::isnan(seabed_depth_m) && !(seabed_depth_m > 0.0 && seabed_depth_m <= 12000.0))
    why << "seabed_depth_m = " << seabed_depth_m << " is outside (0, 12000] m (NaN: not used)";
  else if (!(depth_max_gap_s > 0.0 && depth_max_gap_s <= 600.0))
    why << "depth_max_gap_s = " << depth_max_gap_s << " is outside (0, 600] s";
  else if (base_frame.empty() || default_camera_frame.empty())
    why << "base_frame and default_camera_frame must not be empty";
  return why.str();
}

FusionFrontEnd::FusionFrontEnd(const FusionFrontEndConfig& config, MountLookup mounts)
    : config_(validated(config)),
      mounts_(std::move(mounts)),
      filter_(config.filter),
      imu_attitude_(config.history_window_s, config.attitude_max_gap_s),
      nav_attitude_(config.history_window_s, config.attitude_max_gap_s),
      altimeter_range_m_(config.history_window_s, config.altitude_max_gap_s),
      depth_m_(config.history_window_s, config.depth_max_gap_s) {
  if (!mounts_) throw std::invalid_argument("fusion: no mount lookup given");
  filter_.setKeepLog(config.keep_log);
  if (config.keep_log && !config.log_file.empty()) filter_.setLogFile(config.log_file);
}

void FusionFrontEnd::addImuAttitude(double stamp_s, const Eigen::Quaterniond& world_from_base) {
  imu_attitude_.add(stamp_s, world_from_base);
}

void FusionFrontEnd::addNavigationAttitude(double stamp_s, const Eigen::Quaterniond& world_from_base) {
  nav_attitude_.add(stamp_s, world_from_base);
}

void FusionFrontEnd::addAltimeterRange(double stamp_s, double range_m, const std::string& frame) {
  altimeter_frame_ = frame;
  altimeter_range_m_.add(stamp_s, range_m);
}

void FusionFrontEnd::addDepth(double stamp_s, double depth_m) { depth_m_.add(stamp_s, depth_m); }

void FusionFrontEnd::setCameraFrame(const std::string& frame) {
  if (!frame.empty()) camera_frame_ = frame;
}

const std::string& FusionFrontEnd::cameraFrame() const {
  return camera_frame_.empty() ? config_.default_camera_frame : camera_frame_;
}

void FusionFrontEnd::setOperatorStart(const Eigen::Vector2d& camera_en_m, double sigma_m) {
  pending_start_en_m_ = camera_en_m;
  pending_start_sigma_m_ = sigma_m;
}

void FusionFrontEnd::initialize(double stamp_s, const Eigen::Vector2d& camera_en_m,
                                const Eigen::Matrix2d& covariance_m2) {
  filter_.initialize(stamp_s, camera_en_m, covariance_m2);
  image_only_en_m_ = camera_en_m;
  pending_start_en_m_.reset();
}

void FusionFrontEnd::resume(double stamp_s, const StateVector& x, const StateMatrix& P, bool dr_offset_known) {
  filter_.resume(stamp_s, x, P, dr_offset_known);
  image_only_en_m_ = x.segment<2>(kEast);
  pending_start_en_m_.reset();
}

void FusionFrontEnd::start(double stamp_s, const Eigen::Vector2d& camera_en_m, double sigma_m,
                           const std::string& source, InputOutcome* outcome) {
  initialize(stamp_s, camera_en_m, Eigen::Matrix2d::Identity() * sigma_m * sigma_m);
  outcome->started_from = source;
}

bool FusionFrontEnd::startFromOperator(double stamp_s, InputOutcome* outcome) {
  if (filter_.initialized()) return true;
  if (!pending_start_en_m_) return false;
  start(stamp_s, *pending_start_en_m_, pending_start_sigma_m_, "the operator's first point", outcome);
  return true;
}

void FusionFrontEnd::reset() {
  filter_.reset();
  imu_attitude_.clear();
  nav_attitude_.clear();
  altimeter_range_m_.clear();
  depth_m_.clear();
  image_only_en_m_.reset();
  first_unplaced_stamp_s_.reset();
}

std::optional<Eigen::Quaterniond> FusionFrontEnd::attitudeAt(double stamp_s) const {
  if (auto q = imu_attitude_.at(stamp_s)) return q;
  if (auto q = nav_attitude_.at(stamp_s)) return q;
  return std::nullopt;
}

std::optional<double> FusionFrontEnd::newestAttitudeStamp() const {
  const std::optional<double> imu = imu_attitude_.newestStamp(), nav = nav_attitude_.newestStamp();
  if (imu && nav) return std::max(*imu, *nav);
  return imu ? imu : nav;
}

std::optional<Eigen::Quaterniond> FusionFrontEnd::viewAttitudeAt(double stamp_s) const {
  const std::optional<Eigen::Quaterniond> at = attitudeAt(stamp_s);
  if (!at || config_.view_half_window_s <= 0.0) return at;
  // Roll and pitch (gravity-referenced, white noise) fitted over the window; the heading (gyro-integrated, smooth) is
  // the interpolated one.
  const AttitudeHistory& source = imu_attitude_.at(stamp_s) ? imu_attitude_ : nav_attitude_;
  const double h = config_.view_half_window_s;
  std::vector<double> t, roll, pitch;
  for (const auto& [stamp, q] : source.between(stamp_s - h - 1e-9, stamp_s + h + 1e-9)) {
    const Eigen::Vector3d rpy = rollPitchYaw(q.toRotationMatrix());
    t.push_back(stamp - stamp_s);
    roll.push_back(rpy.x());
    pitch.push_back(rpy.y());
  }
  if (t.empty()) return at;
  const double yaw = rollPitchYaw(at->toRotationMatrix()).z();
  return Eigen::Quaterniond(fromRollPitchYaw(polynomialAtZero(t, roll).first, polynomialAtZero(t, pitch).first, yaw));
}

std::optional<std::pair<double, double>> FusionFrontEnd::viewRangeAt(double stamp_s) const {
  const std::optional<double> at = altimeter_range_m_.at(stamp_s);
  if (!at) return std::nullopt;
  if (config_.view_half_window_s <= 0.0) return std::make_pair(*at, config_.altimeter_sigma_m);
  const double h = config_.view_half_window_s;
  std::vector<double> t, range;
  for (const auto& [stamp, r] : altimeter_range_m_.between(stamp_s - h - 1e-9, stamp_s + h + 1e-9)) {
    t.push_back(stamp - stamp_s);
    range.push_back(r);
  }
  if (t.empty()) return std::make_pair(*at, config_.altimeter_sigma_m);
  const auto [value, factor] = polynomialAtZero(t, range);
  return std::make_pair(value, config_.altimeter_sigma_m * std::sqrt(factor));
}

std::optional<ViewGeometry> FusionFrontEnd::viewWith(double stamp_s, const Eigen::Quaterniond& world_from_base,
                                                     const Eigen::Isometry3d& base_from_camera) const {
  ViewGeometry view;
  view.world_from_base = world_from_base;
  // The altimeter's height (and its sigma) when it covers the stamp, else the operator's (taken as exact).
  if (!altimeter_frame_.empty()) {
    if (const auto range = viewRangeAt(stamp_s)) {
      if (const auto altimeter = mounts_(altimeter_frame_)) {
        try {
          const double height_m = cameraHeightFromAltimeter_m(range->first, world_from_base, altimeter->translation(),
                                                              base_from_camera.translation());
          if (std::isfinite(height_m) && height_m > 0.0) {
            view.camera_height_m = height_m;
            view.camera_height_sigma_m = range->second;
            return view;
          }
        } catch (const std::invalid_argument&) {
          // An altimeter beam that does not point down, or a height <= 0: the operator's height, if any.
        }
      }
    }
  }
  if (std::isfinite(config_.seabed_depth_m)) {
    if (const auto depth_m = depth_m_.at(stamp_s)) {
      // z is up: a camera above the sensor is shallower.
      const double camera_depth_m = *depth_m - (world_from_base * base_from_camera.translation()).z();
      const double height_m = config_.seabed_depth_m - camera_depth_m;
      if (height_m > 0.0) {
        view.camera_height_m = height_m;
        return view;
      }
    }
  }
  if (!operator_height_m_) return std::nullopt;
  view.camera_height_m = *operator_height_m_;
  return view;
}

std::optional<double> FusionFrontEnd::cameraHeightAt(double stamp_s, const Eigen::Quaterniond& world_from_base,
                                                     const Eigen::Isometry3d& base_from_camera) const {
  const std::optional<ViewGeometry> view = viewWith(stamp_s, world_from_base, base_from_camera);
  if (!view) return std::nullopt;
  return view->camera_height_m;
}

std::optional<ViewGeometry> FusionFrontEnd::viewAt(double stamp_s, const Eigen::Isometry3d& base_from_camera) const {
  const std::optional<Eigen::Quaterniond> q = viewAttitudeAt(stamp_s);
  return q ? viewWith(stamp_s, *q, base_from_camera) : std::nullopt;
}

std::string FusionFrontEnd::waitingForLeverArm(bool mounts_known) const {
  return mounts_known ? "the filter waits for the attitude to place the camera from the navigation"
                      : "the filter waits for the transform " + config_.base_frame + " -> " + cameraFrame() +
                            " (and the transponder's, for a fix) to place the camera from the navigation";
}

InputOutcome FusionFrontEnd::addDeadReckoning(double stamp_s, const Eigen::Vector3d& base_en_m,
                                              const Eigen::Matrix2d& covariance_m2) {
  InputOutcome outcome;
  // The camera's position from base_link's: lever arm turned by the attitude when it is known.
  Eigen::Vector2d camera_en = base_en_m.head<2>();
  const auto attitude = attitudeAt(stamp_s);
  const auto camera = cameraMount();
  if (attitude && camera) camera_en = cameraPosition(base_en_m, *attitude, *camera).head<2>();
  outcome.camera_en_m = camera_en;
  if (!filter_.initialized() && !startFromOperator(stamp_s, &outcome)) {
    // The filter tracks the camera: started at base_link's position (its mount or the attitude not known yet: a
    // late /tf_static, the IMU's first sample still to come) it would carry the lever arm as an error for as long as
    // the fixes take to remove it.
    // A vehicle without attitude sensing at all: started without the lever arm after kAttitudeWait.
    if (!first_unplaced_stamp_s_) first_unplaced_stamp_s_ = stamp_s;
    if (!camera || (!attitude && stamp_s - *first_unplaced_stamp_s_ < kAttitudeWaitS)) {
      outcome.problem = waitingForLeverArm(camera.has_value());
      return outcome;
    }
    if (!attitude) outcome.problem = "no attitude: the filter started at base_link's position, without the lever arm";
    start(stamp_s, camera_en, std::sqrt(covariance_m2.trace() / 2.0), "the dead reckoning", &outcome);
    return outcome;
  }
  outcome.update = filter_.addDeadReckoning(stamp_s, camera_en, covariance_m2);
  return outcome;
}

InputOutcome FusionFrontEnd::addFix(double stamp_s, const Eigen::Vector2d& fix_en_m,
                                    const Eigen::Matrix2d& covariance_m2, const std::string& transponder_frame,
                                    bool may_start) {
  InputOutcome outcome;
  // The transponder is not the camera: move the fix by the lever arm between them.
  Eigen::Vector2d camera_en = fix_en_m;
  const auto attitude = attitudeAt(stamp_s);
  const auto camera = cameraMount();
  const auto transponder = transponder_frame.empty() || transponder_frame == config_.base_frame
                               ? std::optional<Eigen::Isometry3d>(Eigen::Isometry3d::Identity())
                               : mounts_(transponder_frame);
  if (attitude && camera && transponder)
    camera_en += (attitude->toRotationMatrix() * (camera->translation() - transponder->translation())).head<2>();
  outcome.camera_en_m = camera_en;
  if (!filter_.initialized() && !startFromOperator(stamp_s, &outcome)) {
    if (may_start && (!camera || !transponder || !attitude))
      outcome.problem = waitingForLeverArm(camera.has_value() && transponder.has_value());
    else if (may_start)
      start(stamp_s, camera_en, std::sqrt(covariance_m2.trace() / 2.0), "the first fix", &outcome);
    return outcome;  // otherwise the dead reckoning starts the filter
  }
  outcome.update = filter_.addAbsoluteFix(stamp_s, camera_en, covariance_m2);
  return outcome;
}

InputOutcome FusionFrontEnd::failImage(const ImageMotionInput& motion, InputOutcome outcome) {
  outcome.update = filter_.addImageFailure(motion.previous_stamp_s, motion.stamp_s);
  return outcome;
}

InputOutcome FusionFrontEnd::addImageMotion(const ImageMotionInput& motion) {
  InputOutcome outcome;
  const double t0 = motion.previous_stamp_s, t1 = motion.stamp_s;
  if (!std::isfinite(t0) || !std::isfinite(t1) || t0 <= 0.0 || t0 > t1) {
    outcome.rejected = "previous_stamp is zero or after the stamp";
    return outcome;
  }
  if (!startFromOperator(t0, &outcome)) {
    outcome.update = UpdateResult{UpdateStatus::kNotInitialized, 0.0, ""};
    return outcome;
  }
  if (motion.failed) return failImage(motion, outcome);
  registration::MotionModel model;
  try {
    model = registration::motionModelFromString(motion.model);
  } catch (const std::invalid_argument& e) {
    outcome.rejected = e.what();
    return failImage(motion, outcome);
  }
  const int n = registration::parameterCount(model);
  if (motion.parameters.size() != n || motion.covariance.rows() != n || motion.covariance.cols() != n) {
    outcome.rejected = "parameters/covariance sizes do not match the model " + motion.model;
    return failImage(motion, outcome);
  }
  if (!motion.parameters.allFinite() || !motion.covariance.allFinite()) {
    outcome.rejected = "non-finite parameters or covariance";
    return failImage(motion, outcome);
  }
  CameraMount mount;
  std::optional<Eigen::Matrix3d> k = motion.camera_matrix;
  if (!k || !((*k)(0, 0) > 0.0 && (*k)(1, 1) > 0.0 && k->allFinite())) k = camera_matrix_;
  if (!k) {
    outcome.rejected = "no camera matrix in the message and no camera_info received";
    return failImage(motion, outcome);
  }
  mount.camera_matrix = *k;
  const auto camera = cameraMount();
  if (!camera) {
    outcome.problem = "no transform " + config_.base_frame + " -> " + cameraFrame();
    return failImage(motion, outcome);
  }
  mount.base_from_camera = *camera;

  // Attitude at both stamps: the sensors', or the operator's heading carried on by the image rotation.
  std::optional<Eigen::Quaterniond> q0 = viewAttitudeAt(t0), q1 = viewAttitudeAt(t1);
  double yaw_change_rad = 0.0;
  if ((!q0 || !q1) && operator_heading_rad_) {
    yaw_change_rad = yawChangeFromImageMotion_rad(motion.pixel_matrix, *k, mount.base_from_camera);
    q0 = levelAttitude(*operator_heading_rad_);
    q1 = levelAttitude(*operator_heading_rad_ + yaw_change_rad);
  }
  if (!q0 || !q1) {
    outcome.problem = "no attitude at the image stamps (IMU, navigation orientation or ~initial_heading_deg)";
    return failImage(motion, outcome);
  }
  const std::optional<ViewGeometry> v0 = viewWith(t0, *q0, mount.base_from_camera);
  const std::optional<ViewGeometry> v1 = viewWith(t1, *q1, mount.base_from_camera);
  if (!v0 || !v1) {
    outcome.problem = std::isfinite(config_.seabed_depth_m)
                          ? "no camera height at the image stamps: no altimeter range and no depth (/nav/depth) "
                            "above the seabed depth (~seabed_depth_m) covers them, and ~initial_altitude_m is not set"
                          : "no camera height at the image stamps: no altimeter range covers them; set "
                            "~initial_altitude_m (the camera's height above the seabed, m) or ~seabed_depth_m (with "
                            "the depth sensor's /nav/depth)";
    return failImage(motion, outcome);
  }
  const MetricMotion metric =
      toMetricMotion(model, motion.parameters, motion.covariance, motion.centre_px, mount, *v0, *v1);
  if (!metric.valid) {
    outcome.rejected = metric.error;
    return failImage(motion, outcome);
  }
  if (operator_heading_rad_ && yaw_change_rad != 0.0) *operator_heading_rad_ += yaw_change_rad;
  outcome.update = filter_.addImageMotion(t0, t1, metric);
  outcome.metric = metric;
  if (image_only_en_m_) {
    *image_only_en_m_ += metric.camera_displacement_en_m;
    outcome.camera_en_m = *image_only_en_m_;
  }
  return outcome;
}

}  // namespace fusion
}  // namespace exocet_mosaic
