/**
 * @file display_image_publisher.h
 * @brief The camera's images decoded for displays (rviz's Image display reads raw images only, and Debian has no
 * compressed image_transport plugin for it): subscribes to the compressed (or raw) camera topic only while someone
 * watches its output, decodes at most max_rate_hz images a second, scales them down to max_width_px and publishes
 * them as bgr8 / mono8 sensor_msgs/Image. Nothing is decoded while nobody subscribes.
 */
#pragma once

#include <cstdint>
#include <mutex>
#include <string>

#include <diagnostic_updater/diagnostic_updater.h>
#include <ros/ros.h>
#include <sensor_msgs/CompressedImage.h>
#include <sensor_msgs/Image.h>

namespace exocet_mosaic {

/// Parameters (private namespace), each checked against its range.
struct DisplayImageConfig {
  std::string image_topic = "/camera/image_raw";  ///< its /compressed sibling is read, or the raw topic (transport)
  std::string transport = "compressed";           ///< compressed | raw
  std::string display_topic = "/camera/image_display";
  int max_width_px = 640;     ///< wider images are scaled down, [16, 100000]
  double max_rate_hz = 10.0;  ///< images published per second at most, (0, 1000]
};

/// @throws std::invalid_argument naming the parameter, its value and its allowed range
DisplayImageConfig readDisplayImageConfig(const ros::NodeHandle& private_nh);

/// The node's ROS class.
class DisplayImagePublisher {
 public:
  DisplayImagePublisher(ros::NodeHandle nh, ros::NodeHandle private_nh);

 private:
  void onSubscribers();  // a display came or went: subscribe upstream only while one watches
  void onCompressed(const sensor_msgs::CompressedImageConstPtr& msg);
  void onRaw(const sensor_msgs::ImageConstPtr& msg);
  bool due(const ros::Time& stamp);
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& status);

  ros::NodeHandle nh_, private_nh_;
  DisplayImageConfig config_;
  ros::Publisher display_pub_;
  ros::Subscriber image_sub_;
  std::mutex mutex_;
  ros::WallTime last_published_;
  diagnostic_updater::Updater updater_;
  ros::SteadyTimer diagnostics_timer_;
  std::int64_t received_ = 0, published_ = 0, failures_ = 0;
  std::string last_problem_;
};

}  // namespace exocet_mosaic
