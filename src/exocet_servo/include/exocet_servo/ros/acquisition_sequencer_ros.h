/**
 * @file acquisition_sequencer_ros.h
 * @brief The acquisition sequencer of the 2D4 report (section 2.5): repeated servoings move the rig along the
 * trajectory its geometry sets (each time the left camera goes where the right one was, the rig turns by the rig
 * transform: a circle, helix or line). At each stop it records the stereo pair and the arm pose into a bag, the
 * input of the offline reconstruction.
 *
 * Uses servo_node's `~capture_reference` service and `~status` topic (parameter ~servo, default "servo"). Records,
 * for each stop k, at one stamp: `left/image_raw`, `left/camera_info`, `right/image_raw`, `right/camera_info`,
 * `joint_states`, and the two cameras' poses in ~world_frame as geometry_msgs/PoseStamped on `left/pose` and
 * `right/pose` (tf at the image stamp). Publishes `~status` (std_msgs/String, latched): "recording stop k of N",
 * "done: N stops in FILE", or "failed at stop k: <the servo's status>"; /diagnostics.
 */
#pragma once

#include <memory>
#include <string>

#include <diagnostic_updater/diagnostic_updater.h>
#include <ros/ros.h>
#include <rosbag/bag.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/JointState.h>
#include <std_msgs/String.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>

namespace exocet_servo {

struct AcquisitionSequencerConfig {
  int stops = 4;                    ///< stereo pairs to record, [1, 10000]
  std::string bag_path;             ///< output bag (required)
  std::string servo = "servo";      ///< name of the servo node
  std::string world_frame = "arm_base";
  std::string left_frame = "left_camera_optical";
  std::string right_frame = "right_camera_optical";
  double settle_s = 0.5;            ///< wait after convergence before recording (the arm stops), [0, 60]
};

/// Reads and checks the private parameters. @throws std::invalid_argument naming the parameter and its range.
AcquisitionSequencerConfig readAcquisitionSequencerConfig(const ros::NodeHandle& private_nh);

class AcquisitionSequencerRos {
 public:
  /// @throws std::invalid_argument for a bad parameter, std::runtime_error when the bag cannot be opened.
  AcquisitionSequencerRos(ros::NodeHandle nh, ros::NodeHandle private_nh);

 private:
  enum class State { kCapture, kServoing, kSettling, kRecord, kDone, kFailed };
  void onTick(const ros::TimerEvent& event);
  bool record();
  void setStatus(const std::string& text);
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& status);

  ros::NodeHandle nh_, pnh_;
  AcquisitionSequencerConfig config_;
  rosbag::Bag bag_;
  tf2_ros::Buffer tf_buffer_;
  tf2_ros::TransformListener tf_listener_;
  ros::Subscriber left_image_sub_, right_image_sub_, left_info_sub_, right_info_sub_, joints_sub_, servo_status_sub_;
  ros::ServiceClient capture_client_;
  ros::Publisher status_pub_;
  diagnostic_updater::Updater diagnostics_;
  ros::Timer timer_;

  sensor_msgs::ImageConstPtr left_image_, right_image_;
  sensor_msgs::CameraInfoConstPtr left_info_, right_info_;
  sensor_msgs::JointStateConstPtr joints_;
  std::string servo_status_;
  State state_ = State::kCapture;
  int recorded_ = 0;
  ros::Time settle_until_;
  std::string status_text_ = "starting";
};

}  // namespace exocet_servo
