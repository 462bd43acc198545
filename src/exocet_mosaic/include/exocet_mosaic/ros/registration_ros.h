/**
 * @file registration_ros.h
 * @brief ROS wrapper of the frame-to-frame registration: camera images in, one exocet_msgs/ImageMotion per image
 * pair out, health on /diagnostics. The node and the nodelet are a few lines over this class.
 */
#pragma once

#include <deque>
#include <map>
#include <memory>
#include <string>

#include <diagnostic_updater/diagnostic_updater.h>
#include <diagnostic_updater/publisher.h>
#include <dynamic_reconfigure/server.h>
#include <exocet_mosaic/RegistrationConfig.h>
#include <image_transport/image_transport.h>
#include <ros/ros.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/CompressedImage.h>
#include <sensor_msgs/Image.h>

#include "exocet_mosaic/registration/gray_converter.h"
#include "exocet_mosaic/registration/registration_config.h"
#include "exocet_mosaic/registration/sequence_registrar.h"
#include "exocet_mosaic/ros/dive_topics.h"
#include "exocet_mosaic/ros/keyed_throttle.h"

namespace exocet_mosaic {

/// Settings of the registration node; each is the private parameter of the same name (see readRegistrationNodeConfig).
struct RegistrationNodeConfig {
  registration::RegistrationConfig registration;   ///< ~method, ~model, ~klt/..., ~rmr/...
  registration::SequenceRegistrarConfig sequence;  ///< ~max_gap_s, ~undistort
  std::string image_topic = topics::kImageRaw;     ///< sensor_msgs/Image; `<image_topic>/compressed` is also watched
  /// auto: the first of raw (image_transport) and `<image_topic>/compressed` that delivers; raw; compressed. The
  /// compressed topic is decoded here because Debian's ROS has no compressed_image_transport plugin.
  std::string transport = "auto";
  std::string motion_topic = topics::kMosaicMotion;  ///< exocet_msgs/ImageMotion
  /// sensor_msgs/CameraInfo; empty: the image topic's sibling camera_info (image_transport's convention)
  std::string camera_info_topic;
  int queue_size = 30;                 ///< subscriber queue (images) [1, 1000]
  double expected_rate_hz = 0.0;       ///< nominal camera rate for /diagnostics, 0 = unknown [0, 1000]
  int quality_window = 50;             ///< pairs over which /diagnostics computes the failure fraction [5, 10000]
  double warn_failure_fraction = 0.2;  ///< above it, /diagnostics warns; above 4x (capped at 0.8), error (0, 1]
};

/**
 * @brief Reads and checks every parameter from `private_nh`.
 * @throws std::invalid_argument naming the parameter, its value and the allowed range.
 */
RegistrationNodeConfig readRegistrationNodeConfig(const ros::NodeHandle& private_nh);

/**
 * @brief Converts and wires: images and camera_info in, handed to a registration::SequenceRegistrar (the policy:
 * undistortion, restarts, prediction, fallback), one exocet_msgs/ImageMotion per image pair out.
 *
 * Every image pair gives one message, failures included (failed = true, with the reason); the first image of a
 * sequence gives none (see SequenceRegistrar for when a sequence restarts). Undecodable images, unsupported
 * encodings and data that does not match its header are counted, logged (throttled) and skipped. Counts, rates,
 * failures by reason, inliers and processing time are on /diagnostics.
 */
class RegistrationRos {
 public:
  /// @throws std::invalid_argument for a bad parameter.
  RegistrationRos(ros::NodeHandle nh, ros::NodeHandle private_nh);

 private:
  void onImage(const sensor_msgs::ImageConstPtr& msg);
  void onCompressed(const sensor_msgs::CompressedImageConstPtr& msg);
  void onCameraInfo(const sensor_msgs::CameraInfoConstPtr& msg);
  /// Takes the first transport that delivers when ~transport is auto; false if this one must be ignored.
  bool acceptTransport(const std::string& transport);
  void process(const cv::Mat& image, const std::string& encoding, const std_msgs::Header& header);
  /// Registers one grey image and publishes its motion.
  void registerImage(const cv::Mat& gray, const std_msgs::Header& header);
  /// Keeps an image that came before the first camera_info (bounded: the oldest go first).
  void holdImage(const cv::Mat& gray, const std_msgs::Header& header);
  /// Registers the held images, oldest first (the camera_info came, or the wait ran out).
  void releaseHeldImages();
  void reject(const std::string& why);
  void noteRestart(const std::string& why);
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& status);
  void onReconfigure(exocet_mosaic::RegistrationConfig& config, uint32_t level);

  ros::NodeHandle nh_;
  ros::NodeHandle private_nh_;
  RegistrationNodeConfig config_;
  std::unique_ptr<registration::SequenceRegistrar> sequence_;
  // The operator's knobs (method, model, ...). Node and nodelet run the callbacks on one thread (ST node handles).
  std::unique_ptr<dynamic_reconfigure::Server<exocet_mosaic::RegistrationConfig>> reconfigure_server_;
  boost::recursive_mutex reconfigure_mutex_;  // dynamic_reconfigure wants a boost mutex
  long reconfigurations_ = 0;
  registration::GrayConverter converter_;

  image_transport::ImageTransport image_transport_;
  image_transport::Subscriber raw_subscriber_;
  ros::Subscriber compressed_subscriber_;
  ros::Subscriber camera_info_subscriber_;
  ros::Time previous_stamp_;  ///< of the last image the sequence accepted
  std::string active_transport_;
  ros::Publisher motion_publisher_;

  diagnostic_updater::Updater updater_;
  std::unique_ptr<diagnostic_updater::FrequencyStatus> image_rate_;
  double min_rate_hz_ = 0.0, max_rate_hz_ = 0.0;
  ros::SteadyTimer diagnostics_timer_;

  // Counts for /diagnostics.
  uint64_t images_ = 0, rejected_ = 0, pairs_ = 0, failures_ = 0, restarts_ = 0;
  struct HeldImage {
    cv::Mat gray;
    std_msgs::Header header;
  };
  std::deque<HeldImage> held_images_;  ///< before the first camera_info, within ~camera_info_wait_s
  std::size_t held_bytes_ = 0;
  uint64_t held_for_camera_info_ = 0;             ///< images held back before the first camera_info
  uint64_t dropped_waiting_for_camera_info_ = 0;  ///< held images let go to stay within the bound
  std::map<std::string, uint64_t> failures_by_reason_;
  std::deque<bool> recent_failures_;
  std::deque<double> recent_inlier_fraction_;
  double processing_ms_sum_ = 0.0, processing_ms_max_ = 0.0;
  std::string last_problem_;
  KeyedThrottle reject_log_{5.0};  ///< rejected images, per kind of problem
};

}  // namespace exocet_mosaic
