#include "exocet_servo/trajectory/acquisition_planner.h"

#include <cmath>
#include <sstream>

#include <Eigen/Dense>

namespace exocet_servo {
namespace trajectory {

std::string AcquisitionPlanConfig::validate() const {
  std::ostringstream errors;
  auto check = [&errors](bool ok, const char* field, const std::string& range) {
    if (ok) return;
    if (errors.tellp() > 0) errors << "; ";
    errors << field << " must be in " << range;
  };
  check(object_height_m > 0.0 && object_height_m <= 100.0, "object_height_m", "(0, 100]");
  check(object_radius_m > 0.0 && object_radius_m <= 100.0, "object_radius_m", "(0, 100]");
  check(distance_m > object_radius_m && distance_m <= 100.0, "distance_m", "(object_radius_m, 100]");
  check(baseline_m > 0.0 && baseline_m < 2.0 * distance_m, "baseline_m", "(0, 2 * distance_m)");
  check(legs >= 1 && legs <= 100, "legs", "[1, 100]");
  check(leg_arc_rad > 0.0 && leg_arc_rad <= 2.0 * M_PI, "leg_arc_rad", "(0, 2 pi]");
  check(std::isfinite(start_azimuth_rad), "start_azimuth_rad", "finite values");
  check(std::isfinite(start_height_m) && std::isfinite(end_height_m), "start_height_m, end_height_m", "finite values");
  return errors.str();
}

Eigen::Isometry3d alignScrewWithAxis(const ScrewMotion& screw, const Eigen::Vector3d& axis_point_w,
                                     const Eigen::Vector3d& axis_direction_w, double azimuth_rad, double height_m) {
  // Frame of the screw in the left camera (origin on the axis, u towards the camera, w the axis) mapped onto the same
  // frame built around the world axis.
  Eigen::Isometry3d f_left = Eigen::Isometry3d::Identity();
  f_left.linear() << screw.u, screw.v, screw.axis;
  f_left.translation() = screw.axis_point;
  const Eigen::Vector3d w = axis_direction_w.normalized();
  // Azimuth measured from world x (or y when the axis is along x), counter-clockwise seen from above.
  Eigen::Vector3d ref = Eigen::Vector3d::UnitX() - w * w.x();
  if (ref.norm() < 1e-6) ref = Eigen::Vector3d::UnitY() - w * w.y();
  ref.normalize();
  const Eigen::Vector3d ref2 = Eigen::Vector3d::UnitZ().dot(w) >= 0.0 ? w.cross(ref) : ref.cross(w);
  // ref2 keeps the azimuth counter-clockwise about world +z whichever way w points.
  const Eigen::Vector3d u = std::cos(azimuth_rad) * ref + std::sin(azimuth_rad) * ref2;
  Eigen::Isometry3d f_world = Eigen::Isometry3d::Identity();
  f_world.linear() << u, w.cross(u), w;
  f_world.translation() = axis_point_w + height_m * w;
  return f_world * f_left.inverse();
}

namespace {

/// Finds pan and tilt such that the rig's screw has the radius and the pitch asked (2x2 Newton, numeric Jacobian).
bool solvePanTilt(double baseline_m, double radius_m, double pitch_m, double* pan_rad, double* tilt_rad) {
  RigGeometry rig;
  rig.baseline_m = baseline_m;
  rig.pan_rad = *pan_rad;
  rig.tilt_rad = *tilt_rad;
  auto residual = [&](double pan, double tilt) {
    RigGeometry r = rig;
    r.pan_rad = pan;
    r.tilt_rad = tilt;
    const ScrewMotion s = screwFromTransform(r.leftFromRight());
    return Eigen::Vector2d(s.radius_m - radius_m, s.pitch_per_step_m - pitch_m);
  };
  double pan = *pan_rad, tilt = *tilt_rad;
  for (int it = 0; it < 50; ++it) {
    const Eigen::Vector2d f = residual(pan, tilt);
    if (f.norm() < 1e-12) break;
    const double h = 1e-7;
    Eigen::Matrix2d j;
    j.col(0) = (residual(pan + h, tilt) - residual(pan - h, tilt)) / (2 * h);
    j.col(1) = (residual(pan, tilt + h) - residual(pan, tilt - h)) / (2 * h);
    if (std::abs(j.determinant()) < 1e-14) return false;
    Eigen::Vector2d step = j.partialPivLu().solve(-f);
    const double max_step = 0.1;  // rad: keep Newton in the basin of the toe-in solution
    if (step.cwiseAbs().maxCoeff() > max_step) step *= max_step / step.cwiseAbs().maxCoeff();
    pan += step(0);
    tilt += step(1);
  }
  if (residual(pan, tilt).norm() > 1e-9 || std::abs(pan) > M_PI / 2 || std::abs(tilt) > M_PI / 2) return false;
  *pan_rad = pan;
  *tilt_rad = tilt;
  return true;
}

}  // namespace

std::string planAcquisition(const AcquisitionPlanConfig& c, AcquisitionPlan* plan) {
  const std::string errors = c.validate();
  if (!errors.empty()) return "AcquisitionPlanConfig: " + errors;
  *plan = AcquisitionPlan();
  // Flat circle first: the chord between two camera centres is the baseline.
  const double angle = 2.0 * std::asin(c.baseline_m / (2.0 * c.distance_m));
  const int steps = std::max(1, static_cast<int>(std::lround(c.leg_arc_rad / angle)));
  const double rise = (c.end_height_m - c.start_height_m) / (c.legs * steps);
  double pan = angle, tilt = 0.0;
  // The pitch is signed along the screw axis; the axis of a toe-in rig points along the camera's -y (up) for even
  // legs. Solve once for a positive pitch; the mirror (-tilt) gives the opposite pitch with the same radius.
  if (!solvePanTilt(c.baseline_m, c.distance_m, std::abs(rise), &pan, &tilt)) {
    std::ostringstream msg;
    msg << "no rig geometry with baseline " << c.baseline_m << " m gives a radius of " << c.distance_m
        << " m and a rise of " << std::abs(rise) << " m per servoing";
    return msg.str();
  }
  plan->pan_rad = pan;
  plan->tilt_rad = std::abs(tilt);
  plan->rise_per_step_m = rise;
  plan->radius_m = c.distance_m;
  const Eigen::Vector3d up = Eigen::Vector3d::UnitZ();
  double azimuth = c.start_azimuth_rad;
  double height = c.start_height_m;
  for (int leg = 0; leg < c.legs; ++leg) {
    AcquisitionLeg l;
    l.direction = leg % 2 == 0 ? 1 : -1;
    l.rig.baseline_m = c.baseline_m;
    l.rig.pan_rad = pan;
    l.steps = steps;
    // Pick the tilt sign whose pitch, mapped on the world axis oriented by the leg's direction, rises as planned.
    for (double sign : {1.0, -1.0}) {
      l.rig.tilt_rad = sign * tilt;
      l.screw = screwFromTransform(l.rig.leftFromRight());
      if (l.screw.pitch_per_step_m * l.direction * (rise >= 0.0 ? 1.0 : -1.0) >= 0.0) break;
    }
    // The screw turns counter-clockwise about its axis: align the axis with +z for a counter-clockwise leg and with
    // -z for a clockwise one (the U-turn is this flip: a 180 deg roll of the rig).
    const Eigen::Vector3d axis_w = l.direction > 0 ? up : Eigen::Vector3d(-up);
    l.world_T_left_start = alignScrewWithAxis(l.screw, c.object_base_m, axis_w, azimuth, height * axis_w.z());
    plan->angle_per_step_rad = l.screw.angle_per_step_rad;
    const Eigen::Isometry3d t = l.rig.leftFromRight();
    Eigen::Isometry3d pose = l.world_T_left_start;
    for (int k = 0; k <= steps; ++k) {
      if (k > 0 || leg == 0) {
        plan->poses.push_back(pose);
        plan->pose_leg.push_back(leg);
      }
      if (k < steps) pose = pose * t;
    }
    azimuth += l.direction * steps * l.screw.angle_per_step_rad;
    height += steps * rise;
    plan->legs.push_back(l);
  }
  return "";
}

}  // namespace trajectory
}  // namespace exocet_servo
