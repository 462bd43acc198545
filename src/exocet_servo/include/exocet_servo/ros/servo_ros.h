/**
 * @file servo_ros.h
 * @brief ROS bridge of control::ImageServoController: the intrinsics-free stereo servoing of the 2D4 report. On
 * `~capture_reference` the right camera's current image (with its depth map) becomes the reference; the left camera
 * is then servoed, image by image, to the pose where the right camera took it, by velocity commands to the arm.
 *
 * Topics (relative to the node's namespace):
 *  - in  `left/image_raw` + `left/depth` (paired by stamp), `left/camera_info`; the same for `right/`. The depth maps
 *        (32FC1, m, NaN or inf where unknown) come from the rig's stereo (or the simulator).
 *  - out `arm/camera_velocity` (geometry_msgs/TwistStamped in the left camera's frame): the law's velocity, scaled
 *        down uniformly to ~max_linear_speed_mps / ~max_angular_speed_rps; zero when the servoing ends.
 *  - out `~status` (std_msgs/String, latched): "idle", "servoing", or how the last servoing ended ("converged: ...",
 *        "lost tracking: ...", "servo stopped: ...", "max iterations: ...", "stopped: ...").
 *  - out `/diagnostics`.
 * Services: `~capture_reference` and `~stop` (std_srvs/Trigger).
 */
#pragma once

#include <memory>
#include <string>

#include <diagnostic_updater/diagnostic_updater.h>
#include <ros/ros.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <std_srvs/Trigger.h>

#include "exocet_servo/control/image_servo_controller.h"

namespace exocet_servo {

struct ServoNodeConfig {
  control::ImageServoConfig servo;   ///< its dt_s is unused: the velocity is held by the arm until the next image
  double max_linear_speed_mps = 0.3;  ///< (0, 10]; the arm's joint speed limits apply too
  double max_angular_speed_rps = 1.0;  ///< (0, 10]
};

/// Reads and checks the private parameters. @throws std::invalid_argument naming the parameter and its range.
ServoNodeConfig readServoNodeConfig(const ros::NodeHandle& private_nh);

class ServoRos {
 public:
  /// @throws std::invalid_argument for a bad parameter.
  ServoRos(ros::NodeHandle nh, ros::NodeHandle private_nh);

 private:
  /// An image and the depth map of the same stamp, from one camera.
  struct CameraSide {
    sensor_msgs::ImageConstPtr image, depth;
    sensor_msgs::CameraInfoConstPtr info;
    bool paired() const { return image && depth && image->header.stamp == depth->header.stamp; }
  };
  enum class State { kIdle, kServoing, kDone };

  void onLeftImage(const sensor_msgs::ImageConstPtr& msg);
  void onLeftDepth(const sensor_msgs::ImageConstPtr& msg);
  void onRightImage(const sensor_msgs::ImageConstPtr& msg) { right_.image = msg; }
  void onRightDepth(const sensor_msgs::ImageConstPtr& msg) { right_.depth = msg; }
  bool onCaptureReference(std_srvs::Trigger::Request& req, std_srvs::Trigger::Response& res);
  bool onStop(std_srvs::Trigger::Request& req, std_srvs::Trigger::Response& res);
  void stepOnLeftPair();
  void finish(const std::string& status);
  void publishVelocity(const Eigen::Matrix<double, 6, 1>& twist, const ros::Time& stamp);
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& status);

  ros::NodeHandle nh_, pnh_;
  ServoNodeConfig config_;
  ros::Subscriber left_image_sub_, left_depth_sub_, left_info_sub_, right_image_sub_, right_depth_sub_,
      right_info_sub_;
  ros::Publisher velocity_pub_, status_pub_;
  ros::ServiceServer capture_srv_, stop_srv_;
  diagnostic_updater::Updater diagnostics_;

  CameraSide left_, right_;
  std::unique_ptr<control::ImageServoController> controller_;
  State state_ = State::kIdle;
  std::string status_text_ = "idle";
  std::string left_frame_;
  ros::Time reference_stamp_, last_processed_stamp_;
  int iterations_ = 0;
  control::ImageStep last_step_;
  long servoings_ = 0, converged_ = 0, corrupt_images_ = 0;
};

}  // namespace exocet_servo
