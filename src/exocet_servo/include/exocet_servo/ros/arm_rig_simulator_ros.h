/**
 * @file arm_rig_simulator_ros.h
 * @brief ROS bridge of sim::ArmRigSimulator (the 6-DOF arm carrying the stereo rig in front of the vent): at
 * ~rate_hz it applies the latest camera velocity command for one period, once (and only when younger than
 * ~command_timeout_s; without a new command the arm stays: a late servo makes it wait), then publishes both
 * cameras' images, depth maps and camera_info, the joint states and tf. The depth maps stand for the rig's stereo
 * triangulation (the servo needs the points' depths).
 *
 * Topics (relative to the node's namespace):
 *  - in  `arm/camera_velocity` (geometry_msgs/TwistStamped): left camera's velocity in its own frame (m/s, rad/s).
 *  - out `left/image_raw`, `left/depth` (32FC1, m, NaN where no surface), `left/camera_info`; the same for `right/`.
 *  - out `joint_states` (sensor_msgs/JointState: position rad, velocity rad/s).
 *  - out tf: ~world_frame -> ~flange_frame (each tick); ~flange_frame -> ~left_frame -> ~right_frame (static).
 *  - out `/diagnostics`: the arm's status (joint limit reached, velocity scaled, singular), the command's age.
 * Parameter `~hide_scene` (bool, default false, read at every tick): both cameras see open water only (no object, no
 * depth), to test the servo's stop on lost tracking.
 */
#pragma once

#include <memory>
#include <mutex>
#include <string>

#include <diagnostic_updater/diagnostic_updater.h>
#include <geometry_msgs/TwistStamped.h>
#include <ros/callback_queue.h>
#include <ros/ros.h>
#include <tf2_ros/static_transform_broadcaster.h>
#include <tf2_ros/transform_broadcaster.h>

#include "exocet_servo/sim/arm_rig_simulator.h"

namespace exocet_servo {

struct ArmRigSimulatorNodeConfig {
  double rate_hz = 4.0;            ///< images and control ticks per second, (0, 50]
  double command_timeout_s = 0.6;  ///< a command older than this is dropped (the arm stops), (0, 10]
  std::string world_frame = "arm_base";
  std::string flange_frame = "arm_flange";
  std::string left_frame = "left_camera_optical";
  std::string right_frame = "right_camera_optical";
  int supersampling = 2;  ///< rays per pixel side of the renderer, [1, 8] (1 aliases: KLT jitters)
};

/// Reads and checks the private parameters. @throws std::invalid_argument naming the parameter and its range.
ArmRigSimulatorNodeConfig readArmRigSimulatorNodeConfig(const ros::NodeHandle& private_nh);

class ArmRigSimulatorRos {
 public:
  /// @throws std::invalid_argument for a bad parameter.
  ArmRigSimulatorRos(ros::NodeHandle nh, ros::NodeHandle private_nh);

 private:
  void onCommand(const geometry_msgs::TwistStamped::ConstPtr& msg);
  void onTick(const ros::TimerEvent& event);
  void publishViews(const ros::Time& stamp);
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& status);

  ros::NodeHandle nh_, pnh_;
  ArmRigSimulatorNodeConfig config_;
  std::unique_ptr<sim::ArmRigSimulator> sim_;
  ros::Subscriber command_sub_;
  ros::Publisher left_image_pub_, left_depth_pub_, left_info_pub_, right_image_pub_, right_depth_pub_, right_info_pub_;
  ros::Publisher joint_pub_;
  tf2_ros::TransformBroadcaster tf_;
  tf2_ros::StaticTransformBroadcaster static_tf_;
  diagnostic_updater::Updater diagnostics_;
  ros::Timer timer_;

  std::mutex mutex_;  ///< the command (callbacks may run on other threads with an AsyncSpinner)
  Eigen::Matrix<double, 6, 1> command_ = Eigen::Matrix<double, 6, 1>::Zero();
  ros::Time command_stamp_;
  ros::Time command_image_stamp_;  ///< the command's header stamp: the image it was computed from
  ros::Time last_motion_stamp_;    ///< stamp of the last tick that moved the arm
  bool have_command_ = false;
  long commands_ = 0, rejected_commands_ = 0;
  /// Commands computed from an image older than the arm's last motion: the servo acted on an image that did not show
  /// its previous command (a late loop), and the arm moves twice for one error.
  long late_commands_ = 0;
  arm::ArmStatus last_status_ = arm::ArmStatus::kOk;
  std::string last_message_;
  /// Commands are taken on their own thread, as an arm controller does, not behind the rendering of the tick: a
  /// command sent before a tick's stamp is in that tick's motion.
  ros::CallbackQueue command_queue_;
  std::unique_ptr<ros::AsyncSpinner> command_spinner_;  ///< last: stopped before anything it uses goes
};

}  // namespace exocet_servo
