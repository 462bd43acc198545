#include "exocet_mosaic/ros/registration_ros.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include <cv_bridge/cv_bridge.h>
#include <exocet_msgs/ImageMotion.h>
#include <image_transport/camera_common.h>
#include <opencv2/imgcodecs.hpp>

#include "exocet_common/ros/parameter_reader.h"
#include "exocet_mosaic/ros/image_message_decoder.h"
#include "exocet_mosaic/ros/registration_parameters.h"

namespace exocet_mosaic {

using diagnostic_msgs::DiagnosticStatus;
namespace reg = registration;

namespace {
constexpr uint32_t kOutgoingQueue = 1000;  // motions per subscriber link (5 s at 8x PAL replay)
}  // namespace

RegistrationNodeConfig readRegistrationNodeConfig(const ros::NodeHandle& private_nh) {
  RegistrationNodeConfig config;
  config.registration = readRegistrationConfig(private_nh);
  const exocet_common::ParameterReader params(private_nh);
  params.readTopic("image_topic", &config.image_topic);
  params.readString("transport", &config.transport, {"auto", "raw", "compressed"},
                    "which image topic to listen to: raw (image_transport), compressed (<image_topic>/compressed, "
                    "decoded here) or auto (the first that delivers)");
  params.readTopic("motion_topic", &config.motion_topic);
  config.camera_info_topic = image_transport::getCameraInfoTopic(config.image_topic);
  params.readTopic("camera_info_topic", &config.camera_info_topic);
  params.readBool("undistort", &config.sequence.undistort,
                  "undistort the images with the camera_info's distortion coefficients before registering them");
  config.sequence.calibration_wait_s = 3.0;  // a live subscription may see images before its first camera_info
  params.readDouble("camera_info_wait_s", &config.sequence.calibration_wait_s, 0.0, 60.0,
                    "seconds of images held back at the start until the first camera_info comes (a late "
                    "subscription must not start the fusion with failed pairs); past it, images are registered "
                    "without calibration");
  params.readPositiveDouble("max_gap_s", &config.sequence.max_gap_s, 3600.0,
                            "seconds between two images beyond which the sequence restarts");
  params.readInt("queue_size", &config.queue_size, 1, 1000, "images waiting to be registered");
  params.readDouble("expected_rate_hz", &config.expected_rate_hz, 0.0, 1000.0,
                    "nominal camera frame rate for /diagnostics, 0 when unknown");
  params.readInt("quality_window", &config.quality_window, 5, 10000,
                 "image pairs over which /diagnostics computes the failure fraction");
  params.readPositiveDouble("warn_failure_fraction", &config.warn_failure_fraction, 1.0,
                            "fraction of failed pairs above which /diagnostics warns");
  return config;
}

RegistrationRos::RegistrationRos(ros::NodeHandle nh, ros::NodeHandle private_nh)
    : nh_(nh), private_nh_(private_nh), config_(readRegistrationNodeConfig(private_nh)), image_transport_(nh) {
  sequence_ = std::make_unique<reg::SequenceRegistrar>(reg::makeRegistrar(config_.registration), config_.sequence);
  // Each subscriber (fusion, tile writer, a recorder) has its own outgoing queue of this length: one that lags by
  // more (a fast replay on a loaded machine) silently loses motions, and a lost motion breaks its chain.
  motion_publisher_ = nh_.advertise<exocet_msgs::ImageMotion>(config_.motion_topic, kOutgoingQueue);
  if (config_.transport != "compressed")
    raw_subscriber_ = image_transport_.subscribe(config_.image_topic, config_.queue_size, &RegistrationRos::onImage,
                                                 this, image_transport::TransportHints("raw"));
  if (config_.transport != "raw")
    compressed_subscriber_ =
        nh_.subscribe(config_.image_topic + "/compressed", config_.queue_size, &RegistrationRos::onCompressed, this);

  camera_info_subscriber_ = nh_.subscribe(config_.camera_info_topic, 5, &RegistrationRos::onCameraInfo, this);

  updater_.setHardwareID("registration " + reg::toString(config_.registration.method));
  min_rate_hz_ = config_.expected_rate_hz > 0.0 ? 0.5 * config_.expected_rate_hz : 0.0;
  max_rate_hz_ = config_.expected_rate_hz > 0.0 ? 2.0 * config_.expected_rate_hz : 1e9;
  image_rate_ = std::make_unique<diagnostic_updater::FrequencyStatus>(
      diagnostic_updater::FrequencyStatusParam(&min_rate_hz_, &max_rate_hz_, 0.1, 10), "images");
  updater_.add(*image_rate_);
  updater_.add("registration", this, &RegistrationRos::diagnose);
  // Wall-clock timer: /diagnostics goes on when a replay pauses or its clock jumps back.
  const double period_s = updater_.getPeriod() > 0.0 ? updater_.getPeriod() : 1.0;
  diagnostics_timer_ = nh_.createSteadyTimer(ros::WallDuration(period_s),
                                             [this](const ros::SteadyTimerEvent&) { updater_.force_update(); });
  reconfigure_server_ =
      std::make_unique<dynamic_reconfigure::Server<exocet_mosaic::RegistrationConfig>>(reconfigure_mutex_, private_nh_);
  exocet_mosaic::RegistrationConfig start;
  start.method = reg::toString(config_.registration.method);
  start.model = reg::toString(config_.registration.model);
  start.klt_max_features = config_.registration.klt.max_features;
  start.klt_min_tracks = config_.registration.klt.min_tracks;
  start.illumination_enabled = config_.registration.illumination.enabled;
  reconfigure_server_->updateConfig(start);
  reconfigure_server_->setCallback(
      [this](exocet_mosaic::RegistrationConfig& c, uint32_t level) { onReconfigure(c, level); });
  ROS_INFO("registration: method %s, model %s, listening to %s (%s), publishing %s",
           reg::toString(config_.registration.method).c_str(), reg::toString(config_.registration.model).c_str(),
           config_.image_topic.c_str(), config_.transport.c_str(), config_.motion_topic.c_str());
}

bool RegistrationRos::acceptTransport(const std::string& transport) {
  if (active_transport_.empty()) {
    active_transport_ = transport;
    ROS_INFO("registration: receiving %s images", transport.c_str());
    // Only one stream may feed the sequence: the other would register each image against itself.
    if (transport == "raw")
      compressed_subscriber_.shutdown();
    else
      raw_subscriber_.shutdown();
  }
  return active_transport_ == transport;
}

void RegistrationRos::onImage(const sensor_msgs::ImageConstPtr& msg) {
  if (!acceptTransport("raw")) return;
  cv_bridge::CvImageConstPtr cv_image;
  try {
    cv_image = cv_bridge::toCvShare(msg);
  } catch (const std::exception& e) {
    reject("image with encoding '" + msg->encoding + "' cannot be read: " + e.what());
    return;
  }
  process(cv_image->image, msg->encoding, msg->header);
}

void RegistrationRos::onCompressed(const sensor_msgs::CompressedImageConstPtr& msg) {
  if (!acceptTransport("compressed")) return;
  DecodedImage decoded;
  const std::string error = decodeCompressedImage(*msg, &decoded, DecodeMode::kGreyIfJpeg);  // registers grey
  if (!error.empty()) {
    reject(error);
    return;
  }
  process(decoded.image, decoded.encoding, msg->header);
}

void RegistrationRos::onCameraInfo(const sensor_msgs::CameraInfoConstPtr& msg) {
  reg::CameraCalibration calibration;
  calibration.size = cv::Size(int(msg->width), int(msg->height));
  std::copy(msg->K.begin(), msg->K.end(), calibration.k.begin());
  for (size_t i = 0; i < std::min<size_t>(5, msg->D.size()); ++i) calibration.d[i] = msg->D[i];
  calibration.distortion_model = msg->distortion_model;
  sequence_->setCalibration(calibration);
  releaseHeldImages();
}

void RegistrationRos::reject(const std::string& why) {
  ++rejected_;
  last_problem_ = why;
  // Throttled per kind of problem (the text's start): undecodable images must not hide repeated stamps.
  std::uint64_t held_back = 0;
  if (reject_log_.allow(why.substr(0, 32), &held_back))
    ROS_ERROR("registration: skipping an image: %s%s", why.c_str(), reject_log_.heldBackNote(held_back).c_str());
}

void RegistrationRos::onReconfigure(exocet_mosaic::RegistrationConfig& c, uint32_t) {
  reg::RegistrationConfig next = config_.registration;
  std::string error;
  try {
    next.method = reg::registrationMethodFromString(c.method);
    next.model = reg::motionModelFromString(c.model);
    next.klt.max_features = c.klt_max_features;
    next.klt.min_tracks = c.klt_min_tracks;
    next.illumination.enabled = c.illumination_enabled;
    error = next.validate();
  } catch (const std::invalid_argument& e) {
    error = e.what();
  }
  std::unique_ptr<reg::FrameRegistrar> registrar;
  if (error.empty()) {
    try {
      registrar = reg::makeRegistrar(next);
    } catch (const std::invalid_argument& e) {
      error = e.what();
    }
  }
  if (!error.empty()) {
    ROS_ERROR("registration: reconfiguration refused, keeping the settings in force: %s", error.c_str());
    last_problem_ = "reconfiguration refused: " + error;
    // Show the operator what is in force.
    c.method = reg::toString(config_.registration.method);
    c.model = reg::toString(config_.registration.model);
    c.klt_max_features = config_.registration.klt.max_features;
    c.klt_min_tracks = config_.registration.klt.min_tracks;
    c.illumination_enabled = config_.registration.illumination.enabled;
    return;
  }
  if (sequence_) {  // not on the server's first call, which only echoes the start values
    const bool changed = next.method != config_.registration.method || next.model != config_.registration.model ||
                         next.klt.max_features != config_.registration.klt.max_features ||
                         next.klt.min_tracks != config_.registration.klt.min_tracks ||
                         next.illumination.enabled != config_.registration.illumination.enabled;
    if (!changed) return;
  }
  config_.registration = next;
  if (sequence_)
    sequence_->replaceRegistrar(std::move(registrar));  // the new registrar starts its sequence at the next image
  else
    sequence_ = std::make_unique<reg::SequenceRegistrar>(std::move(registrar), config_.sequence);
  ++reconfigurations_;
  updater_.setHardwareID("registration " + reg::toString(next.method));
  ROS_INFO("registration: reconfigured: method %s, model %s, KLT %d features / %d tracks, illumination %s",
           c.method.c_str(), c.model.c_str(), c.klt_max_features, c.klt_min_tracks,
           c.illumination_enabled ? "on" : "off");
}

void RegistrationRos::noteRestart(const std::string& why) {
  ++restarts_;
  last_problem_ = why;
  ROS_WARN_THROTTLE(5.0, "registration: restarting the sequence: %s", why.c_str());
}

void RegistrationRos::process(const cv::Mat& image, const std::string& encoding, const std_msgs::Header& header) {
  ++images_;
  image_rate_->tick();
  cv::Mat gray;
  try {
    gray = converter_.convert(image, encoding);
  } catch (const std::invalid_argument& e) {
    reject(e.what());
    return;
  }
  if (header.stamp.isZero()) {
    reject("image with a zero stamp: the motion would have no time");
    return;
  }
  if (sequence_->holdForCalibration(header.stamp.toSec())) {
    holdImage(gray, header);
    return;
  }
  releaseHeldImages();  // the wait ran out: they go first, without calibration
  registerImage(gray, header);
}

void RegistrationRos::holdImage(const cv::Mat& gray, const std_msgs::Header& header) {
  // At most this much image data waits: 3 s of a 4K camera at 10 frames/s; a faster one loses its oldest images.
  constexpr std::size_t kMaxHeldImages = 100, kMaxHeldBytes = std::size_t(256) << 20;
  ++held_for_camera_info_;
  held_images_.push_back({gray.clone(), header});  // the converter's output may share the message's buffer
  held_bytes_ += gray.total() * gray.elemSize();
  while (held_images_.size() > kMaxHeldImages || held_bytes_ > kMaxHeldBytes) {
    held_bytes_ -= held_images_.front().gray.total() * held_images_.front().gray.elemSize();
    held_images_.pop_front();
    ++dropped_waiting_for_camera_info_;
    ROS_WARN_THROTTLE(5.0,
                      "registration: no camera_info yet on %s: the oldest held image dropped (%lu so far; at most "
                      "%zu images, %zu MB wait)",
                      config_.camera_info_topic.c_str(), static_cast<unsigned long>(dropped_waiting_for_camera_info_),
                      kMaxHeldImages, kMaxHeldBytes >> 20);
  }
  ROS_DEBUG_THROTTLE(1.0, "registration: no camera_info yet on %s: %zu images held", config_.camera_info_topic.c_str(),
                     held_images_.size());
}

void RegistrationRos::releaseHeldImages() {
  if (held_images_.empty()) return;
  if (sequence_->hasCalibration()) {
    ROS_INFO("registration: registering the %zu images held until the first camera_info", held_images_.size());
  } else {
    last_problem_ = "no camera_info on " + config_.camera_info_topic + ": images registered without calibration";
    ROS_WARN(
        "registration: no camera_info on %s within ~camera_info_wait_s = %.1f s of images: registering without "
        "calibration (no undistortion, no camera matrix in the motions)",
        config_.camera_info_topic.c_str(), config_.sequence.calibration_wait_s);
  }
  std::deque<HeldImage> held;
  held.swap(held_images_);
  held_bytes_ = 0;
  for (const HeldImage& image : held) registerImage(image.gray, image.header);
}

void RegistrationRos::registerImage(const cv::Mat& gray, const std_msgs::Header& header) {
  reg::SequenceStep step;
  try {
    step = sequence_->add(gray, header.stamp.toSec());
  } catch (const std::invalid_argument& e) {
    reject(e.what());
    return;
  }
  // The stamp of the image this motion starts from, exactly as it arrived (a double would not round-trip).
  const ros::Time previous_stamp = previous_stamp_;
  previous_stamp_ = header.stamp;
  if (!step.calibration_warning.empty()) {
    last_problem_ = step.calibration_warning;
    ROS_WARN_THROTTLE(30.0, "registration: %s", step.calibration_warning.c_str());
  }
  if (!step.restart_reason.empty()) noteRestart(step.restart_reason);
  if (!step.has_motion) return;

  const reg::MotionEstimate& estimate = step.motion;
  exocet_msgs::ImageMotion msg;
  msg.header = header;
  msg.previous_stamp = previous_stamp;
  msg.method = reg::toString(estimate.method);
  msg.model = reg::toString(estimate.model);
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) msg.matrix[3 * r + c] = estimate.failed ? double(r == c) : estimate.pixel_matrix(r, c);
  msg.centre_px[0] = estimate.centre_px.x();
  msg.centre_px[1] = estimate.centre_px.y();
  if (!estimate.failed) {
    msg.parameters.assign(estimate.parameters.data(), estimate.parameters.data() + estimate.parameters.size());
    const Eigen::MatrixXd cov = estimate.covariance;
    for (int r = 0; r < cov.rows(); ++r)
      for (int c = 0; c < cov.cols(); ++c) msg.covariance.push_back(cov(r, c));
  }
  msg.failed = estimate.failed;
  msg.failure = reg::toString(estimate.failure);
  msg.failure_detail = estimate.failure_detail;
  msg.observations = estimate.observations;
  msg.inliers = estimate.inliers;
  msg.inlier_fraction = static_cast<float>(estimate.inlier_fraction);
  msg.residual_scale = static_cast<float>(estimate.residual_scale);
  msg.processing_ms = static_cast<float>(estimate.elapsed_ms);
  msg.image_width = static_cast<uint32_t>(step.image_size.width);
  msg.image_height = static_cast<uint32_t>(step.image_size.height);
  msg.undistorted = step.undistorted;
  if (step.camera_matrix) {
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) msg.camera_matrix[3 * r + c] = (*step.camera_matrix)(r, c);
  }
  motion_publisher_.publish(msg);

  ++pairs_;
  processing_ms_sum_ += estimate.elapsed_ms;
  processing_ms_max_ = std::max(processing_ms_max_, estimate.elapsed_ms);
  recent_failures_.push_back(estimate.failed);
  if (int(recent_failures_.size()) > config_.quality_window) recent_failures_.pop_front();
  if (estimate.failed) {
    ++failures_;
    ++failures_by_reason_[msg.failure];
    last_problem_ = msg.failure + ": " + estimate.failure_detail;
    ROS_WARN_THROTTLE(5.0, "registration failed (%s): %s", msg.failure.c_str(), estimate.failure_detail.c_str());
  } else {
    recent_inlier_fraction_.push_back(estimate.inlier_fraction);
    if (int(recent_inlier_fraction_.size()) > config_.quality_window) recent_inlier_fraction_.pop_front();
  }
}

void RegistrationRos::diagnose(diagnostic_updater::DiagnosticStatusWrapper& status) {
  const double recent = recent_failures_.empty()
                            ? 0.0
                            : double(std::count(recent_failures_.begin(), recent_failures_.end(), true)) /
                                  double(recent_failures_.size());
  double inliers = 0.0;
  for (double f : recent_inlier_fraction_) inliers += f;
  if (!recent_inlier_fraction_.empty()) inliers /= double(recent_inlier_fraction_.size());
  const double error_fraction = std::min(0.8, 4.0 * config_.warn_failure_fraction);
  if (images_ == 0)
    status.summary(DiagnosticStatus::WARN, "no image received yet on " + config_.image_topic);
  else if (recent >= error_fraction)
    status.summaryf(DiagnosticStatus::ERROR, "%.0f%% of the last %zu pairs failed", 100.0 * recent,
                    recent_failures_.size());
  else if (recent > config_.warn_failure_fraction)
    status.summaryf(DiagnosticStatus::WARN, "%.0f%% of the last %zu pairs failed", 100.0 * recent,
                    recent_failures_.size());
  else
    status.summary(DiagnosticStatus::OK, "registering");
  status.add("method", reg::toString(config_.registration.method));
  status.add("model", reg::toString(config_.registration.model));
  status.add("undistorting", sequence_->undistorter().active() ? std::string("yes") : std::string("no"));
  status.add("transport", active_transport_.empty() ? std::string("none yet") : active_transport_);
  status.add("images received", images_);
  status.add("images rejected", rejected_);
  status.add("images held back for camera_info", held_for_camera_info_);
  status.add("images dropped waiting for camera_info", dropped_waiting_for_camera_info_);
  status.add("pairs registered", pairs_);
  status.add("pairs failed", failures_);
  status.add("sequence restarts", restarts_);
  status.add("reconfigurations", reconfigurations_);
  status.addf("recent failure fraction", "%.3f", recent);
  status.addf("recent mean inlier fraction", "%.3f", inliers);
  status.addf("mean processing ms", "%.2f", pairs_ ? processing_ms_sum_ / double(pairs_) : 0.0);
  status.addf("max processing ms", "%.2f", processing_ms_max_);
  for (const auto& [reason, count] : failures_by_reason_) status.add("failures: " + reason, count);
  if (!last_problem_.empty()) status.add("last problem", last_problem_);
}

}  // namespace exocet_mosaic
