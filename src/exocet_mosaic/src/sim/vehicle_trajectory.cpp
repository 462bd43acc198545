#include "exocet_mosaic/sim/vehicle_trajectory.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>
#include <stdexcept>

namespace exocet_mosaic {
namespace sim {

namespace {
constexpr double kDegToRad = M_PI / 180.0;

double wrapAngle(double a) {
  while (a > M_PI) a -= 2.0 * M_PI;
  while (a < -M_PI) a += 2.0 * M_PI;
  return a;
}
}  // namespace

Eigen::Matrix3d rotationFromRpy(double roll_rad, double pitch_rad, double yaw_rad) {
  return (Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(pitch_rad, Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(roll_rad, Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

Eigen::Vector3d rpyFromRotation(const Eigen::Matrix3d& R) {
  const double pitch = std::asin(std::clamp(-R(2, 0), -1.0, 1.0));
  const double roll = std::atan2(R(2, 1), R(2, 2));
  const double yaw = std::atan2(R(1, 0), R(0, 0));
  return {roll, pitch, yaw};
}

Eigen::Matrix3d VehicleState::rotation() const { return rotationFromRpy(roll_rad, pitch_rad, yaw_rad); }

// ---------------------------------------------------------------------------------------------------------------
// Segments of the horizontal path, each parameterised by its local time.
struct VehicleTrajectory::Segment {
  virtual ~Segment() = default;
  virtual double duration_s() const = 0;
  virtual double length_m() const = 0;
  /// Position, yaw and nominal altitude at local time tau in [0, duration].
  virtual void at(double tau_s, Eigen::Vector2d* xy, double* yaw_rad, double* altitude_m) const = 0;
};

namespace {

/// Straight leg with a trapezoidal (or triangular) speed profile.
class LineSegment : public VehicleTrajectory::Segment {
 public:
  LineSegment(const Eigen::Vector2d& p0, const Eigen::Vector2d& p1, double v_start, double v_cruise, double v_end,
              double accel, double alt0, double alt1)
      : p0_(p0), alt0_(alt0), alt1_(alt1), v0_(v_start), a_(accel) {
    const Eigen::Vector2d d = p1 - p0;
    length_ = d.norm();
    dir_ = length_ > 0 ? Eigen::Vector2d(d / length_) : Eigen::Vector2d(1, 0);
    yaw_ = std::atan2(dir_.y(), dir_.x());
    double vc = v_cruise;
    double da = (vc * vc - v0_ * v0_) / (2 * a_);
    double dd = (vc * vc - v_end * v_end) / (2 * a_);
    if (da + dd > length_) {  // no room to reach cruise speed: triangular profile
      vc = std::sqrt((2 * a_ * length_ + v0_ * v0_ + v_end * v_end) / 2.0);
      da = (vc * vc - v0_ * v0_) / (2 * a_);
      dd = (vc * vc - v_end * v_end) / (2 * a_);
    }
    vc_ = vc;
    ta_ = (vc - v0_) / a_;
    tc_ = vc > 0 ? (length_ - da - dd) / vc : 0.0;
    td_ = (vc - v_end) / a_;
    da_ = da;
  }
  double duration_s() const override { return ta_ + tc_ + td_; }
  double length_m() const override { return length_; }
  void at(double tau, Eigen::Vector2d* xy, double* yaw, double* alt) const override {
    double s;
    if (tau <= ta_) {
      s = v0_ * tau + 0.5 * a_ * tau * tau;
    } else if (tau <= ta_ + tc_) {
      s = da_ + vc_ * (tau - ta_);
    } else {
      const double u = std::min(tau - ta_ - tc_, td_);
      s = da_ + vc_ * tc_ + vc_ * u - 0.5 * a_ * u * u;
    }
    s = std::clamp(s, 0.0, length_);
    *xy = p0_ + s * dir_;
    *yaw = yaw_;
    *alt = length_ > 0 ? alt0_ + (alt1_ - alt0_) * s / length_ : alt0_;
  }
  double yaw() const { return yaw_; }

 private:
  Eigen::Vector2d p0_, dir_;
  double alt0_, alt1_, v0_, a_;
  double length_ = 0, yaw_ = 0, vc_ = 0, ta_ = 0, tc_ = 0, td_ = 0, da_ = 0;
};

/// Circular arc at constant speed (lawnmower U-turns). sweep > 0 turns counter-clockwise (to port).
class ArcSegment : public VehicleTrajectory::Segment {
 public:
  ArcSegment(const Eigen::Vector2d& centre, double radius, double start_angle, double sweep, double speed, double alt)
      : c_(centre), r_(radius), phi0_(start_angle), sweep_(sweep), v_(speed), alt_(alt) {}
  double duration_s() const override { return r_ * std::abs(sweep_) / v_; }
  double length_m() const override { return r_ * std::abs(sweep_); }
  void at(double tau, Eigen::Vector2d* xy, double* yaw, double* alt) const override {
    const double sign = sweep_ > 0 ? 1.0 : -1.0;
    const double phi = phi0_ + sign * std::min(tau * v_ / r_, std::abs(sweep_));
    *xy = c_ + r_ * Eigen::Vector2d(std::cos(phi), std::sin(phi));
    *yaw = phi + sign * M_PI / 2;
    *alt = alt_;
  }

 private:
  Eigen::Vector2d c_;
  double r_, phi0_, sweep_, v_, alt_;
};

/// Turn in place with a smooth (raised-cosine) yaw profile: zero yaw rate at both ends.
class TurnSegment : public VehicleTrajectory::Segment {
 public:
  TurnSegment(const Eigen::Vector2d& p, double yaw0, double delta_yaw, double max_rate, double alt)
      : p_(p), yaw0_(yaw0), delta_(delta_yaw), alt_(alt) {
    duration_ = std::abs(delta_) * M_PI / (2.0 * max_rate);
  }
  double duration_s() const override { return duration_; }
  double length_m() const override { return 0.0; }
  void at(double tau, Eigen::Vector2d* xy, double* yaw, double* alt) const override {
    const double u = duration_ > 0 ? std::clamp(tau / duration_, 0.0, 1.0) : 1.0;
    *xy = p_;
    *yaw = yaw0_ + delta_ * 0.5 * (1.0 - std::cos(M_PI * u));
    *alt = alt_;
  }

 private:
  Eigen::Vector2d p_;
  double yaw0_, delta_, alt_, duration_ = 0;
};

bool finite(double v) { return std::isfinite(v); }

void checkRange(std::ostringstream& err, const char* field, double v, double lo, double hi, const char* unit) {
  if (!finite(v) || v < lo || v > hi)
    err << "trajectory." << field << " = " << v << " out of range [" << lo << ", " << hi << "] " << unit << "; ";
}

}  // namespace

std::vector<Waypoint> loadWaypointsCsv(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error("cannot read waypoints file '" + path + "'");
  std::string line;
  if (!std::getline(in, line)) throw std::runtime_error(path + ": empty waypoints file (header x_m,y_m expected)");
  std::vector<std::string> names;
  {
    std::stringstream ss(line);
    std::string n;
    while (std::getline(ss, n, ',')) {
      n.erase(std::remove_if(n.begin(), n.end(), ::isspace), n.end());
      names.push_back(n);
    }
  }
  auto column = [&](const std::string& n) {
    auto it = std::find(names.begin(), names.end(), n);
    return it == names.end() ? -1 : static_cast<int>(it - names.begin());
  };
  const int cx = column("x_m"), cy = column("y_m"), ca = column("altitude_m"), cs = column("speed_mps");
  if (cx < 0 || cy < 0) throw std::runtime_error(path + ": header must name columns x_m and y_m");
  std::vector<Waypoint> wps;
  int line_no = 1;
  while (std::getline(in, line)) {
    ++line_no;
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    std::vector<double> v;
    std::stringstream ss(line);
    std::string cell;
    while (std::getline(ss, cell, ',')) {
      try {
        size_t used = 0;
        v.push_back(std::stod(cell, &used));
      } catch (const std::exception&) {
        throw std::runtime_error(path + ":" + std::to_string(line_no) + ": '" + cell + "' is not a number");
      }
    }
    if (static_cast<int>(v.size()) != static_cast<int>(names.size()))
      throw std::runtime_error(path + ":" + std::to_string(line_no) + ": expected " + std::to_string(names.size()) +
                               " values");
    for (double x : v)
      if (!std::isfinite(x)) throw std::runtime_error(path + ":" + std::to_string(line_no) + ": NaN or infinite value");
    Waypoint w;
    w.x_m = v[cx];
    w.y_m = v[cy];
    if (ca >= 0) {
      w.altitude_m = v[ca];
      if (w.altitude_m <= 0)
        throw std::runtime_error(path + ":" + std::to_string(line_no) + ": altitude_m " + std::to_string(w.altitude_m) +
                                 " must be > 0 m");
    }
    if (cs >= 0) {
      w.speed_mps = v[cs];
      if (w.speed_mps <= 0 || w.speed_mps > 5)
        throw std::runtime_error(path + ":" + std::to_string(line_no) + ": speed_mps " + std::to_string(w.speed_mps) +
                                 " out of range (0, 5] m/s");
    }
    wps.push_back(w);
  }
  if (wps.size() < 2) throw std::runtime_error(path + ": at least 2 waypoints are needed");
  return wps;
}

std::string TrajectoryConfig::validate() const {
  std::ostringstream err;
  checkRange(err, "speed_mps", speed_mps, 0.01, 5.0, "m/s");
  checkRange(err, "acceleration_mps2", acceleration_mps2, 0.001, 5.0, "m/s^2");
  checkRange(err, "altitude_m", altitude_m, 0.2, 100.0, "m");
  checkRange(err, "altitude_variation_m", altitude_variation_m, 0.0, 0.8 * altitude_m, "m (at most 80% of altitude_m)");
  checkRange(err, "altitude_period_s", altitude_period_s, 1.0, 1e5, "s");
  checkRange(err, "roll_amplitude_deg", roll_amplitude_deg, 0.0, 30.0, "deg");
  checkRange(err, "pitch_amplitude_deg", pitch_amplitude_deg, 0.0, 30.0, "deg");
  checkRange(err, "yaw_oscillation_deg", yaw_oscillation_deg, 0.0, 45.0, "deg");
  checkRange(err, "roll_period_s", roll_period_s, 0.5, 1e4, "s");
  checkRange(err, "pitch_period_s", pitch_period_s, 0.5, 1e4, "s");
  checkRange(err, "yaw_period_s", yaw_period_s, 0.5, 1e4, "s");
  checkRange(err, "turn_rate_deg_s", turn_rate_deg_s, 0.5, 180.0, "deg/s");
  checkRange(err, "heading_deg", heading_deg, -360.0, 360.0, "deg");
  checkRange(err, "start_x_m", start_x_m, -1e6, 1e6, "m");
  checkRange(err, "start_y_m", start_y_m, -1e6, 1e6, "m");
  if (kind != Kind::kWaypoints) checkRange(err, "line_length_m", line_length_m, 0.1, 1e5, "m");
  if (kind == Kind::kLawnmower) {
    checkRange(err, "line_spacing_m", line_spacing_m, 0.1, 1e4, "m");
    if (line_count < 1 || line_count > 10000) err << "trajectory.line_count = " << line_count << " out of range [1, 10000]; ";
  }
  if (kind == Kind::kWaypoints && waypoints.size() < 2) err << "trajectory.waypoints: at least 2 waypoints are needed; ";
  std::string s = err.str();
  if (!s.empty()) s.resize(s.size() - 2);
  return s;
}

VehicleTrajectory::~VehicleTrajectory() = default;

VehicleTrajectory::VehicleTrajectory(const TrajectoryConfig& config) : config_(config) {
  const std::string problem = config.validate();
  if (!problem.empty()) throw std::invalid_argument(problem);
  const double v = config.speed_mps, a = config.acceleration_mps2, alt = config.altitude_m;
  const double turn_rate = config.turn_rate_deg_s * kDegToRad;
  const double yaw0 = wrapAngle(M_PI / 2 - config.heading_deg * kDegToRad);  // compass heading -> ENU yaw
  const Eigen::Vector2d start(config.start_x_m, config.start_y_m);
  const Eigen::Vector2d u(std::cos(yaw0), std::sin(yaw0));
  const Eigen::Vector2d starboard(u.y(), -u.x());

  switch (config.kind) {
    case TrajectoryConfig::Kind::kLawnmower: {
      const double side = config.turn_to_starboard ? 1.0 : -1.0;
      const Eigen::Vector2d across = side * starboard;
      const double r = config.line_spacing_m / 2.0;
      for (int i = 0; i < config.line_count; ++i) {
        Eigen::Vector2d p0 = start + i * config.line_spacing_m * across;
        if (i % 2) p0 += config.line_length_m * u;
        const Eigen::Vector2d dir = (i % 2) ? Eigen::Vector2d(-u) : u;
        const Eigen::Vector2d p1 = p0 + config.line_length_m * dir;
        const double vs = i == 0 ? 0.0 : v, ve = i == config.line_count - 1 ? 0.0 : v;
        segments_.push_back(std::make_unique<LineSegment>(p0, p1, vs, v, ve, a, alt, alt));
        if (i + 1 < config.line_count) {
          // U-turn towards `across`: clockwise (negative sweep) when `across` is to starboard of `dir`.
          const Eigen::Vector2d centre = p1 + r * across;
          const Eigen::Vector2d radial = p1 - centre;
          const double phi0 = std::atan2(radial.y(), radial.x());
          const Eigen::Vector2d dir_starboard(dir.y(), -dir.x());
          const double sweep = (dir_starboard.dot(across) > 0) ? -M_PI : M_PI;
          segments_.push_back(std::make_unique<ArcSegment>(centre, r, phi0, sweep, v, alt));
        }
      }
      break;
    }
    case TrajectoryConfig::Kind::kOutAndBack: {
      const Eigen::Vector2d far = start + config.line_length_m * u;
      segments_.push_back(std::make_unique<LineSegment>(start, far, 0.0, v, 0.0, a, alt, alt));
      segments_.push_back(std::make_unique<TurnSegment>(far, yaw0, -M_PI, turn_rate, alt));
      segments_.push_back(std::make_unique<LineSegment>(far, start, 0.0, v, 0.0, a, alt, alt));
      break;
    }
    case TrajectoryConfig::Kind::kWaypoints: {
      const auto& w = config.waypoints;
      double yaw = std::atan2(w[1].y_m - w[0].y_m, w[1].x_m - w[0].x_m);
      for (size_t i = 0; i + 1 < w.size(); ++i) {
        const Eigen::Vector2d p0(w[i].x_m, w[i].y_m), p1(w[i + 1].x_m, w[i + 1].y_m);
        if ((p1 - p0).norm() < 1e-6) continue;
        const double leg_yaw = std::atan2(p1.y() - p0.y(), p1.x() - p0.x());
        const double dyaw = wrapAngle(leg_yaw - yaw);
        const double alt0 = w[i].altitude_m > 0 ? w[i].altitude_m : alt;
        const double alt1 = w[i + 1].altitude_m > 0 ? w[i + 1].altitude_m : alt;
        if (std::abs(dyaw) > 1e-6 && i > 0) segments_.push_back(std::make_unique<TurnSegment>(p0, yaw, dyaw, turn_rate, alt0));
        const double leg_speed = w[i].speed_mps > 0 ? w[i].speed_mps : v;
        segments_.push_back(std::make_unique<LineSegment>(p0, p1, 0.0, leg_speed, 0.0, a, alt0, alt1));
        yaw = leg_yaw;
      }
      if (segments_.empty()) throw std::invalid_argument("trajectory.waypoints: all waypoints coincide");
      break;
    }
  }
  double t = 0.0;
  for (const auto& s : segments_) {
    segment_start_s_.push_back(t);
    t += s->duration_s();
    path_length_m_ += s->length_m();
  }
  duration_s_ = t;
}

VehicleTrajectory::Pose2D VehicleTrajectory::pathPose(double t) const {
  t = std::clamp(t, 0.0, duration_s_);
  size_t i = std::upper_bound(segment_start_s_.begin(), segment_start_s_.end(), t) - segment_start_s_.begin();
  i = i == 0 ? 0 : i - 1;
  Pose2D p;
  segments_[i]->at(t - segment_start_s_[i], &p.xy, &p.yaw_rad, &p.altitude_m);
  return p;
}

VehicleState VehicleTrajectory::exactState(double t) const {
  const Pose2D p = pathPose(t);
  const TrajectoryConfig& c = config_;
  VehicleState s;
  s.t_s = t;
  // Two incommensurate sinusoids so that the altitude does not repeat along a lawnmower.
  const double w_alt = 2 * M_PI / c.altitude_period_s;
  const double alt =
      p.altitude_m + c.altitude_variation_m * (0.6 * std::sin(w_alt * t) + 0.4 * std::sin(w_alt * 1.618 * t + 1.3));
  s.position_m = Eigen::Vector3d(p.xy.x(), p.xy.y(), alt);
  s.roll_rad = c.roll_amplitude_deg * kDegToRad * std::sin(2 * M_PI * t / c.roll_period_s);
  s.pitch_rad = c.pitch_amplitude_deg * kDegToRad * std::sin(2 * M_PI * t / c.pitch_period_s + 0.7);
  s.yaw_rad = wrapAngle(p.yaw_rad + c.yaw_oscillation_deg * kDegToRad * std::sin(2 * M_PI * t / c.yaw_period_s + 0.3));
  return s;
}

VehicleState VehicleTrajectory::stateAt(double t) const {
  t = std::clamp(t, 0.0, duration_s_);
  VehicleState s = exactState(t);
  const double h = 1e-3;
  const VehicleState a = exactState(t - h), b = exactState(t + h);  // exactState clamps to [0, duration]
  const double span = std::min(t + h, duration_s_) - std::max(t - h, 0.0);
  if (span > 0) {
    s.velocity_mps = (b.position_m - a.position_m) / span;
    s.acceleration_mps2 = (b.position_m - 2.0 * s.position_m + a.position_m) / (h * h);
    if (t - h < 0 || t + h > duration_s_) s.acceleration_mps2.setZero();
    const Eigen::AngleAxisd delta(a.rotation().transpose() * b.rotation());
    s.angular_velocity_rps = delta.axis() * delta.angle() / span;
  }
  return s;
}

}  // namespace sim
}  // namespace exocet_mosaic
