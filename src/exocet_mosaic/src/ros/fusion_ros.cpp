#include "exocet_mosaic/ros/fusion_ros.h"

#include <cmath>
#include <filesystem>
#include <iomanip>
#include <sstream>
#include <stdexcept>

#include <geometry_msgs/TransformStamped.h>
#include <opencv2/imgproc.hpp>

#include "exocet_common/atomic_file.h"
#include "exocet_common/free_heap.h"
#include "exocet_common/json_file.h"
#include "exocet_common/unit_quaternion.h"
#include "exocet_mosaic/fusion/rts_smoother.h"
#include "exocet_mosaic/ros/image_message_decoder.h"

namespace exocet_mosaic {

using diagnostic_msgs::DiagnosticStatus;
namespace fu = fusion;

namespace {

/// A 2x2 covariance that is one: finite, symmetric enough, positive definite.
bool validCovariance(const Eigen::Matrix2d& c) {
  return c.allFinite() && c(0, 0) > 0.0 && c(1, 1) > 0.0 && c.determinant() > 0.0 &&
         std::abs(c(0, 1) - c(1, 0)) <= 1e-6 * (c(0, 0) + c(1, 1));
}

Eigen::Quaterniond toEigen(const geometry_msgs::Quaternion& q) { return Eigen::Quaterniond(q.w, q.x, q.y, q.z); }

/// A usable orientation (a zero quaternion means "no orientation").
bool validOrientation(const geometry_msgs::Quaternion& q) {
  return exocet_common::isUnitQuaternion(q.w, q.x, q.y, q.z);
}

/// ENU yaw (counter-clockwise from east) from a grid heading (clockwise from north).
double enuYawFromHeading_rad(double heading_rad) { return M_PI / 2.0 - heading_rad; }

}  // namespace

FusionRos::FusionRos(ros::NodeHandle nh, ros::NodeHandle private_nh)
    : nh_(nh),
      private_nh_(private_nh),
      config_(readFusionNodeConfig(private_nh)),
      tf_listener_(tf_buffer_),
      fused_path_(config_.path_min_spacing_m, config_.max_path_poses, config_.map_frame),
      nav_path_(config_.path_min_spacing_m, config_.max_path_poses, config_.map_frame),
      image_path_(config_.path_min_spacing_m, config_.max_path_poses, config_.map_frame) {
  for (const std::string& stale : removeStaleFusionScratch(private_nh.getNamespace()))
    ROS_INFO("fusion: removed %s, left by a fusion process that is gone", stale.c_str());
  fu::FusionFrontEndConfig front_end;
  front_end.filter = config_.filter;
  front_end.keep_log = config_.keep_smoother_log;
  if (config_.keep_smoother_log && !config_.smoother_log_file.empty()) {
    // A folder that cannot take the file must not stop the fusion: the log is then held in memory.
    std::FILE* probe = std::fopen(config_.smoother_log_file.c_str(), "ab");
    if (probe) {
      std::fclose(probe);
      front_end.log_file = config_.smoother_log_file;
    } else {
      ROS_ERROR(
          "fusion: ~smoother_log_file %s cannot be written (%s): the filter's steps are held in memory, which "
          "grows with the dive",
          config_.smoother_log_file.c_str(), std::strerror(errno));
      config_.smoother_log_file.clear();
    }
  }
  front_end.attitude_max_gap_s = config_.attitude_max_gap_s;
  front_end.altitude_max_gap_s = config_.altitude_max_gap_s;
  front_end.view_half_window_s = config_.view_half_window_s;
  front_end.altimeter_sigma_m = config_.altimeter_sigma_m;
  front_end.seabed_depth_m = config_.seabed_depth_m;
  front_end.base_frame = config_.base_frame;
  front_end.default_camera_frame = config_.camera_frame;
  front_end_ =
      std::make_unique<fu::FusionFrontEnd>(front_end, [this](const std::string& frame) { return mountOf(frame); });
  world_frame_ = config_.utm_frame;
  if (config_.utm_zone > 0) {
    grid_ = exocet_common::UtmGrid::fromZone(config_.utm_zone, config_.northern_hemisphere);
    grid_source_ = "parameter ~utm_zone";
  }

  auto subscribe = [this](ros::Subscriber* sub, const std::string& topic, int queue, auto callback) {
    if (!topic.empty()) *sub = nh_.subscribe(topic, queue, callback, this);
  };
  subscribe(&motion_sub_, config_.motion_topic, 200, &FusionRos::onMotion);
  subscribe(&odometry_sub_, config_.odometry_topic, 200, &FusionRos::onOdometry);
  subscribe(&nav_fix_sub_, config_.nav_fix_topic, 200, &FusionRos::onNavFix);
  subscribe(&usbl_sub_, config_.usbl_topic, 50, &FusionRos::onUsbl);
  // Deep enough for a replay at 16x while a callback (a key frame's image, a graph snapshot) holds the thread: an IMU
  // sample dropped from the queue is an image without attitude, so a gap in the pose graph's image odometry.
  subscribe(&imu_sub_, config_.imu_topic, 5000, &FusionRos::onImu);
  subscribe(&altitude_sub_, config_.altitude_topic, 200, &FusionRos::onAltitude);
  subscribe(&depth_sub_, config_.depth_topic, 200, &FusionRos::onDepth);  // used with ~seabed_depth_m
  // One camera_info per image announces it (its motion holds back the later inputs): as deep as the motions' queue,
  // or an image is missed when a replay's burst outruns the callbacks.
  subscribe(&camera_info_sub_, config_.camera_info_topic, 200, &FusionRos::onCameraInfo);
  subscribe(&datum_sub_, config_.datum_topic, 1, &FusionRos::onDatum);

  // Per subscriber link: one that lags (a fast replay on a loaded machine) must not silently lose poses or heights,
  // which the tile writer needs for every image.
  constexpr uint32_t kOutgoingQueue = 1000;
  odometry_pub_ = nh_.advertise<nav_msgs::Odometry>(config_.odometry_out_topic, kOutgoingQueue);
  fused_path_pub_ = nh_.advertise<nav_msgs::Path>(config_.path_topic, 1, true);
  nav_path_pub_ = nh_.advertise<nav_msgs::Path>(config_.navigation_path_topic, 1, true);
  image_path_pub_ = nh_.advertise<nav_msgs::Path>(config_.image_path_topic, 1, true);
  smoothed_path_pub_ = nh_.advertise<nav_msgs::Path>(config_.smoothed_path_topic, 1, true);
  if (config_.pose_graph) {
    graph_path_pub_ = nh_.advertise<nav_msgs::Path>(config_.graph_path_topic, 1, true);
    graph_odometry_pub_ = nh_.advertise<nav_msgs::Odometry>(config_.graph_odometry_topic, 100);
    graph_corrections_pub_ = nh_.advertise<exocet_msgs::PositionCorrections>(config_.graph_corrections_topic, 1, true);
    startGraph();
    if (config_.loop_closure) {
      graph::RecentImageBufferLimits recent;
      recent.max_bytes = static_cast<std::size_t>(config_.loop_image_buffer_mb * 1e6);
      recent_images_ = graph::RecentImageBuffer<sensor_msgs::CompressedImageConstPtr>(recent);
      loop_image_sub_ = nh_.subscribe(config_.loop_image_topic, 50, &FusionRos::onLoopImage, this);
    }
  }
  if (!config_.camera_height_topic.empty())
    camera_height_pub_ = nh_.advertise<sensor_msgs::Range>(config_.camera_height_topic, kOutgoingQueue);
  if (!config_.datum_out_topic.empty())
    datum_pub_ = nh_.advertise<exocet_msgs::GeoDatum>(config_.datum_out_topic, 1, true);
  initial_pose_srv_ = private_nh_.advertiseService("set_initial_pose", &FusionRos::onSetInitialPose, this);
  smooth_srv_ = private_nh_.advertiseService("smooth", &FusionRos::onSmooth, this);

  updater_.setHardwareID("navigation fusion");
  updater_.add("fusion", this, &FusionRos::diagnose);
  // Wall-clock timers: /diagnostics and the paths go on when a replay pauses or its clock jumps back.
  const double period_s = updater_.getPeriod() > 0.0 ? updater_.getPeriod() : 1.0;
  diagnostics_timer_ = nh_.createSteadyTimer(ros::WallDuration(period_s),
                                             [this](const ros::SteadyTimerEvent&) { updater_.force_update(); });
  // Hours of short-lived large buffers in several threads: their freed pages go back to the system.
  free_heap_timer_ = nh_.createSteadyTimer(ros::WallDuration(kFreeHeapPeriod_s),
                                           [](const ros::SteadyTimerEvent&) { exocet_common::releaseFreeHeap(); });
  path_timer_ = nh_.createSteadyTimer(ros::WallDuration(1.0 / config_.path_rate_hz),
                                      [this](const ros::SteadyTimerEvent&) { publishPaths(); });
  last_nav_wall_ = last_motion_wall_ = ros::WallTime::now();
  images_only_ = config_.odometry_topic.empty() && config_.nav_fix_topic.empty() && config_.usbl_topic.empty();
  initializeFromParameters();
  loadSavedState();
  if (config_.view_half_window_s > config_.reorder_delay_s)
    ROS_WARN(
        "fusion: ~view_half_window_s (%.2f s) is longer than ~reorder_delay_s (%.2f s): an image's view is fitted "
        "before its window's later samples arrive",
        config_.view_half_window_s, config_.reorder_delay_s);
  reconfigure_server_ =
      std::make_unique<dynamic_reconfigure::Server<exocet_mosaic::FusionConfig>>(reconfigure_mutex_, private_nh_);
  exocet_mosaic::FusionConfig start;
  start.gate_probability = front_end_->filter().config().gate_probability;
  start.recovery_rejections = front_end_->filter().config().recovery_rejections;
  reconfigure_server_->updateConfig(start);
  reconfigure_server_->setCallback([this](exocet_mosaic::FusionConfig& c, uint32_t level) { onReconfigure(c, level); });
  ROS_INFO("fusion: motion %s, dead reckoning %s, fixes %s, attitude %s, altitude %s; odometry on %s",
           config_.motion_topic.c_str(),
           (config_.odometry_topic.empty() ? config_.nav_fix_topic : config_.odometry_topic).c_str(),
           config_.usbl_topic.c_str(), config_.imu_topic.c_str(), config_.altitude_topic.c_str(),
           config_.odometry_out_topic.c_str());
}

FusionRos::~FusionRos() {
  writeTracks();
  saveState(true);
}

// ---------------------------------------------------------------------------------------------------------------
// Time, resets and bookkeeping.

bool FusionRos::admitStamp(const ros::Time& stamp, const std::string& what, bool late_allowed) {
  const double t = stamp.toSec();
  if (!std::isfinite(t) || stamp.isZero()) {
    rejectInput(what, "zero stamp");
    return false;
  }
  // A saved state is decided on at the first sensor input (a late fix may be stamped before the state and still
  // belong to the dive), before anything reaches the filter.
  if (saved_state_ && what != "fix") maybeResume(t);
  if (have_stamp_ && t < newest_stamp_s_ - config_.clock_jump_s) {
    // A new dive when the clock went back with the stamps (a bag played again with its clock), or when inputs keep
    // coming from before the newest one with none in order for kLateInputPatience_s (a source restarted without a
    // clock). Otherwise this input is late (its node starved of CPU, a replay faster than the chain): dropped, and
    // the dive's filter, graph and tracks stay.
    const double clock_s = ros::Time::now().toSec();
    const bool clock_back = clock_s > 0.0 && clock_s < newest_stamp_s_ - config_.clock_jump_s;
    const ros::WallTime wall_now = ros::WallTime::now();
    if (!late_since_) late_since_ = wall_now;
    std::ostringstream why;
    why << what << " stamped " << std::fixed << std::setprecision(3) << newest_stamp_s_ - t
        << " s before the newest input (more than ~clock_jump_s = " << config_.clock_jump_s << " s)";
    if (!clock_back && (wall_now - *late_since_).toSec() < kLateInputPatience_s) {
      ++late_inputs_;
      rejectInput(what, why.str() + ": late, dropped");
      return false;
    }
    why << (clock_back ? ": the clock jumped back (a bag played again?)"
                       : ": inputs from before the newest for " + std::to_string(kLateInputPatience_s) +
                             " s (a source restarted?)");
    late_since_.reset();
    resetAll(why.str());
  } else {
    late_since_.reset();
  }
  (void)late_allowed;
  if (!have_stamp_ || t > newest_stamp_s_) newest_stamp_s_ = t;
  have_stamp_ = true;
  return true;
}

void FusionRos::resetAll(const std::string& why) {
  ++resets_;
  last_problem_ = "reset: " + why;
  if (saved_state_) {
    resume_note_ = "not used: the clock jumped before the first input reached the filter";
    saved_state_.reset();
  }
  ROS_WARN_THROTTLE(1.0, "fusion: resetting the filter and the tracks: %s", why.c_str());
  front_end_->reset();
  if (graph_) startGraph();  // the graph of the dive so far ends with the clock it was built on
  have_stamp_ = false;
  newest_sample_stamps_.clear();
  awaiting_motion_.clear();
  newest_motion_stamp_s_ = -1e300;
  for (BoundedPath* path : {&fused_path_, &nav_path_, &image_path_}) path->clear();
  // The operator's first point stands for the dive (no navigation): take it again.
  initializeFromParameters();
}

void FusionRos::rejectInput(const std::string& kind, const std::string& why) {
  ++rejected_inputs_[kind];
  last_problem_ = kind + " rejected: " + why;
  // Throttled per kind of input: a bad attitude stream must not hide bad fixes.
  std::uint64_t held_back = 0;
  if (rejection_log_.allow(kind, &held_back))
    ROS_ERROR("fusion: %s rejected: %s%s", kind.c_str(), why.c_str(), rejection_log_.heldBackNote(held_back).c_str());
}

bool FusionRos::inStreamOrder(const std::string& kind, const ros::Time& stamp) {
  // Samples are interpolated between their neighbours: one stamped at or before the newest (sent twice, or going
  // back) is left out rather than allowed to reorder the history.
  const auto newest = newest_sample_stamps_.find(kind);
  if (newest != newest_sample_stamps_.end() && stamp <= newest->second) {
    std::ostringstream why;
    why << std::fixed << std::setprecision(3) << "stamped " << (newest->second - stamp).toSec()
        << " s before or at the previous sample's (a duplicated or backward stamp): out of order";
    rejectInput(kind, why.str());
    return false;
  }
  newest_sample_stamps_[kind] = stamp;
  return true;
}

void FusionRos::countResult(const std::string& kind, const fu::UpdateResult& result) {
  switch (result.status) {
    case fu::UpdateStatus::kApplied:
      ++applied_[kind];
      return;
    case fu::UpdateStatus::kRejectedByGate:
      ++gated_[kind];
      last_problem_ = kind + " rejected by the gate: " + result.detail;
      ROS_WARN_THROTTLE(2.0, "fusion: %s rejected by the Mahalanobis gate: %s", kind.c_str(), result.detail.c_str());
      return;
    case fu::UpdateStatus::kTooOld:
      ++too_old_[kind];
      last_problem_ = kind + " too old: " + result.detail;
      ROS_WARN_THROTTLE(2.0, "fusion: %s too old for the filter's history: %s", kind.c_str(), result.detail.c_str());
      return;
    case fu::UpdateStatus::kInvalid:
      ++invalid_[kind];
      last_problem_ = kind + " invalid: " + result.detail;
      ROS_ERROR_THROTTLE(2.0, "fusion: %s invalid: %s", kind.c_str(), result.detail.c_str());
      return;
    case fu::UpdateStatus::kNotInitialized:
      ROS_INFO_THROTTLE(5.0, "fusion: %s waiting for a first position (navigation, ~initial_* or ~set_initial_pose)",
                        kind.c_str());
      return;
  }
}

// ---------------------------------------------------------------------------------------------------------------
// Geography, mounts, attitude and height.

const exocet_common::UtmGrid* FusionRos::gridFor(double latitude_deg, double longitude_deg) {
  if (!grid_) {
    grid_ = exocet_common::UtmGrid::forLatLon(latitude_deg, longitude_deg);  // throws on a bad latitude/longitude
    grid_source_ = "the first latitude/longitude";
    ROS_INFO("fusion: UTM zone %s (EPSG %d) from %s", grid_->name().c_str(), grid_->epsg(), grid_source_.c_str());
  }
  return &*grid_;
}

std::optional<Eigen::Isometry3d> FusionRos::mountOf(const std::string& frame) {
  const auto known = mounts_.find(frame);
  if (known != mounts_.end()) return known->second;
  try {
    const geometry_msgs::TransformStamped t =
        tf_buffer_.lookupTransform(config_.base_frame, frame, ros::Time(0), ros::Duration(0.0));
    Eigen::Isometry3d base_from_frame = Eigen::Isometry3d::Identity();
    base_from_frame.translation() =
        Eigen::Vector3d(t.transform.translation.x, t.transform.translation.y, t.transform.translation.z);
    base_from_frame.linear() = toEigen(t.transform.rotation).normalized().toRotationMatrix();
    if (!base_from_frame.matrix().allFinite()) throw tf2::TransformException("non-finite transform");
    mounts_[frame] = base_from_frame;  // mounts are rigid: looked up once
    return base_from_frame;
  } catch (const tf2::TransformException& e) {
    last_problem_ = "no transform " + config_.base_frame + " -> " + frame + ": " + e.what();
    ROS_WARN_THROTTLE(5.0, "fusion: no transform %s -> %s yet (%s)", config_.base_frame.c_str(), frame.c_str(),
                      e.what());
    return std::nullopt;
  }
}

// ---------------------------------------------------------------------------------------------------------------
// Initialisation.

void FusionRos::onStarted(const std::string& source) {
  started_from_ = source;
  const fu::FilterState s = front_end_->filter().current();
  ensureMapOrigin(s.position_en_m);
  ROS_INFO("fusion: initialised from %s at E %.2f N %.2f (1-sigma %.2f m)", source.c_str(), s.position_en_m.x(),
           s.position_en_m.y(), std::sqrt(s.position_covariance_m2.trace() / 2.0));
}

void FusionRos::initializeFromParameters() {
  const FusionNodeConfig& c = config_;
  if (std::isfinite(c.initial_heading_deg))
    front_end_->setOperatorHeading(enuYawFromHeading_rad(c.initial_heading_deg * M_PI / 180.0));
  if (std::isfinite(c.initial_altitude_m)) front_end_->setOperatorHeight(c.initial_altitude_m);
  if (std::isfinite(c.initial_latitude_deg) && std::isfinite(c.initial_longitude_deg)) {
    front_end_->setOperatorStart(gridFor(c.initial_latitude_deg, c.initial_longitude_deg)
                                     ->toGrid(c.initial_latitude_deg, c.initial_longitude_deg),
                                 c.initial_sigma_m);
    operator_start_given_ = true;
  } else if (std::isfinite(c.initial_easting_m) && std::isfinite(c.initial_northing_m)) {
    front_end_->setOperatorStart(Eigen::Vector2d(c.initial_easting_m, c.initial_northing_m), c.initial_sigma_m);
    operator_start_given_ = true;
  }
}

void FusionRos::startInLocalFrame() {
  if (!local_world_) {
    world_frame_ = config_.map_frame;
    local_world_ = true;
    ROS_WARN(
        "fusion: no navigation and no first point (~initial_latitude_deg/~initial_longitude_deg, "
        "~initial_easting_m/~initial_northing_m or ~set_initial_pose): the track starts at (0, 0) in the local frame "
        "'%s' (metres; y points along the first heading, ~initial_heading_deg, 0 if unset) and the tiles are in that "
        "local frame, not geo-referenced",
        world_frame_.c_str());
  }
  // The images carry a heading on but need one to start from: the local frame's y axis if none is given.
  if (!front_end_->operatorHeading()) front_end_->setOperatorHeading(enuYawFromHeading_rad(0.0));
  front_end_->setOperatorStart(Eigen::Vector2d::Zero(), config_.initial_sigma_m);
}

void FusionRos::loadSavedState() {
  if (config_.state_file.empty()) return;
  std::error_code error;
  if (!std::filesystem::exists(config_.state_file, error)) {
    resume_note_ = "none saved";
    return;
  }
  const auto json = exocet_common::readJsonObjectFile<nlohmann::json>(config_.state_file);
  try {
    if (!json) throw std::invalid_argument("not a JSON object");
    saved_state_ = fu::savedFusionStateFromJson(*json);
  } catch (const std::exception& e) {
    resume_note_ = std::string("unreadable: ") + e.what();
    ROS_WARN("fusion: the state file %s cannot be read (%s): the filter starts afresh", config_.state_file.c_str(),
             e.what());
    return;
  }
  resume_note_ = "waiting for the first input";
  ROS_INFO(
      "fusion: %s holds a state saved at %.3f s: the filter resumes from it if the first input comes within %.0f s "
      "after it",
      config_.state_file.c_str(), saved_state_->stamp_s, config_.state_max_age_s);
}

void FusionRos::maybeResume(double first_stamp_s) {
  const fu::SavedFusionState saved = *saved_state_;
  saved_state_.reset();
  if (front_end_->filter().initialized()) {
    resume_note_ = "not used: the filter was started otherwise (" + started_from_ + ")";
    return;
  }
  std::string why = fu::resumeRefusal(saved.stamp_s, first_stamp_s, config_.state_max_age_s);
  const bool saved_in_utm = saved.frame == config_.utm_frame;
  if (why.empty() && saved_in_utm && saved.utm_zone > 0 && grid_ &&
      (grid_->zone() != saved.utm_zone || grid_->northern() != saved.northern_hemisphere))
    why = "it was saved in UTM zone " + std::to_string(saved.utm_zone) + ", the dive is in " + grid_->name();
  if (why.empty() && saved.frame != world_frame_ && (local_world_ || grid_ || saved_in_utm))
    why = "it was saved in the frame '" + saved.frame + "', the dive is in '" + world_frame_ + "'";
  if (!why.empty()) {
    resume_note_ = "not used: " + why;
    ROS_WARN("fusion: the state saved in %s is not used: %s; the filter starts afresh", config_.state_file.c_str(),
             why.c_str());
    return;
  }
  try {
    front_end_->resume(saved.stamp_s, saved.x, saved.P, saved.dr_offset_known);
  } catch (const std::invalid_argument& e) {
    resume_note_ = std::string("not used: ") + e.what();
    ROS_WARN("fusion: the state saved in %s is not used: %s", config_.state_file.c_str(), e.what());
    return;
  }
  if (!saved_in_utm && !local_world_) {
    world_frame_ = saved.frame;
    local_world_ = true;
  }
  if (saved_in_utm && !grid_ && saved.utm_zone > 0) {
    grid_ = exocet_common::UtmGrid::fromZone(saved.utm_zone, saved.northern_hemisphere);
    grid_source_ = "the saved state";
  }
  if (saved.operator_heading_rad) front_end_->setOperatorHeading(*saved.operator_heading_rad);
  if (saved.map_origin_en_m && !map_origin_en_m_) setMapOrigin(*saved.map_origin_en_m);
  std::ostringstream source;
  source << std::fixed << std::setprecision(1) << "the state saved " << first_stamp_s - saved.stamp_s
         << " s before the first input (a restart)";
  resume_note_ = "resumed from it";
  onStarted(source.str());
}

void FusionRos::saveState(bool now) {
  if (config_.state_file.empty() || !front_end_->filter().initialized()) return;
  const ros::SteadyTime wall = ros::SteadyTime::now();
  if (!now && state_saves_ + state_save_failures_ > 0 &&
      (wall - last_state_save_).toSec() < config_.state_save_period_s)
    return;
  last_state_save_ = wall;
  const fu::FilterState current = front_end_->filter().current();
  fu::SavedFusionState state;
  state.stamp_s = current.stamp_s;
  state.x = current.x;
  state.P = current.P;
  state.dr_offset_known = front_end_->filter().drOffsetKnown();
  state.frame = world_frame_;
  if (grid_ && !local_world_) {
    state.utm_zone = grid_->zone();
    state.northern_hemisphere = grid_->northern();
  }
  state.map_origin_en_m = map_origin_en_m_;
  state.operator_heading_rad = front_end_->operatorHeading();
  try {
    exocet_common::writeJsonFileAtomically(config_.state_file, fu::savedFusionStateToJson(state));
    ++state_saves_;
  } catch (const std::exception& e) {
    ++state_save_failures_;
    last_problem_ = std::string("state not saved: ") + e.what();
    ROS_WARN_THROTTLE(30.0, "fusion: the state is not saved (a restart would start blind): %s", e.what());
  }
}

bool FusionRos::onSetInitialPose(exocet_msgs::SetInitialPose::Request& request,
                                 exocet_msgs::SetInitialPose::Response& response) {
  std::ostringstream what;
  try {
    const bool latlon = std::isfinite(request.latitude_deg) && std::isfinite(request.longitude_deg);
    const bool grid = std::isfinite(request.easting_m) && std::isfinite(request.northing_m);
    if (latlon == grid)
      throw std::invalid_argument(
          "give either latitude_deg/longitude_deg or easting_m/northing_m (the other pair NaN)");
    if (latlon && local_world_)
      throw std::invalid_argument("the dive is mapped in the local frame '" + world_frame_ +
                                  "' (no datum or first point at its start): give easting_m/northing_m in that frame, "
                                  "or replay it with ~initial_latitude_deg/~initial_longitude_deg");
    if (!(request.position_sigma_m > 0.0 && request.position_sigma_m <= 10000.0))
      throw std::invalid_argument("position_sigma_m must be in (0, 10000] m");
    if (std::isfinite(request.heading_deg) && !(request.heading_deg >= -360.0 && request.heading_deg <= 360.0))
      throw std::invalid_argument("heading_deg must be in [-360, 360] or NaN");
    if (!std::isnan(request.altitude_m) && !(request.altitude_m > 0.0 && request.altitude_m <= 1000.0))
      throw std::invalid_argument("altitude_m must be in (0, 1000] m or NaN");
    const Eigen::Vector2d en =
        latlon
            ? gridFor(request.latitude_deg, request.longitude_deg)->toGrid(request.latitude_deg, request.longitude_deg)
            : Eigen::Vector2d(request.easting_m, request.northing_m);
    if (std::isfinite(request.heading_deg))
      front_end_->setOperatorHeading(enuYawFromHeading_rad(request.heading_deg * M_PI / 180.0));
    if (std::isfinite(request.altitude_m)) front_end_->setOperatorHeight(request.altitude_m);
    front_end_->setOperatorStart(en, request.position_sigma_m);
    operator_start_given_ = true;
    if (front_end_->filter().initialized()) {
      // Re-seeding during a dive: start again from the given point at the newest stamp.
      front_end_->filter().reset();
      front_end_->initialize(newest_stamp_s_, en, Eigen::Matrix2d::Identity() * std::pow(request.position_sigma_m, 2));
      onStarted("~set_initial_pose");
    }
    what << std::fixed << std::setprecision(2) << "position E " << en.x() << " N " << en.y() << " (1-sigma "
         << request.position_sigma_m << " m)";
    if (std::isfinite(request.heading_deg)) what << ", heading " << request.heading_deg << " deg";
    if (std::isfinite(request.altitude_m)) what << ", camera height " << request.altitude_m << " m";
    response.success = true;
    response.message = "set " + what.str();
    ROS_INFO("fusion: ~set_initial_pose: %s", response.message.c_str());
  } catch (const std::exception& e) {
    response.success = false;
    response.message = e.what();
    ROS_ERROR("fusion: ~set_initial_pose refused: %s", e.what());
  }
  return true;
}

// ---------------------------------------------------------------------------------------------------------------
// Stamp ordering.

void FusionRos::enqueue(double stamp_s, std::function<void()> apply) {
  queue_.emplace(stamp_s, std::move(apply));
  last_input_wall_ = ros::SteadyTime::now();
  release(false);
}

void FusionRos::release(bool everything) {
  // Images whose motion is overdue (dropped by the registration, or it stopped) hold nothing back any more.
  const ros::SteadyTime now = ros::SteadyTime::now();
  while (!awaiting_motion_.empty() &&
         (everything || (now - awaiting_motion_.begin()->second).toSec() > config_.motion_wait_s)) {
    if (!everything) ++motion_waits_timed_out_;
    awaiting_motion_.erase(awaiting_motion_.begin());
  }
  // An image's attitude is interpolated between samples: an input also waits for the attitude sample after it (its
  // topic may lag the others by more than the reorder delay when this thread is busy), unless the attitude has
  // stopped coming (kAttitudeWait_s beyond the delay).
  constexpr double kAttitudeWait_s = 1.0;
  const std::optional<double> attitude_s = front_end_->newestAttitudeStamp();
  auto due = [&](double stamp_s) {
    return stamp_s <= newest_stamp_s_ - config_.reorder_delay_s &&
           (awaiting_motion_.empty() || stamp_s < awaiting_motion_.begin()->first) &&
           (!attitude_s || stamp_s <= *attitude_s ||
            stamp_s <= newest_stamp_s_ - config_.reorder_delay_s - kAttitudeWait_s);
  };
  while (!queue_.empty() && (everything || due(queue_.begin()->first))) {
    auto apply = std::move(queue_.begin()->second);
    queue_.erase(queue_.begin());
    apply();
  }
}

// ---------------------------------------------------------------------------------------------------------------
// Inputs.

void FusionRos::onImu(const sensor_msgs::ImuConstPtr& msg) {
  if (!validOrientation(msg->orientation) || msg->orientation_covariance[0] < 0.0) {
    rejectInput("imu", "no valid orientation (NaN, not a unit quaternion, or orientation_covariance[0] = -1)");
    return;
  }
  if (!admitStamp(msg->header.stamp, "imu", false) || !inStreamOrder("imu", msg->header.stamp)) return;
  front_end_->addImuAttitude(msg->header.stamp.toSec(), toEigen(msg->orientation));
}

void FusionRos::onAltitude(const sensor_msgs::RangeConstPtr& msg) {
  const double r = msg->range;
  if (!std::isfinite(r) || r <= 0.0 || r < msg->min_range || r > msg->max_range) {
    std::ostringstream why;
    why << "range " << r << " m outside (" << msg->min_range << ", " << msg->max_range << "] m or not finite";
    rejectInput("altitude", why.str());
    return;
  }
  if (!admitStamp(msg->header.stamp, "altitude", false)) return;
  if (msg->header.frame_id.empty()) {
    rejectInput("altitude", "empty frame_id: the altimeter's mount on the vehicle is unknown");
    return;
  }
  if (!inStreamOrder("altitude", msg->header.stamp)) return;
  front_end_->addAltimeterRange(msg->header.stamp.toSec(), r, msg->header.frame_id);
}

void FusionRos::onDepth(const exocet_msgs::DepthConstPtr& msg) {
  if (!std::isfinite(msg->depth_m) || msg->depth_m < -100.0 || msg->depth_m > 12000.0) {
    rejectInput("depth", "depth " + std::to_string(msg->depth_m) + " m outside [-100, 12000] m or not finite");
    return;
  }
  if (!admitStamp(msg->header.stamp, "depth", false)) return;
  if (!inStreamOrder("depth", msg->header.stamp)) return;
  front_end_->addDepth(msg->header.stamp.toSec(), msg->depth_m);
}

void FusionRos::onCameraInfo(const sensor_msgs::CameraInfoConstPtr& msg) {
  Eigen::Matrix3d k;
  for (int i = 0; i < 9; ++i) k(i / 3, i % 3) = msg->K[i];
  if (!k.allFinite() || k(0, 0) <= 0.0 || k(1, 1) <= 0.0) {
    rejectInput("camera_info", "K has a non-positive or non-finite focal length");
    return;
  }
  front_end_->setCameraMatrix(k);
  if (!last_camera_matrix_) last_camera_matrix_ = k;  // the motions' K (of the undistorted images) takes over
  // An image is on its way through the registration: what follows it waits for its motion.
  const double t = msg->header.stamp.toSec();
  if (motion_seen_ && config_.motion_wait_s > 0.0 && !msg->header.stamp.isZero() && t > newest_motion_stamp_s_) {
    awaiting_motion_.emplace(t, ros::SteadyTime::now());
    while (awaiting_motion_.size() > 5000) awaiting_motion_.erase(awaiting_motion_.begin());  // bounded
  }
}

void FusionRos::onDatum(const exocet_msgs::GeoDatumConstPtr& msg) {
  if (config_.utm_zone > 0) return;  // the parameter wins
  try {
    exocet_common::UtmGrid grid = exocet_common::UtmGrid::fromZone(msg->utm_zone, msg->northern_hemisphere);
    if (!grid_ || grid_->zone() != grid.zone() || grid_->northern() != grid.northern()) {
      if (grid_ && front_end_->filter().initialized())
        ROS_WARN("fusion: /nav/datum gives zone %s, but %s was in use from %s: keeping it", grid.name().c_str(),
                 grid_->name().c_str(), grid_source_.c_str());
      else {
        grid_ = grid;
        grid_source_ = "the datum topic";
        ROS_INFO("fusion: UTM zone %s (EPSG %d) from %s", grid_->name().c_str(), grid_->epsg(), grid_source_.c_str());
      }
    }
  } catch (const std::invalid_argument& e) {
    rejectInput("datum", e.what());
  }
}

void FusionRos::onOdometry(const nav_msgs::OdometryConstPtr& msg) {
  const auto& p = msg->pose.pose.position;
  if (!std::isfinite(p.x) || !std::isfinite(p.y)) {
    rejectInput("dead reckoning", "position is not finite");
    return;
  }
  if (msg->header.frame_id != world_frame_) {
    if (grid_ || local_world_ || msg->header.frame_id.empty()) {
      rejectInput("dead reckoning", "frame '" + msg->header.frame_id + "', expected '" + world_frame_ + "' (" +
                                        (local_world_ ? "the dive's local frame" : "the UTM frame, ~utm_frame") + ")");
      return;
    }
    // Navigation in a local metric frame and nothing geo-referenced: the dive is mapped in that frame.
    world_frame_ = msg->header.frame_id;
    local_world_ = true;
    ROS_WARN(
        "fusion: dead reckoning in the local frame '%s' with no datum (/nav/datum), ~utm_zone or latitude / "
        "longitude: the fused track and the tiles are in that frame, not geo-referenced",
        world_frame_.c_str());
  }
  if (!admitStamp(msg->header.stamp, "dead reckoning", false)) return;
  Eigen::Matrix2d covariance;
  covariance << msg->pose.covariance[0], msg->pose.covariance[1], msg->pose.covariance[6], msg->pose.covariance[7];
  if (covariance.isZero()) covariance = Eigen::Matrix2d::Identity() * std::pow(config_.dead_reckoning_sigma_m, 2);
  std::optional<Eigen::Quaterniond> attitude;
  if (validOrientation(msg->pose.pose.orientation)) attitude = toEigen(msg->pose.pose.orientation).normalized();
  processDeadReckoning(msg->header.stamp, Eigen::Vector3d(p.x, p.y, p.z), attitude, covariance, msg->child_frame_id);
}

void FusionRos::onNavFix(const sensor_msgs::NavSatFixConstPtr& msg) {
  if (local_world_) {
    rejectInput("dead reckoning", "latitude / longitude in a dive mapped in the local frame '" + world_frame_ + "'");
    return;
  }
  if (!std::isfinite(msg->latitude) || !std::isfinite(msg->longitude) || std::abs(msg->latitude) > 90.0 ||
      msg->longitude < -180.0 || msg->longitude >= 360.0) {
    std::ostringstream why;
    why << "latitude " << msg->latitude << " / longitude " << msg->longitude
        << " outside [-90, 90] / [-180, 360) or not finite";
    rejectInput("dead reckoning", why.str());
    return;
  }
  if (!admitStamp(msg->header.stamp, "dead reckoning", false)) return;
  const Eigen::Vector2d en = gridFor(msg->latitude, msg->longitude)->toGrid(msg->latitude, msg->longitude);
  Eigen::Matrix2d covariance = Eigen::Matrix2d::Identity() * std::pow(config_.dead_reckoning_sigma_m, 2);
  if (msg->position_covariance_type != sensor_msgs::NavSatFix::COVARIANCE_TYPE_UNKNOWN)
    covariance << msg->position_covariance[0], msg->position_covariance[1], msg->position_covariance[3],
        msg->position_covariance[4];
  processDeadReckoning(msg->header.stamp, Eigen::Vector3d(en.x(), en.y(), msg->altitude), std::nullopt, covariance,
                       config_.base_frame);
}

void FusionRos::processDeadReckoning(const ros::Time& stamp, const Eigen::Vector3d& base_en_m,
                                     const std::optional<Eigen::Quaterniond>& world_from_base,
                                     const Eigen::Matrix2d& covariance_m2, const std::string& frame_id) {
  if (!validCovariance(covariance_m2)) {
    rejectInput("dead reckoning", "position covariance is not positive definite or not finite");
    return;
  }
  (void)frame_id;
  const double t = stamp.toSec();
  if (world_from_base) front_end_->addNavigationAttitude(t, *world_from_base);
  last_nav_wall_ = ros::WallTime::now();
  ++dead_reckonings_;
  enqueue(t, [this, t, base_en_m, covariance_m2, stamp]() {
    const fu::InputOutcome outcome = front_end_->addDeadReckoning(t, base_en_m, covariance_m2);
    if (outcome.camera_en_m) nav_path_.append(stamp, mapPosition(*outcome.camera_en_m));
    if (feeder_ && outcome.rejected.empty() && outcome.camera_en_m) {
      try {
        feeder_->addDeadReckoning(t, *outcome.camera_en_m, covariance_m2);
      } catch (const std::invalid_argument& e) {
        last_problem_ = std::string("pose graph: ") + e.what();
        ROS_WARN_THROTTLE(5.0, "fusion: pose graph: %s", e.what());
      }
    }
    handleOutcome("dead reckoning", outcome);
    // Without images the navigation carries the fused track: publish at its rate.
    if (outcome.update && (ros::WallTime::now() - last_motion_wall_).toSec() > 1.0) publishState(stamp);
  });
}

void FusionRos::onUsbl(const sensor_msgs::NavSatFixConstPtr& msg) {
  ++fixes_;
  if (local_world_) {
    rejectInput("fix", "a latitude / longitude fix in a dive mapped in the local frame '" + world_frame_ +
                           "' (no datum to place it)");
    return;
  }
  if (msg->status.status < sensor_msgs::NavSatStatus::STATUS_FIX) {
    rejectInput("fix", "status says no fix");
    return;
  }
  if (!std::isfinite(msg->latitude) || !std::isfinite(msg->longitude) || std::abs(msg->latitude) > 90.0 ||
      msg->longitude < -180.0 || msg->longitude >= 360.0) {
    std::ostringstream why;
    why << "latitude " << msg->latitude << " / longitude " << msg->longitude
        << " outside [-90, 90] / [-180, 360) or not finite";
    rejectInput("fix", why.str());
    return;
  }
  Eigen::Matrix2d covariance = Eigen::Matrix2d::Identity() * std::pow(config_.fix_sigma_m, 2);
  if (msg->position_covariance_type != sensor_msgs::NavSatFix::COVARIANCE_TYPE_UNKNOWN)
    covariance << msg->position_covariance[0], msg->position_covariance[1], msg->position_covariance[3],
        msg->position_covariance[4];
  if (!validCovariance(covariance)) {
    rejectInput("fix", "position covariance is not positive definite or not finite");
    return;
  }
  if (!admitStamp(msg->header.stamp, "fix", true)) return;
  last_nav_wall_ = ros::WallTime::now();
  const double t = msg->header.stamp.toSec();
  const Eigen::Vector2d fix_en = gridFor(msg->latitude, msg->longitude)->toGrid(msg->latitude, msg->longitude);
  const std::string frame = msg->header.frame_id;
  // With no dead reckoning expected, the first fix starts the filter.
  const bool may_start = config_.odometry_topic.empty() && config_.nav_fix_topic.empty();
  enqueue(t, [this, t, fix_en, covariance, frame, may_start]() {
    const fu::InputOutcome outcome = front_end_->addFix(t, fix_en, covariance, frame, may_start);
    // The fix of the camera, moved there by the mounts as the filter took it.
    if (feeder_ && outcome.rejected.empty() && outcome.camera_en_m)
      feeder_->addPositionFix(t, *outcome.camera_en_m, covariance);
    handleOutcome("fix", outcome);
  });
}

void FusionRos::onMotion(const exocet_msgs::ImageMotionConstPtr& msg) {
  if (!admitStamp(msg->header.stamp, "image motion", false)) return;
  if (msg->previous_stamp > msg->header.stamp || msg->previous_stamp.isZero()) {
    rejectInput("image motion", "previous_stamp is zero or after the stamp");
    return;
  }
  front_end_->setCameraFrame(msg->header.frame_id);
  last_motion_wall_ = ros::WallTime::now();
  ++motions_;
  motion_seen_ = true;
  const double t = msg->header.stamp.toSec();
  // The registration goes in image order: the images up to this one have their motion or never will.
  newest_motion_stamp_s_ = std::max(newest_motion_stamp_s_, t);
  awaiting_motion_.erase(awaiting_motion_.begin(), awaiting_motion_.upper_bound(t));
  const exocet_msgs::ImageMotion copy = *msg;
  enqueue(t, [this, copy]() { applyMotion(copy); });
}

void FusionRos::applyMotion(const exocet_msgs::ImageMotion& msg) {
  if (images_only_ && !operator_start_given_ && !front_end_->filter().initialized()) startInLocalFrame();
  fu::ImageMotionInput motion;
  motion.previous_stamp_s = msg.previous_stamp.toSec();
  motion.stamp_s = msg.header.stamp.toSec();
  motion.failed = msg.failed;
  motion.model = msg.model;
  motion.parameters = Eigen::Map<const Eigen::VectorXd>(msg.parameters.data(), Eigen::Index(msg.parameters.size()));
  // A covariance of the wrong size is passed on as it is: the front-end names the mismatch.
  const auto n = Eigen::Index(msg.parameters.size());
  if (n > 0 && Eigen::Index(msg.covariance.size()) == n * n)
    motion.covariance = Eigen::Map<const Eigen::Matrix<double, -1, -1, Eigen::RowMajor>>(msg.covariance.data(), n, n);
  else
    motion.covariance = Eigen::MatrixXd::Zero(0, 0);
  motion.centre_px = Eigen::Vector2d(msg.centre_px[0], msg.centre_px[1]);
  motion.pixel_matrix = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(msg.matrix.data());
  const Eigen::Matrix3d k = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(msg.camera_matrix.data());
  if (k(0, 0) > 0.0 && k(1, 1) > 0.0 && k.allFinite()) {
    motion.camera_matrix = k;
    last_camera_matrix_ = k;
  }

  const fu::InputOutcome outcome = front_end_->addImageMotion(motion);
  if (!outcome.started_from.empty()) onStarted(outcome.started_from);
  if (!outcome.rejected.empty()) rejectInput("image motion", outcome.rejected);
  if (!outcome.problem.empty()) {
    last_problem_ = outcome.problem;
    // Said once plainly (it usually asks for a setting), then repeated at most every 5 s.
    if (problems_told_.size() < 100 && problems_told_.insert(outcome.problem).second)
      ROS_ERROR("fusion: %s", outcome.problem.c_str());
    else
      ROS_WARN_THROTTLE(5.0, "fusion: %s", outcome.problem.c_str());
  }
  if (!outcome.update) return;  // refused before the filter
  const bool waiting = outcome.update->status == fu::UpdateStatus::kNotInitialized;
  if (feeder_ && !waiting) feedGraph(msg.header.stamp.toSec(), outcome);
  // A pair without a metric motion reaches the filter as an image failure: its time passes, its covariance grows.
  if (!outcome.metric && !waiting) ++motion_failures_;
  countResult(outcome.metric || waiting ? "image motion" : "image failure", *outcome.update);
  if (waiting) return;
  if (outcome.metric && outcome.camera_en_m) image_path_.append(msg.header.stamp, mapPosition(*outcome.camera_en_m));
  publishState(msg.header.stamp);
}

void FusionRos::handleOutcome(const std::string& kind, const fu::InputOutcome& outcome) {
  if (!outcome.started_from.empty()) onStarted(outcome.started_from);
  if (!outcome.rejected.empty()) rejectInput(kind, outcome.rejected);
  if (!outcome.problem.empty()) {
    last_problem_ = outcome.problem;
    ROS_WARN_THROTTLE(5.0, "fusion: %s", outcome.problem.c_str());
  }
  if (outcome.update) countResult(kind, *outcome.update);
}

// ---------------------------------------------------------------------------------------------------------------
// Outputs.

void FusionRos::ensureMapOrigin(const Eigen::Vector2d& en_m) {
  if (map_origin_en_m_) return;
  const double g = config_.map_origin_grid_m;
  // A local frame keeps its own origin: rviz's single precision is not at stake there.
  setMapOrigin(local_world_ ? Eigen::Vector2d::Zero()
                            : Eigen::Vector2d(std::round(en_m.x() / g) * g, std::round(en_m.y() / g) * g));
}

void FusionRos::setMapOrigin(const Eigen::Vector2d& origin_en_m) {
  map_origin_en_m_ = origin_en_m;
  if (!config_.publish_tf || config_.map_frame == world_frame_) return;
  geometry_msgs::TransformStamped t;
  t.header.stamp = ros::Time::now();
  t.header.frame_id = world_frame_;
  t.child_frame_id = config_.map_frame;
  t.transform.translation.x = map_origin_en_m_->x();
  t.transform.translation.y = map_origin_en_m_->y();
  t.transform.rotation.w = 1.0;
  static_broadcaster_.sendTransform(t);
}

Eigen::Vector2d FusionRos::mapPosition(const Eigen::Vector2d& en_m) {
  ensureMapOrigin(en_m);
  return en_m - *map_origin_en_m_;
}

void FusionRos::publishState(const ros::Time& stamp) {
  // When the images stop the navigation carries the track, and its stamps can be an image's already published.
  if (!front_end_->filter().initialized() || stamp == last_published_stamp_) return;
  last_published_stamp_ = stamp;
  // At the input's stamp: a late image motion is processed after newer inputs (the filter's latest step is theirs).
  const fu::FilterState s = front_end_->filter().stateAt(stamp.toSec());
  std::optional<Eigen::Quaterniond> attitude = front_end_->attitudeAt(stamp.toSec());
  // No attitude sensor: the operator's heading as the images carried it on, the vehicle level, as the front end
  // takes it for the motions; the camera height and the tiles' orientation need it.
  if (!attitude && front_end_->operatorHeading())
    attitude = Eigen::Quaterniond(Eigen::AngleAxisd(*front_end_->operatorHeading(), Eigen::Vector3d::UnitZ()));
  const auto camera = front_end_->cameraMount();

  nav_msgs::Odometry odometry;
  odometry.header.stamp = stamp;
  odometry.header.frame_id = world_frame_;
  odometry.child_frame_id = config_.fused_camera_frame;
  odometry.pose.pose.position.x = s.position_en_m.x();
  odometry.pose.pose.position.y = s.position_en_m.y();
  Eigen::Quaterniond world_from_camera = Eigen::Quaterniond::Identity();
  if (attitude && camera) world_from_camera = *attitude * Eigen::Quaterniond(camera->linear());
  odometry.pose.pose.orientation.w = world_from_camera.w();
  odometry.pose.pose.orientation.x = world_from_camera.x();
  odometry.pose.pose.orientation.y = world_from_camera.y();
  odometry.pose.pose.orientation.z = world_from_camera.z();
  auto& c = odometry.pose.covariance;
  c[0] = s.position_covariance_m2(0, 0);
  c[1] = s.position_covariance_m2(0, 1);
  c[6] = s.position_covariance_m2(1, 0);
  c[7] = s.position_covariance_m2(1, 1);
  c[14] = 1e6;  // height is not estimated here
  const double attitude_variance = (attitude && camera) ? 1e-4 : 1e6;
  c[21] = c[28] = c[35] = attitude_variance;
  odometry_pub_.publish(odometry);
  if (graph_odometry_pub_) {
    // Where the graph puts this image: the filter's state moved by the graph's latest correction before it.
    nav_msgs::Odometry moved = odometry;
    const Eigen::Vector2d correction = graphCorrectionAt(stamp.toSec()).value_or(Eigen::Vector2d::Zero());
    moved.pose.pose.position.x += correction.x();
    moved.pose.pose.position.y += correction.y();
    graph_odometry_pub_.publish(moved);
  }
  fused_path_.append(stamp, mapPosition(s.position_en_m));
  publishDatum();
  if (camera_height_pub_ && attitude && camera) {
    if (const auto height_m = front_end_->cameraHeightAt(stamp.toSec(), *attitude, *camera)) {
      sensor_msgs::Range range;
      range.header.stamp = stamp;
      range.header.frame_id = front_end_->cameraFrame();
      range.radiation_type = sensor_msgs::Range::ULTRASOUND;
      range.min_range = 0.0f;
      range.max_range = 1000.0f;
      range.range = static_cast<float>(*height_m);  // vertical height of the camera above the seabed (m)
      camera_height_pub_.publish(range);
    }
  }

  if (config_.publish_tf && map_origin_en_m_) {
    geometry_msgs::TransformStamped t;
    t.header = odometry.header;
    t.header.frame_id = config_.map_frame;
    t.child_frame_id = config_.fused_camera_frame;
    t.transform.translation.x = s.position_en_m.x() - map_origin_en_m_->x();
    t.transform.translation.y = s.position_en_m.y() - map_origin_en_m_->y();
    t.transform.rotation = odometry.pose.pose.orientation;
    tf_broadcaster_.sendTransform(t);
  }
  saveState(false);
}

void FusionRos::publishDatum() {
  if (!datum_pub_ || !grid_ || local_world_) return;  // a local frame has no zone
  const int key = grid_->zone() * 2 + (grid_->northern() ? 1 : 0);
  if (key == published_datum_zone_ && published_datum_has_origin_ == map_origin_en_m_.has_value()) return;
  exocet_msgs::GeoDatum datum;
  datum.header.stamp = ros::Time::now();
  datum.frame_id = config_.utm_frame;
  datum.utm_zone = grid_->zone();
  datum.northern_hemisphere = grid_->northern();
  datum.epsg = grid_->epsg();
  if (map_origin_en_m_) {
    datum.origin_easting_m = map_origin_en_m_->x();
    datum.origin_northing_m = map_origin_en_m_->y();
    const Eigen::Vector2d lat_lon = grid_->toLatLon(map_origin_en_m_->x(), map_origin_en_m_->y());
    datum.origin_latitude_deg = lat_lon.x();
    datum.origin_longitude_deg = lat_lon.y();
  }
  datum_pub_.publish(datum);
  published_datum_zone_ = key;
  published_datum_has_origin_ = map_origin_en_m_.has_value();
}

void FusionRos::publishPaths() {
  // The inputs stopped (end of a bag, a pause): what waits for newer inputs goes to the filter now.
  if (!queue_.empty() && (ros::SteadyTime::now() - last_input_wall_).toSec() > std::max(0.5, config_.reorder_delay_s))
    release(true);
  const ros::Time now = ros::Time::now();
  for (auto [path, pub] : {std::make_pair(&fused_path_, &fused_path_pub_), std::make_pair(&nav_path_, &nav_path_pub_),
                           std::make_pair(&image_path_, &image_path_pub_)}) {
    if (path->path().poses.empty()) continue;
    if (path->path().header.stamp.isZero()) {
      nav_msgs::Path stamped = path->path();
      stamped.header.stamp = now;
      pub->publish(stamped);
    } else {
      pub->publish(path->path());
    }
  }
  if (graph_) publishGraphPath();
}

void FusionRos::startGraph() {
  loop_closer_.reset();  // stops its worker before the graph it feeds goes
  if (graph_) graph_->stop();
  graph::BackgroundPoseGraphConfig graph_config;
  graph_config.marginals_duty_cycle = config_.graph_marginals_duty_cycle;
  graph_ = std::make_unique<graph::BackgroundPoseGraph>(graph_config);
  // The dead reckoning's relative error as the filter models it.
  graph::KeyFrameFeederConfig feeder_config;
  const fusion::FilterConfig& filter_config = front_end_->filter().config();
  feeder_config.dr_measurement_sigma_m = filter_config.dr_measurement_sigma_m;
  feeder_config.dr_noise_m2_per_m = filter_config.dr_offset_noise_m2_per_m;
  feeder_config.dr_noise_m2_per_s = filter_config.dr_offset_noise_m2_per_s;
  feeder_ = std::make_unique<graph::KeyFrameFeeder>(feeder_config, graph_.get());
  if (config_.loop_closure) {
    graph::LoopCloserConfig loop_config;
    loop_config.image_folder = config_.loop_image_folder;
    loop_closer_ = std::make_unique<graph::LoopCloser>(loop_config, graph_.get());
  }
  graph_last_yaw_rad_.reset();
  key_frame_filter_en_m_.clear();
}

std::optional<Eigen::Vector2d> FusionRos::graphCorrectionAt(double stamp_s) const {
  if (!graph_) return std::nullopt;
  const std::shared_ptr<const graph::GraphSnapshot> snapshot = graph_->snapshot();
  if (!snapshot) return std::nullopt;
  for (auto k = snapshot->key_frames.rbegin(); k != snapshot->key_frames.rend(); ++k) {
    if (k->stamp_s > stamp_s + 1e-6) continue;
    const auto filter = key_frame_filter_en_m_.find(k->id);
    if (filter == key_frame_filter_en_m_.end()) return std::nullopt;
    return Eigen::Vector2d(k->pose.position_en_m - filter->second);
  }
  return std::nullopt;
}

void FusionRos::onLoopImage(const sensor_msgs::CompressedImageConstPtr& msg) {
  // Only the images of the last seconds: the feeder makes a key frame when the image's motion arrives.
  recent_images_.add(msg->header.stamp.toSec(), msg, msg->data.size());
}

void FusionRos::offerKeyFrame(int64_t id, double stamp_s, const std::optional<Eigen::Quaterniond>& attitude,
                              double yaw_rad) {
  const std::optional<sensor_msgs::CompressedImageConstPtr> image = recent_images_.find(stamp_s);
  const auto camera = front_end_->cameraMount();
  if (!image || !camera || !last_camera_matrix_) {
    ++loop_images_missing_;
    return;
  }
  DecodedImage decoded;
  const std::string error = decodeCompressedImage(**image, &decoded, DecodeMode::kGreyIfJpeg);
  if (!error.empty() || decoded.image.empty()) {
    ++loop_images_missing_;
    return;
  }
  cv::Mat gray = decoded.image;
  if (gray.channels() == 3) cv::cvtColor(gray, gray, cv::COLOR_BGR2GRAY);
  if (gray.depth() != CV_8U) gray.convertTo(gray, CV_8U, 1.0 / 256.0);
  const Eigen::Quaterniond world_from_base =
      attitude.value_or(Eigen::Quaterniond(Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ())));
  const std::optional<double> height_m = front_end_->cameraHeightAt(stamp_s, world_from_base, *camera);
  if (!height_m) {
    ++loop_images_missing_;
    return;
  }
  const Eigen::Matrix3d& k = *last_camera_matrix_;
  graph::LoopCloserKeyFrame kf;
  kf.key_frame.id = id;
  kf.key_frame.stamp_s = stamp_s;
  kf.key_frame.pose = feeder_->keyFrames().back().initial;
  kf.key_frame.position_cov_m2 = front_end_->filter().stateAt(stamp_s).position_covariance_m2;
  kf.key_frame.yaw_sigma_rad = attitude ? 0.02 : 0.1;
  kf.key_frame.camera_height_m = *height_m;
  kf.key_frame.camera.fx_px = k(0, 0);
  kf.key_frame.camera.fy_px = k(1, 1);
  kf.key_frame.camera.cx_px = k(0, 2);
  kf.key_frame.camera.cy_px = k(1, 2);
  kf.key_frame.camera.width_px = gray.cols;
  kf.key_frame.camera.height_px = gray.rows;
  kf.view.camera_matrix = k;
  kf.view.image_size = gray.size();
  kf.view.camera_height_m = *height_m;
  kf.view.camera_height_sigma_m = 0.05;
  // The camera in the key frame's level frame (x along its yaw, y left, z up): the attitude without the yaw.
  kf.view.level_from_camera =
      (Eigen::AngleAxisd(-yaw_rad, Eigen::Vector3d::UnitZ()) * world_from_base * Eigen::Quaterniond(camera->linear()))
          .normalized();
  kf.view.tilt_sigma_rad = attitude ? 0.005 : 0.03;
  kf.gray = gray;
  try {
    loop_closer_->addKeyFrame(kf);
  } catch (const std::invalid_argument& e) {
    ++loop_images_missing_;
    ROS_WARN_THROTTLE(5.0, "fusion: loop closure: %s", e.what());
  }
}

void FusionRos::feedGraph(double stamp_s, const fu::InputOutcome& outcome) {
  // The key frame's yaw: the attitude sensor's, else the operator's heading as the images carried it on.
  const std::optional<Eigen::Quaterniond> attitude = front_end_->attitudeAt(stamp_s);
  std::optional<double> yaw_rad;
  if (attitude) {
    const Eigen::Matrix3d r = attitude->toRotationMatrix();
    yaw_rad = std::atan2(r(1, 0), r(0, 0));
  } else if (front_end_->operatorHeading()) {
    yaw_rad = *front_end_->operatorHeading();
  }
  if (!yaw_rad || !front_end_->filter().initialized()) return;
  try {
    // The filter at the key frame's stamp, not at its latest step: a motion that arrived late (after a burst, or
    // after release(true) let newer navigation through) is applied behind newer inputs, and the filter's latest
    // position would be taken for the key frame's (the graph corrections then spike by the lag times the speed).
    const fu::FilterState state = front_end_->filter().stateAt(stamp_s);
    std::optional<int64_t> key_frame;
    if (!feeder_->started()) {
      key_frame = feeder_->start(stamp_s, state.position_en_m, *yaw_rad);
      // Without dead reckoning (which anchors the graph itself, KeyFrameFeeder::addDeadReckoning), what the filter
      // knew when the graph started (the operator's start): without it the graph's absolute position rests on its
      // first few fixes alone. Not robust: at the USBL's Cauchy scale a start that the fixes' average
      // (0.5 m / sqrt(n)) puts a few of its sigmas away would read as an outlier and lose its hold.
      if (dead_reckonings_ == 0)
        feeder_->addPositionFix(stamp_s, state.position_en_m, state.position_covariance_m2, false);
    } else if (outcome.metric) {
      const double yaw_change = graph::wrapAngle(*yaw_rad - graph_last_yaw_rad_.value_or(*yaw_rad));
      key_frame = feeder_->addImageMotion(stamp_s, outcome.metric->camera_displacement_en_m,
                                          outcome.metric->covariance_m2, yaw_change, attitude ? yaw_rad : std::nullopt);
    } else {
      // The fused displacement since the last key frame (the fused position there, not the graph's).
      const graph::FeederKeyFrame& last = feeder_->keyFrames().back();
      const auto last_fused = key_frame_filter_en_m_.find(last.id);
      const Eigen::Vector2d from =
          last_fused != key_frame_filter_en_m_.end() ? last_fused->second : last.initial.position_en_m;
      key_frame = feeder_->addImageFailure(stamp_s, state.position_en_m - from, *yaw_rad);
      ++graph_navigation_ties_;
    }
    graph_last_yaw_rad_ = yaw_rad;
    if (key_frame) key_frame_filter_en_m_[*key_frame] = state.position_en_m;
    if (key_frame && loop_closer_) offerKeyFrame(*key_frame, stamp_s, attitude, *yaw_rad);
  } catch (const std::invalid_argument& e) {
    // An input the graph refuses is left out of it; the filter goes on.
    last_problem_ = std::string("pose graph: ") + e.what();
    ROS_WARN_THROTTLE(5.0, "fusion: pose graph: %s", e.what());
  }
}

void FusionRos::publishGraphPath() {
  const std::shared_ptr<const graph::GraphSnapshot> snapshot = graph_->snapshot();
  if (!snapshot || snapshot->key_frames.empty() || !map_origin_en_m_) return;
  // In the map frame, as the other paths.
  nav_msgs::Path path;
  path.header.frame_id = config_.map_frame;
  for (const graph::KeyFramePose& k : snapshot->key_frames) {
    geometry_msgs::PoseStamped p;
    p.header.frame_id = config_.map_frame;
    p.header.stamp.fromSec(k.stamp_s);
    p.pose.position.x = k.pose.position_en_m.x() - map_origin_en_m_->x();
    p.pose.position.y = k.pose.position_en_m.y() - map_origin_en_m_->y();
    p.pose.orientation.z = std::sin(0.5 * k.pose.yaw_rad);
    p.pose.orientation.w = std::cos(0.5 * k.pose.yaw_rad);
    path.poses.push_back(p);
  }
  path.header.stamp = path.poses.back().header.stamp;
  graph_path_pub_.publish(path);

  // The corrections, once per solve: the tile writer redraws the tiles whose images they move.
  if (snapshot == last_corrections_snapshot_) return;
  exocet_msgs::PositionCorrections corrections;
  corrections.header.frame_id = world_frame_;
  const bool with_sigmas = snapshot->position_covariance_m2.size() == snapshot->key_frames.size();
  for (std::size_t i = 0; i < snapshot->key_frames.size(); ++i) {
    const graph::KeyFramePose& k = snapshot->key_frames[i];
    const auto filter = key_frame_filter_en_m_.find(k.id);
    if (filter == key_frame_filter_en_m_.end()) continue;
    ros::Time stamp;
    stamp.fromSec(k.stamp_s);
    corrections.stamps.push_back(stamp);
    corrections.east_m.push_back(k.pose.position_en_m.x() - filter->second.x());
    corrections.north_m.push_back(k.pose.position_en_m.y() - filter->second.y());
    if (with_sigmas) {
      const Eigen::Matrix2d& c = snapshot->position_covariance_m2[i];  // NaN for a key frame newer than the marginals
      const double sigma_e = std::sqrt(c(0, 0)), sigma_n = std::sqrt(c(1, 1));
      corrections.east_sigma_m.push_back(sigma_e);
      corrections.north_sigma_m.push_back(sigma_n);
      corrections.east_north_correlation.push_back(c(0, 1) / (sigma_e * sigma_n));
    }
  }
  if (corrections.stamps.empty()) return;
  corrections.header.stamp = corrections.stamps.back();
  graph_corrections_pub_.publish(corrections);
  last_corrections_snapshot_ = snapshot;
}

bool FusionRos::onSmooth(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& response) {
  release(true);
  if (!config_.keep_smoother_log) {
    response.success = false;
    response.message = "~keep_smoother_log is false: the dive was not kept for smoothing";
    return true;
  }
  std::vector<fu::FilterState> smoothed;
  try {
    smoothed = fu::smoothRts(front_end_->filter().wholeLog());
  } catch (const std::exception& e) {
    response.success = false;
    response.message = std::string("the dive's filter steps cannot be read back: ") + e.what();
    return true;
  }
  if (smoothed.empty()) {
    response.success = false;
    response.message = "nothing to smooth yet";
    return true;
  }
  // Every smoothed state: asked for once, and published at once.
  BoundedPath path(0.0, std::max<int>(3, static_cast<int>(smoothed.size())), config_.map_frame);
  for (const fu::FilterState& s : smoothed) path.append(ros::Time(s.stamp_s), mapPosition(s.position_en_m));
  smoothed_path_pub_.publish(path.path());
  response.success = true;
  response.message = "smoothed " + std::to_string(smoothed.size()) + " states";
  return true;
}

namespace {
std::string trackCsv(const std::vector<fu::FilterState>& states) {
  std::ostringstream out;
  out << "stamp_s,easting_m,northing_m,sigma_easting_m,sigma_northing_m,covariance_en_m2,pixel_size_correction,"
         "pixel_size_correction_sigma\n";
  out << std::fixed;
  for (const fu::FilterState& s : states) {
    out << std::setprecision(6) << s.stamp_s << ',' << std::setprecision(4) << s.position_en_m.x() << ','
        << s.position_en_m.y() << ',' << std::sqrt(s.position_covariance_m2(0, 0)) << ','
        << std::sqrt(s.position_covariance_m2(1, 1)) << ',' << std::setprecision(6) << s.position_covariance_m2(0, 1)
        << ',' << s.pixel_size_correction << ',' << s.pixel_size_correction_sigma << '\n';
  }
  return out.str();
}
}  // namespace

void FusionRos::writeTracks() {
  release(true);
  if (graph_ && feeder_) {
    const std::shared_ptr<const graph::GraphSnapshot> snapshot = graph_->snapshot();
    int accepted = 0;
    if (snapshot)
      for (char a : snapshot->loop_accepted) accepted += a;
    ROS_INFO("fusion: pose graph: %zu key frames (%lld tied by the navigation, no image odometry), %d loops accepted",
             feeder_->keyFrames().size(), static_cast<long long>(graph_navigation_ties_), accepted);
  }
  if (config_.track_csv.empty() && config_.smoothed_track_csv.empty()) return;
  if (!config_.keep_smoother_log) {
    ROS_ERROR("fusion: ~track_csv / ~smoothed_track_csv need ~keep_smoother_log: nothing written");
    return;
  }
  try {
    const fu::FilterLog log = front_end_->filter().wholeLog();
    std::vector<fu::FilterState> filtered;
    for (const fu::FilterStep& step : log.steps)
      filtered.push_back(fu::FilterState::from(step.stamp_s, step.x_posterior, step.P_posterior));
    if (!config_.track_csv.empty()) exocet_common::writeFileAtomically(config_.track_csv, trackCsv(filtered));
    if (!config_.smoothed_track_csv.empty())
      exocet_common::writeFileAtomically(config_.smoothed_track_csv, trackCsv(fu::smoothRts(log)));
    ROS_INFO("fusion: wrote %zu states to %s %s", filtered.size(), config_.track_csv.c_str(),
             config_.smoothed_track_csv.c_str());
  } catch (const std::exception& e) {
    ROS_ERROR("fusion: could not write the tracks: %s", e.what());
  }
}

void FusionRos::onReconfigure(exocet_mosaic::FusionConfig& c, uint32_t) {
  const fusion::FilterConfig now = front_end_->filter().config();
  if (c.gate_probability == now.gate_probability && c.recovery_rejections == now.recovery_rejections) return;
  try {
    front_end_->filter().setGating(c.gate_probability, c.recovery_rejections);
  } catch (const std::invalid_argument& e) {
    ROS_ERROR("fusion: reconfiguration refused, keeping the gate in force: %s", e.what());
    c.gate_probability = now.gate_probability;
    c.recovery_rejections = now.recovery_rejections;
    return;
  }
  config_.filter.gate_probability = c.gate_probability;
  config_.filter.recovery_rejections = c.recovery_rejections;
  ROS_INFO("fusion: reconfigured: gate probability %.9g (Mahalanobis^2 <= %.1f), recovery after %d rejections",
           c.gate_probability, front_end_->filter().config().gateThreshold(), c.recovery_rejections);
}

void FusionRos::diagnose(diagnostic_updater::DiagnosticStatusWrapper& status) {
  auto total = [](const std::map<std::string, uint64_t>& m) {
    uint64_t n = 0;
    for (const auto& kv : m) n += kv.second;
    return n;
  };
  status.add("initialised", front_end_->filter().initialized());
  status.add("utm zone", grid_ ? grid_->name() + " (EPSG " + std::to_string(grid_->epsg()) + ") from " + grid_source_
                         : local_world_ ? "none: local frame '" + world_frame_ + "'"
                                        : std::string("unknown"));
  status.addf("gate", "p = %.9g, Mahalanobis^2 <= %.1f", front_end_->filter().config().gate_probability,
              front_end_->filter().config().gateThreshold());
  status.add("image motions", motions_);
  if (graph_) {
    const std::shared_ptr<const graph::GraphSnapshot> snapshot = graph_->snapshot();
    status.add("graph key frames", feeder_ ? feeder_->keyFrames().size() : 0);
    status.add("graph key frames tied by the navigation (no image odometry)", graph_navigation_ties_);
    if (feeder_) {
      status.add("graph dead-reckoning ties", feeder_->deadReckoningFactors());
      status.add("graph anchored by the dead reckoning", feeder_->deadReckoningAnchored() ? "yes" : "no");
    }
    if (snapshot) {
      status.add("graph key frames solved", snapshot->key_frames.size());
      status.addf("graph last solve", "%.3f s CPU, %s", snapshot->report.cpu_s,
                  snapshot->report.converged ? "converged" : "bounded");
      if (!snapshot->last_error.empty()) status.add("graph last error", snapshot->last_error);
      if (!snapshot->position_covariance_m2.empty()) {
        // The latest key frame the marginals cover: how well the graph knows where the vehicle was lately.
        for (auto c = snapshot->position_covariance_m2.rbegin(); c != snapshot->position_covariance_m2.rend(); ++c)
          if (c->allFinite()) {
            status.addf("graph position 1-sigma (m)", "%.3f E, %.3f N (%.3f s CPU)", std::sqrt((*c)(0, 0)),
                        std::sqrt((*c)(1, 1)), snapshot->marginals_cpu_s);
            break;
          }
      }
      int accepted = 0;
      for (char a : snapshot->loop_accepted) accepted += a;
      status.add("graph loops accepted", accepted);
    }
    if (loop_closer_) {
      const graph::LoopCloserStats loops = loop_closer_->stats();
      status.add("loop key frames searched", loops.key_frames_done);
      status.add("loop key frames without image", loop_images_missing_);
      status.add("loop candidates verified", loops.candidates);
      status.add("loops added", loops.loops_added);
      status.add("loop key frames dropped (queue full)", loops.dropped);
      if (!loops.last_refusal.empty()) status.add("loop last refusal", loops.last_refusal);
      if (!loops.last_error.empty()) status.add("loop last error", loops.last_error);
      status.add("loop images in memory", loops.images.in_memory);
      status.add("loop images on disk", loops.images.on_disk);
      status.add("loop image write failures", loops.images.write_failures);
      status.add("loop images lost", loops.images.lost);
      if (!loops.images.last_error.empty()) status.add("loop image last error", loops.images.last_error);
    }
  }
  status.add("images awaiting their motion", awaiting_motion_.size());
  status.add("motion waits timed out", motion_waits_timed_out_);
  status.add("image motion failures", motion_failures_);
  status.add("dead reckoning messages", dead_reckonings_);
  status.add("fixes received", fixes_);
  for (const auto& [name, counts] :
       {std::make_pair("applied", &applied_), std::make_pair("gated", &gated_), std::make_pair("too old", &too_old_),
        std::make_pair("invalid", &invalid_), std::make_pair("rejected inputs", &rejected_inputs_)})
    for (const auto& kv : *counts) status.add(std::string(name) + ": " + kv.first, kv.second);
  status.add("resets", resets_);
  status.add("late inputs dropped", late_inputs_);
  if (const auto heap = exocet_common::heapUsage()) {  // resident memory that rises while this stays flat is malloc's
    status.addf("heap in use (MB)", "%.1f", heap->in_use_mb);
    status.addf("heap freed, kept by malloc (MB)", "%.1f", heap->free_held_mb);
    status.add("heap allocator", exocet_common::heapAllocator());
  }
  if (config_.keep_smoother_log && !config_.smoother_log_file.empty()) {
    status.add("filter steps written out", front_end_->filter().loggedToFile());
    status.add("filter steps in memory", front_end_->filter().log().steps.size());
    if (!front_end_->filter().logFileError().empty())
      status.add("filter step file error", front_end_->filter().logFileError());
  }
  status.add("started from", started_from_.empty() ? std::string("not started") : started_from_);
  if (!config_.state_file.empty()) {
    status.add("saved state", resume_note_);
    status.add("state saves", state_saves_);
    status.add("state save failures", state_save_failures_);
  }
  status.add("last problem", last_problem_);
  if (!front_end_->filter().initialized()) {
    status.summary(DiagnosticStatus::WARN,
                   "waiting for a first position (navigation, ~initial_* or ~set_initial_pose)");
    return;
  }
  const fu::FilterState s = front_end_->filter().current();
  const double sigma_m = std::sqrt(std::max(s.position_covariance_m2(0, 0), s.position_covariance_m2(1, 1)));
  status.add("position sigma (m)", sigma_m);
  status.add("pixel size correction", s.pixel_size_correction);
  status.add("pixel size correction sigma", s.pixel_size_correction_sigma);
  const double nav_silence_s = (ros::WallTime::now() - last_nav_wall_).toSec();
  const bool expects_navigation = !config_.odometry_topic.empty() || !config_.nav_fix_topic.empty();
  if (sigma_m > config_.max_position_sigma_m)
    status.summary(DiagnosticStatus::WARN, "position uncertain: 1-sigma " + std::to_string(sigma_m) + " m");
  else if (expects_navigation && dead_reckonings_ > 0 && nav_silence_s > config_.max_navigation_silence_s)
    status.summary(DiagnosticStatus::WARN,
                   "no navigation for " + std::to_string(static_cast<int>(nav_silence_s)) + " s");
  else if (total(rejected_inputs_) + total(invalid_) > 0 && !last_problem_.empty())
    status.summary(DiagnosticStatus::OK, "fusing; some inputs rejected (see last problem)");
  else
    status.summary(DiagnosticStatus::OK, "fusing");
}

}  // namespace exocet_mosaic
