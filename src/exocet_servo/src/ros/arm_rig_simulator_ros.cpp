#include "exocet_servo/ros/arm_rig_simulator_ros.h"

#include <cmath>
#include <limits>
#include <stdexcept>

#include <cv_bridge/cv_bridge.h>
#include <geometry_msgs/TransformStamped.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/JointState.h>
#include <sensor_msgs/image_encodings.h>

#include "exocet_common/ros/parameter_reader.h"

namespace exocet_servo {

namespace {

geometry_msgs::TransformStamped toTransform(const Eigen::Isometry3d& parent_T_child, const ros::Time& stamp,
                                            const std::string& parent, const std::string& child) {
  geometry_msgs::TransformStamped t;
  t.header.stamp = stamp;
  t.header.frame_id = parent;
  t.child_frame_id = child;
  const Eigen::Quaterniond q(parent_T_child.linear());
  t.transform.translation.x = parent_T_child.translation().x();
  t.transform.translation.y = parent_T_child.translation().y();
  t.transform.translation.z = parent_T_child.translation().z();
  t.transform.rotation.x = q.x();
  t.transform.rotation.y = q.y();
  t.transform.rotation.z = q.z();
  t.transform.rotation.w = q.w();
  return t;
}

sensor_msgs::CameraInfo cameraInfo(const sim::PinholeCamera& camera, const ros::Time& stamp, const std::string& frame) {
  sensor_msgs::CameraInfo info;
  info.header.stamp = stamp;
  info.header.frame_id = frame;
  info.width = camera.width_px;
  info.height = camera.height_px;
  info.distortion_model = "plumb_bob";
  info.D.assign(5, 0.0);
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) info.K[3 * r + c] = camera.k(r, c);
  info.R = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) info.P[4 * r + c] = camera.k(r, c);
  return info;
}

/// Depth map with NaN where no surface was hit (REP 118 uses NaN for "no return").
cv::Mat depthForRos(const cv::Mat& depth_m) {
  cv::Mat out = depth_m.clone();
  out.setTo(std::numeric_limits<float>::quiet_NaN(), depth_m == std::numeric_limits<float>::infinity());
  return out;
}

}  // namespace

ArmRigSimulatorNodeConfig readArmRigSimulatorNodeConfig(const ros::NodeHandle& private_nh) {
  ArmRigSimulatorNodeConfig c;
  const exocet_common::ParameterReader p(private_nh);
  p.readPositiveDouble("rate_hz", &c.rate_hz, 50.0, "images and control ticks per second (Hz)");
  p.readPositiveDouble("command_timeout_s", &c.command_timeout_s, 10.0,
                       "age after which a velocity command is dropped and the arm stops (s)");
  p.readString("world_frame", &c.world_frame, {}, "frame of the arm's base");
  p.readString("flange_frame", &c.flange_frame, {}, "frame of the arm's flange");
  p.readString("left_frame", &c.left_frame, {}, "optical frame of the left (servoed) camera");
  p.readString("right_frame", &c.right_frame, {}, "optical frame of the right (reference) camera");
  p.readInt("supersampling", &c.supersampling, 1, 8, "rays per pixel side of the renderer");
  return c;
}

ArmRigSimulatorRos::ArmRigSimulatorRos(ros::NodeHandle nh, ros::NodeHandle private_nh)
    : nh_(nh), pnh_(private_nh), config_(readArmRigSimulatorNodeConfig(private_nh)), diagnostics_(nh, private_nh) {
  sim::ArmRigConfig arm_config;
  arm_config.scene.supersampling = config_.supersampling;
  sim_ = std::make_unique<sim::ArmRigSimulator>(arm_config);
  ros::SubscribeOptions command_options = ros::SubscribeOptions::create<geometry_msgs::TwistStamped>(
      "arm/camera_velocity", 5, [this](const geometry_msgs::TwistStamped::ConstPtr& m) { onCommand(m); },
      ros::VoidPtr(), &command_queue_);
  command_sub_ = nh_.subscribe(command_options);
  command_spinner_ = std::make_unique<ros::AsyncSpinner>(1, &command_queue_);
  command_spinner_->start();
  left_image_pub_ = nh_.advertise<sensor_msgs::Image>("left/image_raw", 2);
  left_depth_pub_ = nh_.advertise<sensor_msgs::Image>("left/depth", 2);
  left_info_pub_ = nh_.advertise<sensor_msgs::CameraInfo>("left/camera_info", 2);
  right_image_pub_ = nh_.advertise<sensor_msgs::Image>("right/image_raw", 2);
  right_depth_pub_ = nh_.advertise<sensor_msgs::Image>("right/depth", 2);
  right_info_pub_ = nh_.advertise<sensor_msgs::CameraInfo>("right/camera_info", 2);
  joint_pub_ = nh_.advertise<sensor_msgs::JointState>("joint_states", 5);
  const ros::Time now = ros::Time::now();
  Eigen::Isometry3d flange_T_left = sim_->worldFromFlange().inverse() * sim_->worldFromLeft();
  static_tf_.sendTransform({toTransform(flange_T_left, now, config_.flange_frame, config_.left_frame),
                            toTransform(sim_->leftFromRight(), now, config_.left_frame, config_.right_frame)});
  diagnostics_.setHardwareID("exocet arm and stereo rig simulator");
  diagnostics_.add("arm", this, &ArmRigSimulatorRos::diagnose);
  timer_ = nh_.createTimer(ros::Duration(1.0 / config_.rate_hz), &ArmRigSimulatorRos::onTick, this);
  ROS_INFO("arm_rig_simulator: %g Hz, commands on %s, images on %s and %s", config_.rate_hz,
           command_sub_.getTopic().c_str(), left_image_pub_.getTopic().c_str(), right_image_pub_.getTopic().c_str());
}

void ArmRigSimulatorRos::onCommand(const geometry_msgs::TwistStamped::ConstPtr& msg) {
  Eigen::Matrix<double, 6, 1> twist;
  twist << msg->twist.linear.x, msg->twist.linear.y, msg->twist.linear.z, msg->twist.angular.x, msg->twist.angular.y,
      msg->twist.angular.z;
  std::lock_guard<std::mutex> lock(mutex_);
  if (!twist.allFinite()) {
    ++rejected_commands_;
    ROS_ERROR_THROTTLE(5.0, "arm_rig_simulator: a velocity command is not finite; the arm stops");
    have_command_ = false;
    return;
  }
  if (!msg->header.frame_id.empty() && msg->header.frame_id != config_.left_frame) {
    ++rejected_commands_;
    ROS_ERROR_THROTTLE(5.0, "arm_rig_simulator: velocity command in frame '%s', expected the left camera's '%s'",
                       msg->header.frame_id.c_str(), config_.left_frame.c_str());
    return;
  }
  command_ = twist;
  command_stamp_ = ros::Time::now();
  command_image_stamp_ = msg->header.stamp;
  have_command_ = true;
  ++commands_;
}

void ArmRigSimulatorRos::onTick(const ros::TimerEvent&) {
  const double dt_s = 1.0 / config_.rate_hz;
  Eigen::Matrix<double, 6, 1> twist = Eigen::Matrix<double, 6, 1>::Zero();
  ros::Time stamp;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stamp = ros::Time::now();  // the images' stamp: every command received before it is in this tick's motion
    // Each command moves the arm for one period, once: a servo that falls behind (a loaded machine) makes the arm
    // wait instead of repeating a velocity computed from an older image (which overshoots and loses the object).
    if (have_command_ && (ros::Time::now() - command_stamp_).toSec() <= config_.command_timeout_s) twist = command_;
    have_command_ = false;
    if (!twist.isZero()) {
      if (!command_image_stamp_.isZero() && command_image_stamp_ < last_motion_stamp_) {
        ++late_commands_;
        ROS_DEBUG("arm_rig_simulator: command from the image of %.3f, after a motion at %.3f",
                  command_image_stamp_.toSec(), last_motion_stamp_.toSec());
      }
    }
  }
  const arm::ResolvedRate rate = sim_->command(twist, dt_s);
  if (rate.status == arm::ArmStatus::kJointLimit || rate.status == arm::ArmStatus::kInvalidInput)
    ROS_WARN_THROTTLE(5.0, "arm_rig_simulator: %s: %s", arm::toString(rate.status).c_str(), rate.message.c_str());
  last_status_ = rate.status;
  last_message_ = rate.message;
  if (!twist.isZero()) last_motion_stamp_ = stamp;  // (read on this thread only)
  publishViews(stamp);
  diagnostics_.update();
}

void ArmRigSimulatorRos::publishViews(const ros::Time& stamp) {
  sim::StereoViews views = sim_->render();
  // ~hide_scene (read at every tick, so that a test can set it while the node runs): both cameras see open water, as
  // when the rig looks away or the water turns turbid; the servo must stop on lost tracking.
  bool hide_scene = false;
  pnh_.getParamCached("hide_scene", hide_scene);
  if (hide_scene) {
    for (sim::RenderedView* view : {&views.left, &views.right}) {
      view->image.setTo(cv::Scalar(sim_->config().scene.water_gray));
      view->depth_m.setTo(cv::Scalar(std::numeric_limits<float>::infinity()));
    }
  }
  const auto publish = [&](const sim::RenderedView& view, const sim::PinholeCamera& camera, const std::string& frame,
                           ros::Publisher& image_pub, ros::Publisher& depth_pub, ros::Publisher& info_pub) {
    std_msgs::Header header;
    header.stamp = stamp;
    header.frame_id = frame;
    // Depth first: the servo pairs each image with the depth map of the same stamp.
    depth_pub.publish(
        cv_bridge::CvImage(header, sensor_msgs::image_encodings::TYPE_32FC1, depthForRos(view.depth_m)).toImageMsg());
    info_pub.publish(cameraInfo(camera, stamp, frame));
    image_pub.publish(cv_bridge::CvImage(header, sensor_msgs::image_encodings::MONO8, view.image).toImageMsg());
  };
  publish(views.left, sim_->config().left_camera, config_.left_frame, left_image_pub_, left_depth_pub_, left_info_pub_);
  publish(views.right, sim_->config().right_camera, config_.right_frame, right_image_pub_, right_depth_pub_,
          right_info_pub_);
  sensor_msgs::JointState joints;
  joints.header.stamp = stamp;
  for (int j = 0; j < arm::kArmJoints; ++j) {
    joints.name.push_back("joint_" + std::to_string(j + 1));
    joints.position.push_back(sim_->jointPositions()[j]);
    joints.velocity.push_back(sim_->jointVelocities()[j]);
  }
  joint_pub_.publish(joints);
  tf_.sendTransform(toTransform(sim_->worldFromFlange(), stamp, config_.world_frame, config_.flange_frame));
}

void ArmRigSimulatorRos::diagnose(diagnostic_updater::DiagnosticStatusWrapper& status) {
  using diagnostic_msgs::DiagnosticStatus;
  const bool stopped = last_status_ == arm::ArmStatus::kJointLimit || last_status_ == arm::ArmStatus::kInvalidInput;
  status.summary(stopped ? DiagnosticStatus::WARN : DiagnosticStatus::OK,
                 arm::toString(last_status_) + (last_message_.empty() ? "" : ": " + last_message_));
  std::lock_guard<std::mutex> lock(mutex_);
  status.add("commands", commands_);
  status.add("rejected commands", rejected_commands_);
  status.add("late commands", late_commands_);
  status.add("command age (s)", have_command_ ? (ros::Time::now() - command_stamp_).toSec() : -1.0);
  for (int j = 0; j < arm::kArmJoints; ++j)
    status.add("joint " + std::to_string(j + 1) + " (rad)", sim_->jointPositions()[j]);
}

}  // namespace exocet_servo
