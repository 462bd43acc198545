#include "exocet_servo/ros/servo_ros.h"

#include <cmath>
#include <cstdio>
#include <limits>
#include <set>
#include <sstream>
#include <stdexcept>

#include <cv_bridge/cv_bridge.h>
#include <geometry_msgs/TwistStamped.h>
#include <sensor_msgs/image_encodings.h>
#include <std_msgs/String.h>

#include "exocet_common/ros/parameter_reader.h"
#include "exocet_servo/control/twist_limit.h"
#include "exocet_servo/arm/arm_kinematics.h"
#include "exocet_servo/vision/depth_lookup.h"

namespace exocet_servo {

namespace {

Eigen::Matrix3d intrinsicsOf(const sensor_msgs::CameraInfo& info) {
  Eigen::Matrix3d k;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) k(r, c) = info.K[3 * r + c];
  return k;
}

/// The image as 8-bit gray, or an empty Mat (with the reason) for an encoding the servo cannot use.
cv::Mat grayOf(const sensor_msgs::Image& msg, std::string* error) {
  try {
    if (msg.encoding == sensor_msgs::image_encodings::MONO8) return cv_bridge::toCvCopy(msg)->image;
    return cv_bridge::toCvCopy(msg, sensor_msgs::image_encodings::MONO8)->image;
  } catch (const std::exception& e) {
    *error = "image " + std::to_string(msg.width) + "x" + std::to_string(msg.height) + " '" + msg.encoding +
             "' cannot be read as 8-bit gray: " + e.what();
    return cv::Mat();
  }
}

/// The depth map as metres in CV_32F with +inf where unknown (the convention of vision::screenedDepthAt), or empty.
cv::Mat depthOf(const sensor_msgs::Image& msg, std::string* error) {
  try {
    cv::Mat depth;
    if (msg.encoding == sensor_msgs::image_encodings::TYPE_32FC1) {
      depth = cv_bridge::toCvCopy(msg)->image;
    } else if (msg.encoding == sensor_msgs::image_encodings::TYPE_16UC1) {  // REP 118: millimetres, 0 = unknown
      cv_bridge::toCvCopy(msg)->image.convertTo(depth, CV_32F, 1e-3);
      depth.setTo(std::numeric_limits<float>::infinity(), depth == 0.0f);
    } else {
      *error = "depth map encoding '" + msg.encoding + "' is neither 32FC1 (m) nor 16UC1 (mm)";
      return cv::Mat();
    }
    depth.setTo(std::numeric_limits<float>::infinity(), depth != depth);  // NaN
    depth.setTo(std::numeric_limits<float>::infinity(), depth <= 0.0f);
    return depth;
  } catch (const std::exception& e) {
    *error = std::string("depth map cannot be read: ") + e.what();
    return cv::Mat();
  }
}

/// Depth at a pixel from a depth map, screened for discontinuities (the window's max / min), NaN when unusable.
control::DepthLookup lookupIn(const cv::Mat& depth_m, const control::ImageServoConfig& config) {
  return [depth_m, radius = config.depth_check_radius_px,
          step = config.depth_max_relative_step](const Eigen::Vector2d& px) {
    double d = 0.0;
    return vision::screenedDepthAt(depth_m, px, radius, step, &d) ? d : std::numeric_limits<double>::quiet_NaN();
  };
}

std::string fixed(double value, int decimals = 3) {
  char text[64];
  std::snprintf(text, sizeof(text), "%.*f", decimals, value);
  return text;
}

}  // namespace

JointSafetyConfig JointSafetyConfig::simulatedArm() {
  JointSafetyConfig c;
  const arm::ArmModelConfig arm = arm::ArmModel::defaultConfig();
  for (int j = 0; j < arm::kArmJoints; ++j) {
    c.names.push_back("joint_" + std::to_string(j + 1));  // the simulator's names
    c.min_rad.push_back(arm.joints[j].min_rad);
    c.max_rad.push_back(arm.joints[j].max_rad);
    c.max_velocity_rad_s.push_back(arm.joints[j].max_velocity_rad_s);
  }
  return c;
}

std::string JointSafetyConfig::validate() const {
  std::ostringstream errors;
  auto check = [&errors](bool ok, const std::string& what) {
    if (ok) return;
    if (errors.tellp() > 0) errors << "; ";
    errors << what;
  };
  const size_t n = names.size();
  check(n >= 1 && min_rad.size() == n && max_rad.size() == n && max_velocity_rad_s.size() == n,
        "joint_names, joint_min_rad, joint_max_rad, joint_max_velocity_rad_s must have the same length >= 1 (got " +
            std::to_string(n) + ", " + std::to_string(min_rad.size()) + ", " + std::to_string(max_rad.size()) + ", " +
            std::to_string(max_velocity_rad_s.size()) + ")");
  const std::set<std::string> unique(names.begin(), names.end());
  check(unique.size() == n && !unique.count(""), "joint_names must be unique and non-empty");
  for (size_t j = 0; j < n && j < min_rad.size() && j < max_rad.size(); ++j)
    check(min_rad[j] < max_rad[j] && max_rad[j] - min_rad[j] > 2.0 * margin_rad,
          "joint " + names[j] +
              ": joint_min_rad < joint_max_rad with more than 2 x joint_margin_rad between them (got " +
              fixed(min_rad[j]) + ", " + fixed(max_rad[j]) + ")");
  for (size_t j = 0; j < n && j < max_velocity_rad_s.size(); ++j)
    check(max_velocity_rad_s[j] > 0.0 && max_velocity_rad_s[j] <= 100.0,
          "joint " + names[j] + ": joint_max_velocity_rad_s must be in (0, 100]");
  check(margin_rad >= 0.0 && margin_rad <= 1.0, "joint_margin_rad must be in [0, 1]");
  check(lookahead_s >= 0.0 && lookahead_s <= 10.0, "joint_lookahead_s must be in [0, 10]");
  check(velocity_tolerance >= 0.0 && velocity_tolerance <= 10.0, "joint_velocity_tolerance must be in [0, 10]");
  check(max_age_s > 0.0 && max_age_s <= 60.0, "joint_state_max_age_s must be in (0, 60]");
  return errors.str();
}

std::string checkJointState(const JointSafetyConfig& config, const sensor_msgs::JointState& state) {
  for (size_t j = 0; j < config.names.size(); ++j) {
    const std::string& name = config.names[j];
    size_t k = 0;
    while (k < state.name.size() && state.name[k] != name) ++k;
    if (k == state.name.size() || k >= state.position.size()) return name + " has no position in the joint state";
    const double q = state.position[k];
    // No velocity (an arm that publishes positions only): the position alone is checked.
    const double dq = k < state.velocity.size() ? state.velocity[k] : 0.0;
    if (!std::isfinite(q) || !std::isfinite(dq))
      return name + ": position " + fixed(q) + " rad, velocity " + fixed(dq) + " rad/s are not finite";
    const double limit_v = config.max_velocity_rad_s[j];
    if (std::abs(dq) > (1.0 + config.velocity_tolerance) * limit_v)
      return name + " moving at " + fixed(dq) + " rad/s is beyond its velocity limit " + fixed(limit_v) + " rad/s (+" +
             fixed(100.0 * config.velocity_tolerance, 0) + " %)";
    // Where the joint may be by the next check, whatever the command (at most its velocity limit for lookahead_s):
    // a stop then comes before the limit, not after it.
    const double reach = limit_v * config.lookahead_s;
    const bool upper = q + reach > config.max_rad[j] - config.margin_rad;
    const bool lower = q - reach < config.min_rad[j] + config.margin_rad;
    if (!upper && !lower) continue;
    std::string m = name + " at " + fixed(q) + " rad";
    if (reach > 0.0)
      m += " could reach " + fixed(upper ? q + reach : q - reach) + " rad in " + fixed(config.lookahead_s, 2) +
           " s at its " + fixed(limit_v) + " rad/s limit,";
    if (upper)
      m += " beyond its upper limit " + fixed(config.max_rad[j]) + " rad - margin " + fixed(config.margin_rad) + " rad";
    else
      m += " beyond its lower limit " + fixed(config.min_rad[j]) + " rad + margin " + fixed(config.margin_rad) + " rad";
    return m;
  }
  return "";
}

ServoNodeConfig readServoNodeConfig(const ros::NodeHandle& private_nh) {
  ServoNodeConfig c;
  const exocet_common::ParameterReader p(private_nh);
  control::ImageServoConfig& s = c.servo;
  // Gains per second: with images at 4 Hz, lambda dt = 0.5 near the goal and 0.25 far from it, as the simulated
  // loop's 0.7 / 0.3 per image.
  s.servo.gain = control::AdaptiveGain{2.0, 1.0, 4.0};
  s.servo.max_iterations = 300;
  s.matcher.ratio = 0.6;  // fewer, surer SIFT pairs across the rig's baseline (0.75 lets the servo diverge there)
  p.readPositiveDouble("gain_near", &s.servo.gain.gain_at_zero, 100.0, "gain of the law near the goal (1/s)");
  p.readPositiveDouble("gain_far", &s.servo.gain.gain_at_infinity, 100.0,
                       "gain of the law far from the goal (1/s), at most gain_near");
  p.readPositiveDouble("convergence_threshold", &s.servo.convergence_threshold, 1.0,
                       "|e| below which the servoing has converged");
  p.readInt("convergence_window", &s.servo.convergence_window, 1, 1000,
            "images over which the mean of e is also compared with the threshold (1: one image only)");
  p.readInt("max_iterations", &s.servo.max_iterations, 1, 1000000, "images per servoing before it gives up");
  p.readDouble("sift_ratio", &s.matcher.ratio, 0.3, 1.0, "Lowe's ratio test of the SIFT matching");
  p.readInt("max_points", &s.max_points, 4, 100000, "points given to the law");
  p.readInt("max_rematches", &s.max_rematches, 0, 100000, "SIFT re-matchings allowed in one servoing");
  p.readInt("stall_rematch_images", &s.stall_rematch_images, 0, 100000,
            "images without progress of |e| (far from the goal) after which the whole image is matched again, 0: off");
  p.readInt("min_tracked_points", &s.tracker.min_points, 4, 100000, "tracked points below which SIFT re-matches");
  p.readPositiveDouble("max_linear_speed_mps", &c.max_linear_speed_mps, 10.0, "camera speed limit (m/s)");
  p.readPositiveDouble("max_angular_speed_rps", &c.max_angular_speed_rps, 10.0, "camera rotation speed limit (rad/s)");
  const std::string problems = s.validate();
  if (!problems.empty()) throw std::invalid_argument("servo parameters: " + problems);

  // Safety stops (servo_safety.h): the servo's own budget replaces the monitor's.
  control::ServoSafetyConfig& f = c.safety;
  p.readInt("safety/min_tracked_points", &f.min_tracked_points, 4, 100000,
            "fewer points given to the law than this stops the servo (lost tracking)");
  p.readDouble("safety/growth_factor", &f.growth_factor, 1.0, 1e6,
               "|e| above this times its smallest value so far counts as growing, > 1");
  if (!(f.growth_factor > 1.0))
    throw std::invalid_argument(p.describe("safety/growth_factor") + " = 1 is out of range (1, 1e6]: |e| above this " +
                                "times its smallest value so far counts as growing");
  p.readInt("safety/growth_iterations", &f.growth_iterations, 1, 10000,
            "consecutive images with a growing |e| that stop the servo");
  p.readDouble("safety/growth_floor", &f.growth_floor, 0.0, 1.0,
               "|e| at or below this never counts as growing (the noise near the goal)");
  p.readVector3("safety/workspace_min_m", &f.workspace_min_m,
                "lower corner [x, y, z] of the workspace box of the left camera's centre in ~safety/world_frame (m)");
  p.readVector3("safety/workspace_max_m", &f.workspace_max_m,
                "upper corner [x, y, z] of the workspace box (m), above the lower corner on every axis");
  p.readVector3("safety/workspace_centre_m", &f.workspace_centre_m, "centre [x, y, z] of the workspace sphere (m)");
  p.readDouble("safety/workspace_radius_m", &f.workspace_radius_m, 0.0, 1000.0,
               "radius of the workspace sphere (m), 0 disables it");
  const std::string safety_problems = f.validate();
  if (!safety_problems.empty()) throw std::invalid_argument("safety parameters (~safety/...): " + safety_problems);
  p.readString("safety/world_frame", &c.world_frame, {}, "frame of the workspace (the arm's base)");
  p.readPositiveDouble("safety/tf_timeout_s", &c.tf_timeout_s, 10.0,
                       "wait for the left camera's pose at an image's stamp (s)");

  JointSafetyConfig& j = c.joints;
  p.readBool("safety/check_joints", &j.enabled, "check joint_states against the joint limits");
  p.readStringList("safety/joint_names", &j.names, "the checked joints' names in joint_states");
  const int n = static_cast<int>(j.names.size());
  p.readNumberList("safety/joint_min_rad", n, &j.min_rad, "lower position limit of each joint (rad)");
  p.readNumberList("safety/joint_max_rad", n, &j.max_rad, "upper position limit of each joint (rad)");
  p.readNumberList("safety/joint_max_velocity_rad_s", n, &j.max_velocity_rad_s, "velocity limit of each joint (rad/s)");
  p.readDouble("safety/joint_margin_rad", &j.margin_rad, 0.0, 1.0, "stop this far inside a joint limit (rad)");
  p.readDouble(
      "safety/joint_lookahead_s", &j.lookahead_s, 0.0, 10.0,
      "time a command acts before the next check (s): a joint closer to a limit + margin than its velocity limit "
      "times this stops the servo");
  p.readDouble("safety/joint_velocity_tolerance", &j.velocity_tolerance, 0.0, 10.0,
               "stop above (1 + this) times a joint velocity limit");
  p.readPositiveDouble("safety/joint_state_max_age_s", &j.max_age_s, 60.0,
                       "a joint state older than this at an image stops the servo (s)");
  const std::string joint_problems = j.validate();
  if (!joint_problems.empty()) throw std::invalid_argument("safety parameters (~safety/...): " + joint_problems);
  return c;
}

ServoRos::ServoRos(ros::NodeHandle nh, ros::NodeHandle private_nh)
    : nh_(nh),
      pnh_(private_nh),
      config_(readServoNodeConfig(private_nh)),
      diagnostics_(nh, private_nh),
      tf_listener_(tf_buffer_),
      monitor_(config_.safety) {
  left_image_sub_ = nh_.subscribe("left/image_raw", 2, &ServoRos::onLeftImage, this);
  left_depth_sub_ = nh_.subscribe("left/depth", 2, &ServoRos::onLeftDepth, this);
  left_info_sub_ = nh_.subscribe<sensor_msgs::CameraInfo>(
      "left/camera_info", 1, [this](const sensor_msgs::CameraInfoConstPtr& m) { left_.info = m; });
  right_image_sub_ = nh_.subscribe("right/image_raw", 2, &ServoRos::onRightImage, this);
  right_depth_sub_ = nh_.subscribe("right/depth", 2, &ServoRos::onRightDepth, this);
  right_info_sub_ = nh_.subscribe<sensor_msgs::CameraInfo>(
      "right/camera_info", 1, [this](const sensor_msgs::CameraInfoConstPtr& m) { right_.info = m; });
  if (config_.joints.enabled) {
    ros::SubscribeOptions options = ros::SubscribeOptions::create<sensor_msgs::JointState>(
        "joint_states", 5, [this](const sensor_msgs::JointStateConstPtr& m) { onJointState(m); }, ros::VoidPtr(),
        &joint_queue_);
    joint_state_sub_ = nh_.subscribe(options);
    joint_spinner_ = std::make_unique<ros::AsyncSpinner>(1, &joint_queue_);
    joint_spinner_->start();
  }
  velocity_pub_ = nh_.advertise<geometry_msgs::TwistStamped>("arm/camera_velocity", 2);
  status_pub_ = pnh_.advertise<std_msgs::String>("status", 1, true);
  capture_srv_ = pnh_.advertiseService("capture_reference", &ServoRos::onCaptureReference, this);
  stop_srv_ = pnh_.advertiseService("stop", &ServoRos::onStop, this);
  diagnostics_.setHardwareID("exocet stereo servo");
  diagnostics_.add("servo", this, &ServoRos::diagnose);
  std_msgs::String idle;
  idle.data = status_text_;
  status_pub_.publish(idle);
  const control::ServoSafetyConfig& f = config_.safety;
  const std::string sphere =
      f.workspace_radius_m > 0.0 ? ", sphere of " + fixed(f.workspace_radius_m) + " m" : std::string();
  ROS_INFO(
      "servo: safety: joints %s (margin %.3f rad, look-ahead %.2f s), workspace box [%g %g %g] .. [%g %g %g] m in "
      "'%s'%s, at least %d points, |e| growing x%g (above %g) for %d images",
      config_.joints.enabled ? "checked" : "NOT checked", config_.joints.margin_rad, config_.joints.lookahead_s,
      f.workspace_min_m.x(), f.workspace_min_m.y(), f.workspace_min_m.z(), f.workspace_max_m.x(), f.workspace_max_m.y(),
      f.workspace_max_m.z(), config_.world_frame.c_str(), sphere.c_str(), f.min_tracked_points, f.growth_factor,
      f.growth_floor, f.growth_iterations);
}

void ServoRos::onLeftImage(const sensor_msgs::ImageConstPtr& msg) {
  left_.image = msg;
  if (left_.paired()) stepOnLeftPair();
}

void ServoRos::onLeftDepth(const sensor_msgs::ImageConstPtr& msg) {
  left_.depth = msg;
  if (left_.paired()) stepOnLeftPair();
}

bool ServoRos::onCaptureReference(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
  res.success = false;
  if (!right_.paired() || !right_.info || !left_.info) {
    res.message = "no reference yet: need the right camera's image and depth map of one stamp and both camera_info";
    return true;
  }
  if (config_.joints.enabled) {
    // Without a joint state the first safety check would stop the servo at once: refuse until one arrives (the
    // joint_states connection can come up after the image topics'), so the caller tries again.
    std::lock_guard<std::mutex> lock(joint_mutex_);
    if (!joint_state_) {
      res.message =
          "no joint state received yet on " + joint_state_sub_.getTopic() + " (~safety/check_joints is on); try again";
      return true;
    }
  }
  std::string error;
  const cv::Mat image = grayOf(*right_.image, &error);
  const cv::Mat depth = image.empty() ? cv::Mat() : depthOf(*right_.depth, &error);
  if (image.empty() || depth.empty()) {
    res.message = "right camera: " + error;
    return true;
  }
  if (depth.size() != image.size()) {
    res.message = "right camera: depth map " + std::to_string(depth.cols) + "x" + std::to_string(depth.rows) +
                  " does not match the image " + std::to_string(image.cols) + "x" + std::to_string(image.rows);
    return true;
  }
  auto controller = std::make_unique<control::ImageServoController>(
      config_.servo, intrinsicsOf(*right_.info), intrinsicsOf(*left_.info), left_.info->width, left_.info->height);
  error = controller->setReference(image, lookupIn(depth, config_.servo));
  if (!error.empty()) {
    res.message = "reference unusable: " + error;
    return true;
  }
  controller_ = std::move(controller);
  reference_stamp_ = right_.image->header.stamp;
  state_ = State::kServoing;
  iterations_ = 0;
  monitor_.reset();
  safety_stopped_ = false;
  safety_reason_.clear();
  ++servoings_;
  status_text_ = "servoing";
  std_msgs::String s;
  s.data = status_text_;
  status_pub_.publish(s);
  res.success = true;
  res.message = "reference captured from the right camera at " + std::to_string(reference_stamp_.toSec());
  ROS_INFO("servo: %s", res.message.c_str());
  return true;
}

bool ServoRos::onStop(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
  if (state_ == State::kServoing) finish("stopped: by the operator");
  res.success = true;
  res.message = status_text_;
  return true;
}

void ServoRos::stepOnLeftPair() {
  const ros::Time stamp = left_.image->header.stamp;
  if (state_ != State::kServoing || stamp <= reference_stamp_ || stamp == last_processed_stamp_) return;
  {
    // An image exposed before the last command was sent cannot show its motion: a velocity computed from it repeats
    // that command, and the arm overshoots. A servo that falls behind (a loaded machine, images queued) would do that
    // at every image; it waits for an image that shows its last command instead.
    std::lock_guard<std::mutex> lock(joint_mutex_);
    if (stamp <= last_command_time_) {
      ++stale_images_;
      return;
    }
  }
  last_processed_stamp_ = stamp;
  left_frame_ = left_.image->header.frame_id;
  std::string error;
  const cv::Mat image = grayOf(*left_.image, &error);
  const cv::Mat depth = image.empty() ? cv::Mat() : depthOf(*left_.depth, &error);
  if (image.empty() || depth.empty() || depth.size() != image.size()) {
    // A corrupt image is skipped (the arm stops until a good one): the servoing goes on.
    ++corrupt_images_;
    ROS_ERROR_THROTTLE(5.0, "servo: left camera: %s",
                       error.empty() ? "depth map size differs from the image" : error.c_str());
    publishVelocity(Eigen::Matrix<double, 6, 1>::Zero(), stamp);
    return;
  }
  last_step_ = controller_->step(image, lookupIn(depth, config_.servo));
  ++iterations_;
  ROS_DEBUG("servo: image %d: %s, |e| %.6f, %d points%s%s", iterations_, control::toString(last_step_.status).c_str(),
            last_step_.error_norm, last_step_.points, last_step_.rematched ? ", re-matched" : "",
            last_step_.anchored ? ", anchored" : "");
  switch (last_step_.status) {
    case control::ImageStepStatus::kRunning:
      if (iterations_ >= config_.servo.servo.max_iterations) {
        finish("max iterations: not converged after " + std::to_string(iterations_) + " images (|e| " +
               std::to_string(last_step_.error_norm) + ")");
        return;
      }
      {
        // The last line before the command: nothing is sent once a check fails.
        // A re-matching gives the law a new point set: |e| is not comparable across it, the growth history restarts.
        if (last_step_.rematched) monitor_.reset();
        const std::string reason = checkSafety(stamp);
        if (!reason.empty()) {
          safetyStop(reason);
          return;
        }
      }
      publishVelocity(
          control::limitTwist(last_step_.velocity, config_.max_linear_speed_mps, config_.max_angular_speed_rps), stamp);
      break;
    case control::ImageStepStatus::kConverged:
      ++converged_;
      finish("converged: |e| " + std::to_string(last_step_.error_norm) + " after " + std::to_string(iterations_) +
             " images, " + std::to_string(last_step_.points) + " points");
      break;
    case control::ImageStepStatus::kLostTracking:  // re-matching failed: a safety stop as well
      safetyStop(control::toString(last_step_.status) + ": " + last_step_.message);
      return;
    default:
      finish(control::toString(last_step_.status) + ": " + last_step_.message);
      break;
  }
  diagnostics_.update();
}

void ServoRos::onJointState(const sensor_msgs::JointStateConstPtr& msg) {
  std::lock_guard<std::mutex> lock(joint_mutex_);
  joint_state_ = msg;
}

sensor_msgs::JointStateConstPtr ServoRos::jointStateAt(const ros::Time& image_stamp) {
  const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(config_.tf_timeout_s);
  while (true) {
    {
      std::lock_guard<std::mutex> lock(joint_mutex_);
      if ((joint_state_ && joint_state_->header.stamp >= image_stamp) || ros::WallTime::now() > deadline || !ros::ok())
        return joint_state_;
    }
    ros::WallDuration(0.002).sleep();
  }
}

sensor_msgs::JointStateConstPtr ServoRos::jointStateAfterLastCommand() {
  const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(config_.joints.max_age_s);
  while (true) {
    {
      std::lock_guard<std::mutex> lock(joint_mutex_);
      if (joint_state_->header.stamp > last_command_time_ || ros::WallTime::now() > deadline || !ros::ok())
        return joint_state_;
    }
    ros::WallDuration(0.002).sleep();
  }
}

std::string ServoRos::checkSafety(const ros::Time& stamp) {
  control::SafetyInput in;
  in.tracked_points = last_step_.points;
  in.error_norm = last_step_.error_norm;
  if (config_.joints.enabled) {
    // The joint state of the image's tick (published with it).
    const sensor_msgs::JointStateConstPtr joint_state = jointStateAt(stamp);
    if (!joint_state) return "joint limit: no joint state received on " + joint_state_sub_.getTopic();
    const double age_s = (stamp - joint_state->header.stamp).toSec();
    if (age_s > config_.joints.max_age_s) {
      return "joint limit: the joint state is " + fixed(age_s, 2) + " s older than the image, more than " +
             fixed(config_.joints.max_age_s, 2) + " s (~safety/joint_state_max_age_s)";
    }
    sensor_msgs::JointStateConstPtr checked = joint_state;
    bool stale = false;
    {
      std::lock_guard<std::mutex> lock(joint_mutex_);
      stale = joint_state->header.stamp <= last_command_time_;
    }
    if (stale) {
      // The last command may have moved the arm since this state: when that could matter (a joint within two
      // periods' reach of its limit), wait for a state that shows it. Not always: waiting puts the loop one image
      // behind (a velocity computed from an image that misses the previous command overshoots).
      JointSafetyConfig two_periods = config_.joints;
      two_periods.lookahead_s *= 2.0;
      if (!checkJointState(two_periods, *joint_state).empty()) {
        checked = jointStateAfterLastCommand();
        std::lock_guard<std::mutex> lock(joint_mutex_);
        if (checked->header.stamp <= last_command_time_)
          return "joint limit: no joint state on " + joint_state_sub_.getTopic() + " after the last command within " +
                 fixed(config_.joints.max_age_s, 2) + " s (~safety/joint_state_max_age_s), near a joint limit";
      }
    }
    const std::string joints = checkJointState(config_.joints, *checked);
    if (!joints.empty()) {
      in.arm_status = arm::ArmStatus::kJointLimit;
      in.arm_message = joints;
    }
  }
  try {
    const geometry_msgs::TransformStamped t =
        tf_buffer_.lookupTransform(config_.world_frame, left_frame_, stamp, ros::Duration(config_.tf_timeout_s));
    in.camera_position_m =
        Eigen::Vector3d(t.transform.translation.x, t.transform.translation.y, t.transform.translation.z);
  } catch (const tf2::TransformException& e) {
    return "left workspace: the left camera's pose is unknown ('" + config_.world_frame + "' -> '" + left_frame_ +
           "' at the image's stamp: " + e.what() + ")";
  }
  if (monitor_.update(in) != control::SafetyStatus::kOk) return monitor_.message();
  return "";
}

void ServoRos::safetyStop(const std::string& reason) {
  safety_stopped_ = true;
  safety_reason_ = reason;
  ++safety_stops_;
  ROS_ERROR_THROTTLE(1.0, "servo: safety stop: %s", reason.c_str());
  finish("safety stop: " + reason);
}

void ServoRos::finish(const std::string& status) {
  state_ = State::kDone;
  status_text_ = status;
  publishVelocity(Eigen::Matrix<double, 6, 1>::Zero(), ros::Time::now());
  std_msgs::String s;
  s.data = status_text_;
  status_pub_.publish(s);
  if (status.rfind("converged", 0) == 0)
    ROS_INFO("servo: %s", status.c_str());
  else if (!safety_stopped_)  // a safety stop is logged as an error by safetyStop()
    ROS_WARN("servo: %s", status.c_str());
  diagnostics_.force_update();
}

void ServoRos::publishVelocity(const Eigen::Matrix<double, 6, 1>& twist, const ros::Time& stamp) {
  geometry_msgs::TwistStamped msg;
  msg.header.stamp = stamp;
  msg.header.frame_id = left_frame_;
  msg.twist.linear.x = twist[0];
  msg.twist.linear.y = twist[1];
  msg.twist.linear.z = twist[2];
  msg.twist.angular.x = twist[3];
  msg.twist.angular.y = twist[4];
  msg.twist.angular.z = twist[5];
  velocity_pub_.publish(msg);
  // Taken once the command is sent: an image stamped later is from a tick that had it (up to the transport time).
  std::lock_guard<std::mutex> lock(joint_mutex_);
  last_command_time_ = ros::Time::now();
}

void ServoRos::diagnose(diagnostic_updater::DiagnosticStatusWrapper& status) {
  using diagnostic_msgs::DiagnosticStatus;
  const bool failed = state_ == State::kDone && status_text_.rfind("converged", 0) != 0;
  status.summary(safety_stopped_ ? DiagnosticStatus::ERROR
                 : failed        ? DiagnosticStatus::WARN
                                 : DiagnosticStatus::OK,
                 status_text_);
  status.add("safety stop", safety_stopped_ ? safety_reason_ : std::string("none"));
  status.add("safety stops", safety_stops_);
  status.add("images this servoing", iterations_);
  status.add("|e|", last_step_.error_norm);
  status.add("points", last_step_.points);
  status.add("re-matchings", controller_ ? controller_->rematches() : 0);
  status.add("re-matchings on a stalled law", controller_ ? controller_->stallRematches() : 0);
  status.add("servoings", servoings_);
  status.add("converged", converged_);
  status.add("corrupt images", corrupt_images_);
  status.add("stale images skipped", stale_images_);
}

}  // namespace exocet_servo
