#include "exocet_mosaic/ros/display_image_publisher.h"

#include <cv_bridge/cv_bridge.h>
#include <opencv2/imgproc.hpp>

#include "exocet_common/ros/parameter_reader.h"
#include "exocet_mosaic/ros/image_message_decoder.h"

namespace exocet_mosaic {

DisplayImageConfig readDisplayImageConfig(const ros::NodeHandle& private_nh) {
  DisplayImageConfig c;
  const exocet_common::ParameterReader params(private_nh);
  params.readTopic("image_topic", &c.image_topic);
  params.readTopic("display_topic", &c.display_topic);
  params.readString("transport", &c.transport, {"compressed", "raw"}, "the camera topic's transport");
  params.readInt("max_width_px", &c.max_width_px, 16, 100000, "wider images are scaled down to this width");
  params.readDouble("max_rate_hz", &c.max_rate_hz, 1e-3, 1000.0, "images published per second at most");
  return c;
}

DisplayImagePublisher::DisplayImagePublisher(ros::NodeHandle nh, ros::NodeHandle private_nh)
    : nh_(nh), private_nh_(private_nh), config_(readDisplayImageConfig(private_nh)) {
  const auto changed = [this](const ros::SingleSubscriberPublisher&) { onSubscribers(); };
  display_pub_ = nh_.advertise<sensor_msgs::Image>(config_.display_topic, 1, changed, changed);
  updater_.setHardwareID("display of " + config_.image_topic);
  updater_.add("display image", this, &DisplayImagePublisher::diagnose);
  const double period_s = updater_.getPeriod() > 0.0 ? updater_.getPeriod() : 1.0;
  diagnostics_timer_ = nh_.createSteadyTimer(ros::WallDuration(period_s),
                                             [this](const ros::SteadyTimerEvent&) { updater_.force_update(); });
  ROS_INFO("display image: %s (%s) -> %s, at most %d px wide and %.1f images/s, decoded only while watched",
           config_.image_topic.c_str(), config_.transport.c_str(), config_.display_topic.c_str(), config_.max_width_px,
           config_.max_rate_hz);
}

void DisplayImagePublisher::onSubscribers() {
  std::lock_guard<std::mutex> lock(mutex_);
  const bool watched = display_pub_.getNumSubscribers() > 0;
  if (watched && !image_sub_) {
    if (config_.transport == "compressed")
      image_sub_ = nh_.subscribe(config_.image_topic + "/compressed", 1, &DisplayImagePublisher::onCompressed, this);
    else
      image_sub_ = nh_.subscribe(config_.image_topic, 1, &DisplayImagePublisher::onRaw, this);
  } else if (!watched && image_sub_) {
    image_sub_.shutdown();
    image_sub_ = ros::Subscriber();
  }
}

bool DisplayImagePublisher::due(const ros::Time&) {
  // Wall time: a replay at 8x must not make the display decode 8 times more.
  const ros::WallTime now = ros::WallTime::now();
  ++received_;
  if (!last_published_.isZero() && (now - last_published_).toSec() < 1.0 / config_.max_rate_hz) return false;
  last_published_ = now;
  return true;
}

namespace {
cv::Mat scaledDown(const cv::Mat& image, int max_width_px) {
  if (image.cols <= max_width_px) return image;
  cv::Mat out;
  const double f = static_cast<double>(max_width_px) / image.cols;
  cv::resize(image, out, cv::Size(), f, f, cv::INTER_AREA);
  return out;
}
}  // namespace

void DisplayImagePublisher::onCompressed(const sensor_msgs::CompressedImageConstPtr& msg) {
  if (!due(msg->header.stamp)) return;
  DecodedImage decoded;
  const std::string problem = decodeCompressedImage(*msg, &decoded);
  cv::Mat shown;
  try {
    if (problem.empty()) shown = toDisplayImage(decoded.image, decoded.encoding);
  } catch (const std::invalid_argument& e) {
    last_problem_ = e.what();
  }
  if (shown.empty()) {
    ++failures_;
    if (!problem.empty()) last_problem_ = problem;
    ROS_WARN_THROTTLE(10.0, "display image: %s", last_problem_.c_str());
    return;
  }
  shown = scaledDown(shown, config_.max_width_px);
  display_pub_.publish(cv_bridge::CvImage(msg->header, shown.channels() == 1 ? "mono8" : "bgr8", shown).toImageMsg());
  ++published_;
}

void DisplayImagePublisher::onRaw(const sensor_msgs::ImageConstPtr& msg) {
  if (!due(msg->header.stamp)) return;
  cv::Mat shown;
  try {
    shown = toDisplayImage(cv_bridge::toCvShare(msg)->image, msg->encoding);
  } catch (const std::exception& e) {
    ++failures_;
    last_problem_ = e.what();
    ROS_WARN_THROTTLE(10.0, "display image: %s", last_problem_.c_str());
    return;
  }
  shown = scaledDown(shown, config_.max_width_px);
  display_pub_.publish(cv_bridge::CvImage(msg->header, shown.channels() == 1 ? "mono8" : "bgr8", shown).toImageMsg());
  ++published_;
}

void DisplayImagePublisher::diagnose(diagnostic_updater::DiagnosticStatusWrapper& status) {
  const bool watched = display_pub_.getNumSubscribers() > 0;
  if (failures_ > 0 && !last_problem_.empty())
    status.summary(diagnostic_msgs::DiagnosticStatus::WARN, "images that could not be decoded: " + last_problem_);
  else
    status.summary(diagnostic_msgs::DiagnosticStatus::OK, watched ? "decoding for a display" : "idle: nobody watches");
  status.add("displays subscribed", display_pub_.getNumSubscribers());
  status.add("images received", received_);
  status.add("images published", published_);
  status.add("images that could not be decoded", failures_);
}

}  // namespace exocet_mosaic
