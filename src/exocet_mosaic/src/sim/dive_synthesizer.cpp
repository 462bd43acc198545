#include "exocet_mosaic/sim/dive_synthesizer.h"

#include <cmath>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <vector>

#include "exocet_common/geo_reference.h"
#include "exocet_common/ordered_work_pool.h"
#include "exocet_mosaic/sim/random.h"

namespace exocet_mosaic {
namespace sim {

namespace {
constexpr double kDegToRad = M_PI / 180.0;
}

Eigen::Isometry3d CameraRig::baseFromCamera() const {
  Eigen::Matrix3d down;
  // Columns: the camera's x, y, z axes in base_link. x = starboard (-y), y = aft (-x: image up is forward), z = down.
  down << 0, -1, 0, -1, 0, 0, 0, 0, -1;
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = down * rotationFromRpy(mounting_rpy_deg.x() * kDegToRad, mounting_rpy_deg.y() * kDegToRad,
                                      mounting_rpy_deg.z() * kDegToRad);
  T.translation() = lever_arm_m;
  return T;
}

std::string CameraRig::validate() const {
  std::ostringstream err;
  const std::string cam = camera.validate();
  if (!cam.empty()) err << cam << "; ";
  if (!(fps > 0.0 && fps <= 120.0)) err << "camera.fps = " << fps << " out of range (0, 120] frames/s; ";
  if (!SeabedRenderer::isSupportedEncoding(encoding))
    err << "camera.encoding '" << encoding << "' is not one of bgr8, rgb8, mono8, mono16, bayer_rggb8; ";
  for (int i = 0; i < 3; ++i) {
    if (!std::isfinite(lever_arm_m[i]) || std::abs(lever_arm_m[i]) > 10.0)
      err << "camera.lever_arm_m[" << i << "] = " << lever_arm_m[i] << " out of range [-10, 10] m; ";
    if (!std::isfinite(mounting_rpy_deg[i]) || std::abs(mounting_rpy_deg[i]) > 45.0)
      err << "camera.mounting_rpy_deg[" << i << "] = " << mounting_rpy_deg[i] << " out of range [-45, 45] deg; ";
  }
  if (!(drop_probability >= 0.0 && drop_probability <= 0.5))
    err << "camera.drop_probability = " << drop_probability << " out of range [0, 0.5]; ";
  std::string s = err.str();
  if (!s.empty()) s.resize(s.size() - 2);
  return s;
}

std::string DiveSynthesisConfig::validate() const {
  std::ostringstream err;
  auto add = [&](const std::string& s) {
    if (!s.empty()) err << s << "; ";
  };
  add(trajectory.validate());
  add(navigation.validate());
  add(imaging.validate());
  add(rig.validate());
  if (!(start_time_unix_s >= 0.0 && start_time_unix_s < 4102444800.0))
    err << "start_time_unix_s = " << start_time_unix_s << " out of range [0, 4102444800) s; ";
  if (!(duration_s >= 0.0 && duration_s <= 86400.0 * 3)) err << "duration_s = " << duration_s << " out of range [0, 259200] s; ";
  if (!(seabed_depth_m > trajectory.altitude_m && seabed_depth_m <= 11000.0))
    err << "seabed_depth_m = " << seabed_depth_m << " out of range (trajectory.altitude_m, 11000] m; ";
  if (!(ground_truth_rate_hz >= 1.0 && ground_truth_rate_hz <= 1000.0))
    err << "ground_truth_rate_hz = " << ground_truth_rate_hz << " out of range [1, 1000] Hz; ";
  if (threads < 1 || threads > 64) err << "threads = " << threads << " out of range [1, 64]; ";
  for (const Landmark& m : landmarks)
    if (!(m.size_m > 0.01 && m.size_m < 10.0))
      err << "landmarks[" << m.id << "].size_m = " << m.size_m << " out of range (0.01, 10) m; ";
  std::string s = err.str();
  if (!s.empty()) s.resize(s.size() - 2);
  return s;
}

double rayToSeabed_m(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction, const SeabedRelief& relief) {
  const Eigen::Vector3d d = direction.normalized();
  if (d.z() > -1e-3) return std::numeric_limits<double>::infinity();
  double t = origin.z() / -d.z();
  if (relief.isFlat()) return t;
  // Conservative marching from above the highest point (no overshoot for slopes under the bound).
  t = std::max(0.0, (origin.z() - relief.maxHeight_m()) / -d.z());
  const double denom = -d.z() + (relief.maxSlope() * 1.5 + 1e-3) * d.head<2>().norm();
  for (int i = 0; i < 2000; ++i) {
    const Eigen::Vector3d p = origin + t * d;
    const double f = p.z() - relief.heightAt_m(p.x(), p.y());
    if (f < 1e-7) break;
    t += f / denom;
  }
  return t;
}

std::vector<Landmark> landmarksAlongTrajectory(const VehicleTrajectory& trajectory, int count, double size_m,
                                               double lateral_offset_m) {
  std::vector<Landmark> marks;
  for (int i = 0; i < count; ++i) {
    const double t = trajectory.duration_s() * (i + 0.5) / count;
    const VehicleState s = trajectory.stateAt(t);
    const double side = (i % 2 == 0) ? 1.0 : -1.0;
    Landmark m;
    m.id = i;
    m.x_m = s.position_m.x() - side * lateral_offset_m * std::sin(s.yaw_rad);
    m.y_m = s.position_m.y() + side * lateral_offset_m * std::cos(s.yaw_rad);
    m.size_m = size_m;
    marks.push_back(m);
  }
  return marks;
}

DiveSynthesizer::DiveSynthesizer(const DiveSynthesisConfig& config, SeabedTexture* texture, SeabedRelief* relief)
    : config_(config),
      relief_(relief),
      trajectory_((config.validate().empty() ? config.trajectory
                                             : throw std::invalid_argument(config.validate()))),
      renderer_(config.rig.camera, config.imaging, texture, relief, config.landmarks, config.seed,
                config.trajectory.altitude_m - config.rig.lever_arm_m.z()),
      duration_s_(config.duration_s > 0.0 ? std::min(config.duration_s, trajectory_.duration_s())
                                          : trajectory_.duration_s()) {
  if (relief_->maxHeight_m() > config.trajectory.altitude_m * 0.8 - config.trajectory.altitude_variation_m)
    throw std::invalid_argument("trajectory.altitude_m = " + std::to_string(config.trajectory.altitude_m) +
                                " m is too low over this relief (highest point " +
                                std::to_string(relief_->maxHeight_m()) + " m above the reference plane)");
}

int DiveSynthesizer::frameCount() const { return static_cast<int>(std::floor(duration_s_ * config_.rig.fps + 1e-9)) + 1; }

Eigen::Vector3d DiveSynthesizer::toWorld(const Eigen::Vector3d& local) const {
  return {config_.geo.origin_easting_m + local.x(), config_.geo.origin_northing_m + local.y(),
          local.z() - config_.seabed_depth_m};
}

Eigen::Isometry3d DiveSynthesizer::cameraPoseLocal(double t_s) const {
  const VehicleState s = trajectory_.stateAt(t_s);
  Eigen::Isometry3d world_from_base = Eigen::Isometry3d::Identity();
  world_from_base.linear() = s.rotation();
  world_from_base.translation() = s.position_m;
  return world_from_base * config_.rig.baseFromCamera();
}

WorldRect DiveSynthesizer::footprintOnReferencePlane(double t_s) const {
  const Eigen::Isometry3d pose = cameraPoseLocal(t_s);
  const exocet_common::CameraModel& c = config_.rig.camera;
  WorldRect r{1e300, 1e300, -1e300, -1e300};
  for (const auto& px : {Eigen::Vector2d(0, 0), Eigen::Vector2d(c.width - 1, 0), Eigen::Vector2d(0, c.height - 1),
                         Eigen::Vector2d(c.width - 1, c.height - 1)}) {
    const Eigen::Vector2d xy = c.undistortNormalized(Eigen::Vector2d((px.x() - c.cx) / c.fx, (px.y() - c.cy) / c.fy));
    const Eigen::Vector3d d = pose.linear() * Eigen::Vector3d(xy.x(), xy.y(), 1.0);
    const double t = d.z() < -1e-6 ? pose.translation().z() / -d.z() : 1e6;
    const Eigen::Vector3d p = pose.translation() + t * d;
    r.x_min_m = std::min(r.x_min_m, p.x());
    r.x_max_m = std::max(r.x_max_m, p.x());
    r.y_min_m = std::min(r.y_min_m, p.y());
    r.y_max_m = std::max(r.y_max_m, p.y());
  }
  return r;
}

FrameTruth DiveSynthesizer::renderFrame(int k, bool dropped, const DiveSink& sink) const {
  const double t = k / config_.rig.fps;
  FrameTruth truth;
  truth.vehicle = trajectory_.stateAt(t);
  const Eigen::Isometry3d local = cameraPoseLocal(t);
  truth.world_from_camera = local;
  truth.world_from_camera.translation() = toWorld(local.translation());
  truth.camera_altitude_m = rayToSeabed_m(local.translation(), local.linear().col(2), *relief_);
  truth.ground_sample_distance_m = truth.camera_altitude_m / std::sqrt(config_.rig.camera.fx * config_.rig.camera.fy);
  const Eigen::Vector3d c = truth.world_from_camera.translation();
  truth.latlon_deg = exocet_common::gridToLatLon(config_.geo, c.x(), c.y());
  truth.frame.stamp_s = config_.start_time_unix_s + t;
  truth.frame.index = k;
  truth.frame.encoding = config_.rig.encoding;
  truth.dropped = dropped;
  if (!truth.dropped) {
    truth.frame.image = renderer_.render([this](double ts) { return cameraPoseLocal(ts); }, t, k, config_.rig.encoding);
    if (sink.prepare_frame) sink.prepare_frame(&truth);
  }
  return truth;
}

void DiveSynthesizer::run(const DiveSink& sink) {
  NavigationSensorSimulator nav(config_.navigation, config_.geo, config_.seabed_depth_m, config_.start_time_unix_s,
                                config_.seed, [this](double x, double y) { return relief_->heightAt_m(x, y); });
  const int frames = frameCount();
  // Lost frames drawn in frame order before any rendering: the draws cannot depend on which thread renders what.
  std::vector<char> dropped(static_cast<size_t>(frames), 0);
  RandomStream drops(config_.seed, 201);
  for (int k = 1; k < frames; ++k) dropped[static_cast<size_t>(k)] = drops.chance(config_.rig.drop_probability);
  long gt_ticks = -1;
  auto emit_ground_truth_until = [&](double t) {
    const long last = static_cast<long>(std::floor(t * config_.ground_truth_rate_hz + 1e-9));
    while (gt_ticks < last) {
      ++gt_ticks;
      if (sink.ground_truth) sink.ground_truth(nav.groundTruth(trajectory_.stateAt(gt_ticks / config_.ground_truth_rate_hz)));
    }
  };
  // Frames are rendered ahead on the workers (each frame a function of its index alone) while this thread emits
  // everything in time order; `ahead` bounds the frames held in memory.
  std::optional<exocet_common::OrderedWorkPool<FrameTruth>> pool;
  if (config_.threads > 1 && frames > 1)
    pool.emplace(frames, config_.threads, 2 * config_.threads,
                 [&](int k) { return renderFrame(k, dropped[static_cast<size_t>(k)], sink); });
  for (int k = 0; k < frames; ++k) {
    const double t = k / config_.rig.fps;
    nav.advanceTo(trajectory_, t, sink.navigation);
    emit_ground_truth_until(t);
    const FrameTruth truth = pool ? pool->take(k) : renderFrame(k, dropped[static_cast<size_t>(k)], sink);
    if (sink.frame) sink.frame(truth);
    if (sink.progress) sink.progress(k + 1, frames);
  }
  nav.advanceTo(trajectory_, duration_s_, sink.navigation);
  emit_ground_truth_until(duration_s_);
}

}  // namespace sim
}  // namespace exocet_mosaic
