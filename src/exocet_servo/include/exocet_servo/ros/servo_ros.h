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
 *        "safety stop: <check>: ...", "servo stopped: ...", "max iterations: ...", "stopped: ..."); <check> is
 *        "joint limit", "left workspace", "lost tracking" or "error growing".
 *  - in  `joint_states` (sensor_msgs/JointState): the arm's joint positions and velocities (safety checks).
 *  - in  tf: ~safety/world_frame -> the left camera's frame (the image's frame_id), for the workspace check.
 *  - out `/diagnostics`: ERROR with the reason after a safety stop.
 * Services: `~capture_reference` and `~stop` (std_srvs/Trigger). A capture is refused (success false, the reason in
 * the message) until both cameras' images and, with ~safety/check_joints, a joint state have arrived.
 *
 * Safety (control::ServoSafetyMonitor, the last line before each command): before a velocity is published it is
 * scaled to the speed limits, and the servo stops (zero velocity at once, ~status "safety stop: <check>: <what, the
 * value and the limit>", ROS_ERROR, /diagnostics ERROR) when a joint could come closer than ~safety/joint_margin_rad
 * to a joint limit within ~safety/joint_lookahead_s at its velocity limit, or moves faster than that limit, when the
 * joint state is more than ~safety/joint_state_max_age_s older than the image, when the left camera leaves the
 * workspace box / sphere (or its pose is unknown), when too few points are tracked or re-matching fails ("lost
 * tracking"), or when |e| keeps growing (~safety/... parameters, see readServoNodeConfig()). The
 * node keeps running: the next ~capture_reference starts a new servoing (checked in the same way).
 */
#pragma once

#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <diagnostic_updater/diagnostic_updater.h>
#include <ros/callback_queue.h>
#include <ros/ros.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/JointState.h>
#include <std_srvs/Trigger.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>

#include "exocet_servo/control/image_servo_controller.h"
#include "exocet_servo/control/servo_safety.h"

namespace exocet_servo {

/// The arm's joints as the servo node checks them (defaults: the simulated arm, sim::ArmModel::defaultConfig(), with
/// the simulator's joint names); validate() lists the allowed ranges.
struct JointSafetyConfig {
  bool enabled = true;                     ///< false: no joint check (an arm without joint_states)
  std::vector<std::string> names;          ///< as in joint_states; one per limit below, unique, non-empty
  std::vector<double> min_rad, max_rad;    ///< position limits, min < max
  std::vector<double> max_velocity_rad_s;  ///< |dq/dt| limits, > 0
  double margin_rad = 0.1;                 ///< stop this far inside a position limit, [0, 1]
  /// A command acts this long before the next check (one image at 4 Hz), [0, 10]: a joint closer to a limit + margin
  /// than its velocity limit x lookahead_s stops the servo (whatever the command, it cannot then cross the limit).
  double lookahead_s = 0.25;
  double velocity_tolerance = 0.05;  ///< stop above (1 + this) x a velocity limit, [0, 10]
  double max_age_s = 1.0;            ///< a joint state older than this at an image stops the servo, (0, 60]
  /// The defaults described above.
  static JointSafetyConfig simulatedArm();
  /// "" or every bad field with its allowed range ("; "-joined).
  std::string validate() const;
};

/// "" when the joint state is within the limits, else what is wrong: the joint, its value and the limit (e.g.
/// "joint_1 at -0.416 rad could reach -0.541 rad in 0.25 s at its 0.500 rad/s limit, beyond its lower limit -0.700 rad
/// + margin 0.100 rad"). A joint of the config missing from the message, or non-finite values, are violations too.
std::string checkJointState(const JointSafetyConfig& config, const sensor_msgs::JointState& state);

struct ServoNodeConfig {
  control::ImageServoConfig servo;     ///< its dt_s is unused: the velocity is held by the arm until the next image
  double max_linear_speed_mps = 0.3;   ///< (0, 10]; the arm's joint speed limits apply too
  double max_angular_speed_rps = 1.0;  ///< (0, 10]
  /// Tracking, error growth and workspace (box and sphere, camera centre in world_frame); its max_iterations is not
  /// used (the servo's own budget, max_iterations, applies). The growth check is loose (|e| 10 x its minimum for 10
  /// images): this loop's |e| wanders by up to 8 x between images without diverging (tracks lost, the law's reference
  /// reset to the surviving subset), and its history restarts at each SIFT re-matching (a new point set).
  control::ServoSafetyConfig safety = [] {
    control::ServoSafetyConfig c;
    c.growth_factor = 10.0;
    c.growth_iterations = 10;
    c.growth_floor = 0.003;  // 10 x the convergence threshold: the |e| the re-anchored points' jitter reaches
    c.max_iterations = 10000000;
    return c;
  }();
  JointSafetyConfig joints = JointSafetyConfig::simulatedArm();
  std::string world_frame = "arm_base";  ///< frame of the workspace (the arm's base)
  double tf_timeout_s = 0.3;             ///< wait for the left camera's pose at an image's stamp, (0, 10]
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
  void onJointState(const sensor_msgs::JointStateConstPtr& msg);
  /// The latest joint state, after waiting (up to tf_timeout_s) for one stamped at or after the image's stamp.
  sensor_msgs::JointStateConstPtr jointStateAt(const ros::Time& image_stamp);
  /// The latest joint state, after waiting (up to joints.max_age_s) for one stamped after the last command.
  sensor_msgs::JointStateConstPtr jointStateAfterLastCommand();
  bool onCaptureReference(std_srvs::Trigger::Request& req, std_srvs::Trigger::Response& res);
  bool onStop(std_srvs::Trigger::Request& req, std_srvs::Trigger::Response& res);
  void stepOnLeftPair();
  /// "" or why the safety monitor stops the servoing before last_step_'s velocity is sent (monitor_ updated).
  std::string checkSafety(const ros::Time& stamp);
  void finish(const std::string& status);
  /// Zero velocity, the stop on ~status, ROS_ERROR and /diagnostics ERROR.
  void safetyStop(const std::string& reason);
  void publishVelocity(const Eigen::Matrix<double, 6, 1>& twist, const ros::Time& stamp);
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& status);

  ros::NodeHandle nh_, pnh_;
  ServoNodeConfig config_;
  // joint_states on their own queue and thread: the check at an image then sees the joint state of the same tick,
  // published while the image is processed (declared before the subscribers, which must go first).
  ros::CallbackQueue joint_queue_;
  ros::Subscriber left_image_sub_, left_depth_sub_, left_info_sub_, right_image_sub_, right_depth_sub_, right_info_sub_,
      joint_state_sub_;
  ros::Publisher velocity_pub_, status_pub_;
  ros::ServiceServer capture_srv_, stop_srv_;
  diagnostic_updater::Updater diagnostics_;
  tf2_ros::Buffer tf_buffer_;
  tf2_ros::TransformListener tf_listener_;

  CameraSide left_, right_;
  std::mutex joint_mutex_;
  sensor_msgs::JointStateConstPtr joint_state_;  ///< guarded by joint_mutex_
  ros::Time last_command_time_;                  ///< when the last velocity was published; guarded by joint_mutex_
  control::ServoSafetyMonitor monitor_;
  bool safety_stopped_ = false;
  std::string safety_reason_;
  std::unique_ptr<control::ImageServoController> controller_;
  State state_ = State::kIdle;
  std::string status_text_ = "idle";
  std::string left_frame_;
  ros::Time reference_stamp_, last_processed_stamp_;
  int iterations_ = 0;
  control::ImageStep last_step_;
  long servoings_ = 0, converged_ = 0, corrupt_images_ = 0, safety_stops_ = 0;
  long stale_images_ = 0;                             ///< images exposed before the last command was sent, skipped
  std::unique_ptr<ros::AsyncSpinner> joint_spinner_;  ///< last: stopped before anything it uses goes
};

}  // namespace exocet_servo
