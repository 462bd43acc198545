/**
 * @file odometry_path_recorder.h
 * @brief Turns an odometry stream (the simulator's ground truth, a DVL's dead reckoning, another vehicle's track)
 * into a nav_msgs/Path for rviz, beside the fusion's fused, navigation-only and image-only paths.
 *
 * Memory stays bounded on a dive of any length: poses closer than ~min_spacing_m to the last kept one are skipped,
 * and when ~max_poses is reached every other pose is dropped (the path keeps its whole extent at half the density).
 * A stamp going back (bag replayed again, clock jump) starts a new path. Non-finite poses are refused, counted and
 * reported on /diagnostics. Poses are published in ~frame_id (the fusion's map frame by default): rviz draws in single
 * precision, and a path in UTM (northings of millions of metres) would come out in half-metre steps. The transform
 * from the odometry's frame is looked up with tf2 as a fixed one (utm -> map is static); until it is known the poses
 * wait (the oldest beyond 20000 are left out, counted).
 */
#pragma once

#include <deque>
#include <string>

#include <diagnostic_updater/diagnostic_updater.h>
#include <nav_msgs/Odometry.h>
#include <nav_msgs/Path.h>
#include <ros/ros.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>

namespace exocet_mosaic {

struct OdometryPathConfig {
  std::string odometry_topic = "/ground_truth/odometry";  ///< nav_msgs/Odometry in
  std::string path_topic = "/mosaic/ground_truth_path";   ///< nav_msgs/Path out (latched)
  double min_spacing_m = 0.05;                            ///< [0, 1000]: closer poses are skipped
  int max_poses = 20000;                                  ///< [10, 10^7]: beyond, the path is thinned by two
  double publish_rate_hz = 2.0;                           ///< (0, 100]: the path is re-published at most this often
  std::string frame_id = "map";  ///< the path's frame; empty: the odometry's own
};

/// @throws std::invalid_argument naming the parameter, its value and the allowed range.
OdometryPathConfig readOdometryPathConfig(const ros::NodeHandle& private_nh);

/// Adds one pose to a path (the recorder's rule, apart from ROS for its test). Returns what happened.
enum class PathUpdate { kAppended, kSkippedTooClose, kRestarted, kRejectedNotFinite };
PathUpdate appendToPath(const geometry_msgs::PoseStamped& pose, const OdometryPathConfig& config, nav_msgs::Path* path);

class OdometryPathRecorder {
 public:
  /// @throws std::invalid_argument for a bad parameter.
  OdometryPathRecorder(ros::NodeHandle nh, ros::NodeHandle private_nh);

 private:
  void onOdometry(const nav_msgs::OdometryConstPtr& msg);
  void publish();
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& status);

  ros::NodeHandle nh_, private_nh_;
  OdometryPathConfig config_;
  ros::Subscriber odometry_sub_;
  ros::Publisher path_pub_;
  ros::SteadyTimer publish_timer_, diagnostics_timer_;
  diagnostic_updater::Updater updater_;
  nav_msgs::Path path_;
  bool dirty_ = false;
  static constexpr std::size_t kMaxWaitingPoses = 20000;
  std::deque<geometry_msgs::PoseStamped> waiting_;  ///< poses waiting for the transform to ~frame_id
  tf2_ros::Buffer tf_buffer_;
  tf2_ros::TransformListener tf_listener_{tf_buffer_};
  long received_ = 0, rejected_ = 0, restarts_ = 0, untransformed_ = 0;
  std::string last_problem_;
};

}  // namespace exocet_mosaic
