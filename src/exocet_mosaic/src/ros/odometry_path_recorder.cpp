#include "exocet_mosaic/ros/odometry_path_recorder.h"

#include <cmath>

#include <tf2_geometry_msgs/tf2_geometry_msgs.h>

#include "exocet_common/ros/parameter_reader.h"

namespace exocet_mosaic {

namespace {
bool finitePose(const geometry_msgs::Pose& p) {
  const auto& q = p.orientation;
  return std::isfinite(p.position.x) && std::isfinite(p.position.y) && std::isfinite(p.position.z) &&
         std::isfinite(q.x) && std::isfinite(q.y) && std::isfinite(q.z) && std::isfinite(q.w);
}
}  // namespace

OdometryPathConfig readOdometryPathConfig(const ros::NodeHandle& private_nh) {
  OdometryPathConfig c;
  const exocet_common::ParameterReader params(private_nh);
  params.readTopic("odometry_topic", &c.odometry_topic);
  params.readTopic("path_topic", &c.path_topic);
  params.readDouble("min_spacing_m", &c.min_spacing_m, 0.0, 1000.0,
                    "poses closer than this to the last kept are skipped");
  params.readInt("max_poses", &c.max_poses, 10, 10000000, "poses kept; beyond, the path is thinned by two");
  params.readDouble("publish_rate_hz", &c.publish_rate_hz, 1e-3, 100.0, "how often the path is re-published");
  params.readOptionalString("frame_id", &c.frame_id, "frame of the path, empty: the odometry's");
  return c;
}

PathUpdate appendToPath(const geometry_msgs::PoseStamped& pose, const OdometryPathConfig& config,
                        nav_msgs::Path* path) {
  if (!finitePose(pose.pose) || pose.header.stamp.isZero()) return PathUpdate::kRejectedNotFinite;
  PathUpdate result = PathUpdate::kAppended;
  if (!path->poses.empty()) {
    const geometry_msgs::PoseStamped& last = path->poses.back();
    if (pose.header.stamp < last.header.stamp || pose.header.frame_id != path->header.frame_id) {
      path->poses.clear();
      result = PathUpdate::kRestarted;
    } else {
      const double dx = pose.pose.position.x - last.pose.position.x;
      const double dy = pose.pose.position.y - last.pose.position.y;
      const double dz = pose.pose.position.z - last.pose.position.z;
      if (std::sqrt(dx * dx + dy * dy + dz * dz) < config.min_spacing_m) return PathUpdate::kSkippedTooClose;
    }
  }
  path->header.frame_id = pose.header.frame_id;
  path->header.stamp = pose.header.stamp;
  path->poses.push_back(pose);
  if (int(path->poses.size()) > config.max_poses) {
    // Keep the first and the newest; drop every other pose in between.
    std::vector<geometry_msgs::PoseStamped> thinned;
    thinned.reserve(path->poses.size() / 2 + 2);
    for (size_t i = 0; i + 1 < path->poses.size(); i += 2) thinned.push_back(path->poses[i]);
    thinned.push_back(path->poses.back());
    path->poses.swap(thinned);
  }
  return result;
}

OdometryPathRecorder::OdometryPathRecorder(ros::NodeHandle nh, ros::NodeHandle private_nh)
    : nh_(nh), private_nh_(private_nh), config_(readOdometryPathConfig(private_nh)) {
  path_pub_ = nh_.advertise<nav_msgs::Path>(config_.path_topic, 1, true);
  odometry_sub_ = nh_.subscribe(config_.odometry_topic, 200, &OdometryPathRecorder::onOdometry, this);
  updater_.setHardwareID("path of " + config_.odometry_topic);
  updater_.add("path", this, &OdometryPathRecorder::diagnose);
  // Wall-clock timers: the path and /diagnostics go on when a replay pauses or its clock jumps back.
  publish_timer_ = nh_.createSteadyTimer(ros::WallDuration(1.0 / config_.publish_rate_hz),
                                         [this](const ros::SteadyTimerEvent&) { publish(); });
  const double period_s = updater_.getPeriod() > 0.0 ? updater_.getPeriod() : 1.0;
  diagnostics_timer_ = nh_.createSteadyTimer(ros::WallDuration(period_s),
                                             [this](const ros::SteadyTimerEvent&) { updater_.force_update(); });
  ROS_INFO("odometry path: %s -> %s (every %.3f m, at most %d poses)", config_.odometry_topic.c_str(),
           config_.path_topic.c_str(), config_.min_spacing_m, config_.max_poses);
}

void OdometryPathRecorder::onOdometry(const nav_msgs::OdometryConstPtr& msg) {
  ++received_;
  geometry_msgs::PoseStamped pose;
  pose.header = msg->header;
  pose.pose = msg->pose.pose;
  if (!config_.frame_id.empty() && msg->header.frame_id != config_.frame_id) {
    geometry_msgs::TransformStamped t;
    try {
      // A fixed offset (utm -> map): the latest transform, whatever the pose's stamp.
      t = tf_buffer_.lookupTransform(config_.frame_id, msg->header.frame_id, ros::Time(0));
    } catch (const tf2::TransformException& e) {
      // Kept until the transform comes (the fusion gives utm -> map once it knows the datum), within a bound.
      if (waiting_.size() >= kMaxWaitingPoses) {
        waiting_.pop_front();
        ++untransformed_;
      }
      waiting_.push_back(pose);
      ROS_WARN_THROTTLE(10.0, "odometry path: no transform %s -> %s yet (%s): poses wait", msg->header.frame_id.c_str(),
                        config_.frame_id.c_str(), e.what());
      return;
    }
    waiting_.push_back(pose);
    while (!waiting_.empty()) {
      geometry_msgs::PoseStamped moved;
      tf2::doTransform(waiting_.front(), moved, t);
      moved.header.stamp = waiting_.front().header.stamp;
      moved.header.frame_id = config_.frame_id;
      waiting_.pop_front();
      if (waiting_.empty()) {
        pose = moved;
        break;
      }
      if (appendToPath(moved, config_, &path_) == PathUpdate::kRejectedNotFinite) ++rejected_;
    }
  }
  switch (appendToPath(pose, config_, &path_)) {
    case PathUpdate::kRejectedNotFinite:
      ++rejected_;
      last_problem_ = "odometry with a non-finite pose or a zero stamp";
      ROS_WARN_THROTTLE(5.0, "odometry path: skipping an %s on %s", last_problem_.c_str(),
                        config_.odometry_topic.c_str());
      return;
    case PathUpdate::kRestarted:
      ++restarts_;
      last_problem_ = "the stamps went back (bag replayed again, clock jump) or the frame changed: new path";
      ROS_WARN_THROTTLE(5.0, "odometry path: %s", last_problem_.c_str());
      break;
    case PathUpdate::kSkippedTooClose:
      return;
    case PathUpdate::kAppended:
      break;
  }
  dirty_ = true;
}

void OdometryPathRecorder::publish() {
  if (!dirty_) return;
  path_pub_.publish(path_);
  dirty_ = false;
}

void OdometryPathRecorder::diagnose(diagnostic_updater::DiagnosticStatusWrapper& status) {
  if (received_ == 0)
    status.summary(diagnostic_msgs::DiagnosticStatus::WARN, "no odometry received yet on " + config_.odometry_topic);
  else if (rejected_ > 0)
    status.summary(diagnostic_msgs::DiagnosticStatus::WARN, last_problem_);
  else
    status.summary(diagnostic_msgs::DiagnosticStatus::OK, "recording");
  status.add("odometry received", received_);
  status.add("odometry rejected", rejected_);
  status.add("path restarts", restarts_);
  status.add("poses left out for want of a transform to " + config_.frame_id, untransformed_);
  status.add("poses in the path", path_.poses.size());
}

}  // namespace exocet_mosaic
