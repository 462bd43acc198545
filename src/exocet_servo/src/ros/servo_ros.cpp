#include "exocet_servo/ros/servo_ros.h"

#include <cmath>
#include <limits>
#include <stdexcept>

#include <cv_bridge/cv_bridge.h>
#include <geometry_msgs/TwistStamped.h>
#include <sensor_msgs/image_encodings.h>
#include <std_msgs/String.h>

#include "exocet_mosaic/ros/parameter_reader.h"
#include "exocet_servo/control/twist_limit.h"
#include "exocet_servo/sim/vent_renderer.h"

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

/// The depth map as metres in CV_32F with +inf where unknown (the convention of sim::RenderedView), or empty.
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
  auto view = std::make_shared<sim::RenderedView>();
  view->depth_m = depth_m;
  return [view, radius = config.depth_check_radius_px, step = config.depth_max_relative_step](
             const Eigen::Vector2d& px) {
    double d = 0.0;
    return view->smoothDepthAt(px, radius, step, &d) ? d : std::numeric_limits<double>::quiet_NaN();
  };
}

}  // namespace

ServoNodeConfig readServoNodeConfig(const ros::NodeHandle& private_nh) {
  ServoNodeConfig c;
  const exocet_mosaic::ParameterReader p(private_nh);
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
  p.readInt("max_iterations", &s.servo.max_iterations, 1, 1000000, "images per servoing before it gives up");
  p.readDouble("sift_ratio", &s.matcher.ratio, 0.3, 1.0, "Lowe's ratio test of the SIFT matching");
  p.readInt("max_points", &s.max_points, 4, 100000, "points given to the law");
  p.readInt("max_rematches", &s.max_rematches, 0, 100000, "SIFT re-matchings allowed in one servoing");
  p.readInt("min_tracked_points", &s.tracker.min_points, 4, 100000, "tracked points below which SIFT re-matches");
  p.readPositiveDouble("max_linear_speed_mps", &c.max_linear_speed_mps, 10.0, "camera speed limit (m/s)");
  p.readPositiveDouble("max_angular_speed_rps", &c.max_angular_speed_rps, 10.0, "camera rotation speed limit (rad/s)");
  const std::string problems = s.validate();
  if (!problems.empty()) throw std::invalid_argument("servo parameters: " + problems);
  return c;
}

ServoRos::ServoRos(ros::NodeHandle nh, ros::NodeHandle private_nh)
    : nh_(nh), pnh_(private_nh), config_(readServoNodeConfig(private_nh)), diagnostics_(nh, private_nh) {
  left_image_sub_ = nh_.subscribe("left/image_raw", 2, &ServoRos::onLeftImage, this);
  left_depth_sub_ = nh_.subscribe("left/depth", 2, &ServoRos::onLeftDepth, this);
  left_info_sub_ = nh_.subscribe<sensor_msgs::CameraInfo>(
      "left/camera_info", 1, [this](const sensor_msgs::CameraInfoConstPtr& m) { left_.info = m; });
  right_image_sub_ = nh_.subscribe("right/image_raw", 2, &ServoRos::onRightImage, this);
  right_depth_sub_ = nh_.subscribe("right/depth", 2, &ServoRos::onRightDepth, this);
  right_info_sub_ = nh_.subscribe<sensor_msgs::CameraInfo>(
      "right/camera_info", 1, [this](const sensor_msgs::CameraInfoConstPtr& m) { right_.info = m; });
  velocity_pub_ = nh_.advertise<geometry_msgs::TwistStamped>("arm/camera_velocity", 2);
  status_pub_ = pnh_.advertise<std_msgs::String>("status", 1, true);
  capture_srv_ = pnh_.advertiseService("capture_reference", &ServoRos::onCaptureReference, this);
  stop_srv_ = pnh_.advertiseService("stop", &ServoRos::onStop, this);
  diagnostics_.setHardwareID("exocet stereo servo");
  diagnostics_.add("servo", this, &ServoRos::diagnose);
  std_msgs::String idle;
  idle.data = status_text_;
  status_pub_.publish(idle);
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
  last_processed_stamp_ = stamp;
  left_frame_ = left_.image->header.frame_id;
  std::string error;
  const cv::Mat image = grayOf(*left_.image, &error);
  const cv::Mat depth = image.empty() ? cv::Mat() : depthOf(*left_.depth, &error);
  if (image.empty() || depth.empty() || depth.size() != image.size()) {
    // A corrupt image is skipped (the arm stops until a good one): the servoing goes on.
    ++corrupt_images_;
    ROS_ERROR_THROTTLE(5.0, "servo: left camera: %s", error.empty() ? "depth map size differs from the image" : error.c_str());
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
      publishVelocity(control::limitTwist(last_step_.velocity, config_.max_linear_speed_mps, config_.max_angular_speed_rps),
                      stamp);
      break;
    case control::ImageStepStatus::kConverged:
      ++converged_;
      finish("converged: |e| " + std::to_string(last_step_.error_norm) + " after " + std::to_string(iterations_) +
             " images, " + std::to_string(last_step_.points) + " points");
      break;
    default:
      finish(control::toString(last_step_.status) + ": " + last_step_.message);
      break;
  }
  diagnostics_.update();
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
  else
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
}

void ServoRos::diagnose(diagnostic_updater::DiagnosticStatusWrapper& status) {
  using diagnostic_msgs::DiagnosticStatus;
  const bool failed = state_ == State::kDone && status_text_.rfind("converged", 0) != 0;
  status.summary(failed ? DiagnosticStatus::WARN : DiagnosticStatus::OK, status_text_);
  status.add("images this servoing", iterations_);
  status.add("|e|", last_step_.error_norm);
  status.add("points", last_step_.points);
  status.add("re-matchings", controller_ ? controller_->rematches() : 0);
  status.add("servoings", servoings_);
  status.add("converged", converged_);
  status.add("corrupt images", corrupt_images_);
}

}  // namespace exocet_servo
