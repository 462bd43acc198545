#include "exocet_mosaic/ros/tile_writer_ros.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <numeric>
#include <stdexcept>

#include <unistd.h>

#include <cv_bridge/cv_bridge.h>
#include <exocet_msgs/Tile.h>
#include <visualization_msgs/MarkerArray.h>
#include <Eigen/Eigenvalues>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "exocet_common/atomic_file.h"
#include "exocet_common/background_priority.h"
#include "exocet_common/free_heap.h"
#include "exocet_common/json_file.h"
#include "exocet_common/unit_quaternion.h"
#include "exocet_mosaic/ros/image_message_decoder.h"
#include "exocet_mosaic/tiles/closed_mosaic_tile.h"
#include "exocet_mosaic/tiles/tile_mosaic_vrt.h"
#include "exocet_mosaic/tiles/tile_network_adjustment.h"

namespace exocet_mosaic {

using diagnostic_msgs::DiagnosticStatus;

namespace {

constexpr std::size_t kMaxFootprints = 2000;  // tiles drawn in rviz (bounded memory on a dive of any length)

bool finite(const Eigen::MatrixXd& m) { return m.allFinite(); }

cv::Matx33d matrixFrom(const boost::array<double, 9>& values) {
  cv::Matx33d m;
  for (int i = 0; i < 9; ++i) m.val[i] = values[i];
  return m;
}

}  // namespace

TileWriterRos::TileWriterRos(ros::NodeHandle nh, ros::NodeHandle private_nh)
    : nh_(nh),
      private_nh_(private_nh),
      config_(readTileWriterNodeConfig(private_nh)),
      image_transport_(nh),
      composer_(config_.composer),
      assembler_(config_.sync_timeout_s, static_cast<std::size_t>(config_.max_pending_frames)) {
  // A missing folder is made; one that cannot be made is reported and every tile is kept for a retry meanwhile.
  std::error_code mkdir_error;
  std::filesystem::create_directories(config_.files.output_dir, mkdir_error);
  if (mkdir_error) {
    last_write_error_ = "cannot create the output folder " + config_.files.output_dir + ": " + mkdir_error.message();
    ROS_ERROR("tile writer: %s", last_write_error_.c_str());
  }
  writer_ = std::make_unique<tiles::GeoTiffTileWriter>(config_.files);
  if (config_.keep_images) {
    images_dir_ = config_.files.output_dir + "/.exocet_images";
    std::error_code error;
    std::filesystem::create_directories(images_dir_, error);
    if (error) ROS_ERROR("tile writer: cannot create %s: %s", images_dir_.c_str(), error.message().c_str());
    // The tile gains' cells of the older tiles go beside the kept images: their memory does not grow with the dive.
    compose::TileGainConfig gain_config = gains_.config();
    gain_config.cells_folder = images_dir_;
    gains_ = compose::TileGainCompensator(gain_config);
  }
  const int stale =
      writer_->removeStaleTemporaries() + (images_dir_.empty() ? 0 : tiles::removeTemporariesIn(images_dir_));
  if (stale > 0) ROS_WARN("tile writer: removed %d partial file(s) left by an interrupted run", stale);
  const int incomplete = writer_->removeIncompleteTiles();
  if (incomplete > 0)
    ROS_WARN("tile writer: removed %d file(s) of a tile whose GeoTIFF an interrupted run had not renamed yet",
             incomplete);
  loadPreviousRun();
  if (!config_.udp_host.empty())
    notifier_ = std::make_unique<tiles::TileNotifier>(config_.udp_host, config_.udp_port, config_.udp_bind_address);
  if (config_.utm_zone > 0) {
    utm_zone_ = config_.utm_zone;
    northern_ = config_.northern_hemisphere;
  }

  tile_pub_ = nh_.advertise<exocet_msgs::Tile>(config_.tile_topic, 50, true);
  footprints_pub_ = nh_.advertise<visualization_msgs::MarkerArray>(config_.footprints_topic, 1, true);
  preview_pub_ = image_transport_.advertise(config_.preview_topic, 1);

  if (config_.transport != "compressed")
    raw_sub_ = image_transport_.subscribe(config_.image_topic, config_.queue_size, &TileWriterRos::onImage, this,
                                          image_transport::TransportHints("raw"));
  if (config_.transport != "raw")
    compressed_sub_ =
        nh_.subscribe(config_.image_topic + "/compressed", config_.queue_size, &TileWriterRos::onCompressed, this);
  // One motion, pose and height per image: their queues are at least as deep as the images'.
  const int per_image_queue = std::max(500, config_.queue_size);
  motion_sub_ = nh_.subscribe(config_.motion_topic, per_image_queue, &TileWriterRos::onMotion, this);
  odometry_sub_ = nh_.subscribe(config_.odometry_topic, per_image_queue, &TileWriterRos::onOdometry, this);
  height_sub_ = nh_.subscribe(config_.camera_height_topic, per_image_queue, &TileWriterRos::onCameraHeight, this);
  datum_sub_ = nh_.subscribe(config_.datum_topic, 1, &TileWriterRos::onDatum, this);
  camera_info_sub_ = nh_.subscribe(config_.camera_info_topic, 5, &TileWriterRos::onCameraInfo, this);
  if (!config_.graph_corrections_topic.empty())
    corrections_sub_ = nh_.subscribe(config_.graph_corrections_topic, 1, &TileWriterRos::onCorrections, this);

  // The operator's knobs: start from the parameters read above, then follow dynamic_reconfigure.
  reconfigure_server_ =
      std::make_unique<dynamic_reconfigure::Server<exocet_mosaic::TileWriterConfig>>(reconfigure_mutex_, private_nh_);
  exocet_mosaic::TileWriterConfig start;
  start.frames_per_mosaic = config_.composer.frames_per_mosaic;
  start.blend = config_.composer.blend;
  start.feather_power = config_.composer.feather_power;
  start.min_key_frame_shift_fraction = config_.composer.min_key_frame_shift_fraction;
  start.max_extent_m = config_.composer.max_extent_m;
  start.max_memory_mb = config_.composer.max_memory_mb;
  start.navigation_jump_sigma = config_.composer.navigation_jump_sigma;
  start.navigation_jump_min_m = config_.composer.navigation_jump_min_m;
  start.lighting_enabled = config_.composer.lighting.enabled;
  start.write_cog = config_.files.write_cog;
  start.write_kmz = config_.files.write_kmz;
  reconfigure_server_->updateConfig(start);
  reconfigure_server_->setCallback(
      [this](exocet_mosaic::TileWriterConfig& c, uint32_t level) { onReconfigure(c, level); });

  writer_thread_ = std::thread([this]() { writerLoop(); });
  redraws_ = !config_.graph_corrections_topic.empty() || config_.image_gain_compensation;
  if (redraws_) rerender_thread_ = std::thread([this]() { rerenderLoop(); });
  flush_srv_ = private_nh_.advertiseService("flush", &TileWriterRos::onFlush, this);

  updater_.setHardwareID("tile writer " + config_.files.output_dir);
  updater_.add("tiles", this, &TileWriterRos::diagnose);
  const double period_s = updater_.getPeriod() > 0.0 ? updater_.getPeriod() : 1.0;
  diagnostics_timer_ = nh_.createSteadyTimer(ros::WallDuration(period_s),
                                             [this](const ros::SteadyTimerEvent&) { updater_.force_update(); });
  // Hours of short-lived large buffers in several threads: their freed pages go back to the system.
  free_heap_timer_ = nh_.createSteadyTimer(ros::WallDuration(kFreeHeapPeriod_s),
                                           [](const ros::SteadyTimerEvent&) { exocet_common::releaseFreeHeap(); });
  timer_ = nh_.createSteadyTimer(ros::WallDuration(0.1), [this](const ros::SteadyTimerEvent&) { onTimer(); });
  last_input_wall_ = ros::WallTime::now();
  ROS_INFO("tile writer: %s -> %s/%s_NNNN.tif, %d images per mosaic, %s blending", config_.image_topic.c_str(),
           config_.files.output_dir.c_str(), config_.files.prefix.c_str(), config_.composer.frames_per_mosaic,
           config_.composer.blend.c_str());
}

TileWriterRos::~TileWriterRos() {
  timer_.stop();
  flushAll("flush");
  {
    std::lock_guard<std::mutex> lock(rerender_mutex_);
    stop_rerender_ = true;
  }
  rerender_cv_.notify_all();
  if (rerender_thread_.joinable()) rerender_thread_.join();
  if (redraws_) {
    // The tiles as the last corrections and gains place them: the written ones first, then one last look.
    waitWriterIdle(120.0);
    rerenderDue(true);
    saveCorrections();
    if (!config_.graph_corrections_topic.empty() && config_.tile_adjustment_period_s > 0.0) {
      waitWriterIdle(300.0);
      if (adjustWrittenTiles() > 0) rerenderDue();
    }
    waitWriterIdle(300.0);
  }
  {
    std::lock_guard<std::mutex> lock(write_mutex_);
    stop_writer_ = true;
  }
  write_cv_.notify_all();
  if (writer_thread_.joinable()) writer_thread_.join();
  updateMosaicVrt(true);
  if (!run_decided_) {
    if (previous_run_ && previous_run_->finished) {
      // No image came (a writer respawned after the replay's end): the summary and progress are the last run's.
      ROS_INFO("tile writer: no image received: %s stays as the last run left it", config_.files.output_dir.c_str());
      return;
    }
    if (previous_run_) continueRun(*previous_run_, false);  // the interrupted run ends here: its counts
    run_decided_ = true;
  }
  writeRunSummary();
  saveProgress(true);
}

// ---------------------------------------------------------------------------------------------------------------
// Inputs.

bool TileWriterRos::acceptTransport(const std::string& transport) {
  if (active_transport_.empty()) {
    active_transport_ = transport;
    if (transport == "raw")
      compressed_sub_.shutdown();
    else
      raw_sub_.shutdown();
  }
  return active_transport_ == transport;
}

void TileWriterRos::reject(const std::string& why) {
  ++rejected_;
  last_problem_ = why;
  // Throttled per kind of problem (the text's start): a frequent one must not hide another.
  std::uint64_t held_back = 0;
  if (reject_log_.allow(why.substr(0, 32), &held_back))
    ROS_ERROR("tile writer: %s%s", why.c_str(), reject_log_.heldBackNote(held_back).c_str());
}

void TileWriterRos::onImage(const sensor_msgs::ImageConstPtr& msg) {
  if (!acceptTransport("raw")) return;
  acceptImage(
      msg->header,
      [msg](int) {                                                            // at full size: the composer reduces it
        const cv_bridge::CvImageConstPtr shared = cv_bridge::toCvShare(msg);  // throws on a bad message
        return toDisplayImage(shared->image, msg->encoding);
      },
      cv::Size(static_cast<int>(msg->width), static_cast<int>(msg->height)), displayChannels(msg->encoding));
}

void TileWriterRos::onCompressed(const sensor_msgs::CompressedImageConstPtr& msg) {
  if (!acceptTransport("compressed")) return;
  // The header gives the shape: the pixels are decoded only for the images the composer draws (about one in ten).
  const std::optional<DisplayShape> shape = peekDisplayShape(*msg);
  acceptImage(
      msg->header,
      [msg](int reduction) {
        DecodedImage decoded;
        const std::string error = decodeCompressedImage(*msg, &decoded, DecodeMode::kAsStored, reduction);
        if (!error.empty()) throw std::invalid_argument(error);
        return toDisplayImage(decoded.image, decoded.encoding);
      },
      shape ? shape->size : cv::Size(), shape ? shape->channels : 0);
}

void TileWriterRos::checkClock(std::int64_t stamp_ns) {
  if (newest_stamp_ns_ && stamp_ns < *newest_stamp_ns_ - static_cast<std::int64_t>(config_.clock_jump_s * 1e9)) {
    ++clock_jumps_;
    last_problem_ = "the clock jumped back (a bag played again?): the open mosaic is closed, a new one starts";
    ROS_WARN_THROTTLE(5.0, "tile writer: %s", last_problem_.c_str());
    waitForWriteRoom();  // before compose_mutex_, which the writer takes to save its progress
    std::lock_guard<std::mutex> lock(compose_mutex_);
    if (auto closed = composer_.flush("clock_jump")) enqueue(std::move(*closed));
    assembler_.reset();
    last_composed_stamp_ns_.reset();
    newest_stamp_ns_.reset();
  }
  if (!newest_stamp_ns_ || stamp_ns > *newest_stamp_ns_) newest_stamp_ns_ = stamp_ns;
}

void TileWriterRos::acceptImage(const std_msgs::Header& header, ImageDecoder decode, cv::Size image_size,
                                int image_channels) {
  ++images_;
  last_input_wall_ = ros::WallTime::now();
  received_input_ = true;
  if (header.stamp.isZero()) {
    reject("image with a zero stamp: it cannot be matched to its pose");
    return;
  }
  const std::int64_t stamp_ns = static_cast<std::int64_t>(header.stamp.toNSec());
  if (!run_decided_) decideRun(header.stamp.toSec());
  newest_image_stamp_s_ = std::max(newest_image_stamp_s_.load(), header.stamp.toSec());
  checkClock(stamp_ns);
  if (!addAndProcess([&](double now_s) {
        return assembler_.addImage(stamp_ns, std::move(decode), now_s, image_size, image_channels);
      }))
    reject("image stamped like one already received (a duplicated stamp) or older than the frames composed: ignored");
}

bool TileWriterRos::addAndProcess(const std::function<bool(double now_s)>& add) {
  // One part in, then every frame it completes (or that waited too long) out, in stamp order.
  std::vector<AssembledFrame> ready;
  {
    std::lock_guard<std::mutex> lock(compose_mutex_);
    const double now_s = last_input_wall_.toSec();
    if (!add(now_s)) return false;
    ready = assembler_.popReady(now_s);
  }
  processReady(std::move(ready));
  return true;
}

void TileWriterRos::onMotion(const exocet_msgs::ImageMotionConstPtr& msg) {
  last_input_wall_ = ros::WallTime::now();
  MotionPart motion;
  motion.previous_stamp_ns = static_cast<std::int64_t>(msg->previous_stamp.toNSec());
  motion.failed = msg->failed;
  motion.current_from_previous_px = matrixFrom(msg->matrix);
  motion.camera_matrix = matrixFrom(msg->camera_matrix);
  motion.has_camera_matrix = motion.camera_matrix(0, 0) > 0.0 && motion.camera_matrix(1, 1) > 0.0;
  motion.undistorted = msg->undistorted;
  if (!motion.failed && !cv::checkRange(motion.current_from_previous_px)) {
    reject("image motion with non-finite matrix: treated as a failed registration");
    motion.failed = true;
  }
  addAndProcess([&](double now_s) {
    return assembler_.addMotion(static_cast<std::int64_t>(msg->header.stamp.toNSec()), motion, now_s);
  });
}

void TileWriterRos::onOdometry(const nav_msgs::OdometryConstPtr& msg) {
  last_input_wall_ = ros::WallTime::now();
  PosePart pose;
  pose.camera_en_m = Eigen::Vector2d(msg->pose.pose.position.x, msg->pose.pose.position.y);
  const auto& c = msg->pose.covariance;
  pose.position_cov_m2 << c[0], c[1], c[6], c[7];
  const auto& q = msg->pose.pose.orientation;
  pose.world_from_camera = Eigen::Quaterniond(q.w, q.x, q.y, q.z);
  if (!finite(pose.camera_en_m) || !finite(pose.position_cov_m2) ||
      !exocet_common::isUnitQuaternion(q.w, q.x, q.y, q.z)) {
    reject(
        "fused odometry with a non-finite position or covariance, or an orientation that is not a unit "
        "quaternion: ignored");
    return;
  }
  pose.world_from_camera.normalize();
  ++poses_;
  if (!msg->header.frame_id.empty() && msg->header.frame_id != config_.frame_id) {
    std::lock_guard<std::mutex> lock(write_mutex_);
    if (local_frame_ != msg->header.frame_id) {
      local_frame_ = msg->header.frame_id;
      ROS_WARN(
          "tile writer: fused poses in frame '%s', not in the UTM frame '%s' (~frame_id): the dive is not "
          "geo-referenced, tiles are written in the local metric frame '%s'",
          local_frame_.c_str(), config_.frame_id.c_str(), local_frame_.c_str());
    }
  }
  addAndProcess([&](double now_s) {
    return assembler_.addPose(static_cast<std::int64_t>(msg->header.stamp.toNSec()), pose, now_s);
  });
}

void TileWriterRos::onCameraHeight(const sensor_msgs::RangeConstPtr& msg) {
  last_input_wall_ = ros::WallTime::now();
  if (!(std::isfinite(msg->range) && msg->range > 0.0f)) {
    reject("camera height " + std::to_string(msg->range) + " m is not a positive number: ignored");
    return;
  }
  ++camera_heights_;
  addAndProcess([&](double now_s) {
    return assembler_.addHeight(static_cast<std::int64_t>(msg->header.stamp.toNSec()), msg->range, now_s);
  });
}

void TileWriterRos::onDatum(const exocet_msgs::GeoDatumConstPtr& msg) {
  if (msg->utm_zone < 0 || msg->utm_zone > 60) {
    reject("datum with UTM zone " + std::to_string(msg->utm_zone) + " (allowed 0..60): ignored");
    return;
  }
  std::lock_guard<std::mutex> lock(write_mutex_);  // the writer thread reads the zone and the origin
  if (msg->origin_easting_m != 0.0 || msg->origin_northing_m != 0.0)
    map_origin_en_m_ = Eigen::Vector2d(msg->origin_easting_m, msg->origin_northing_m);
  if (config_.utm_zone > 0) return;  // the parameter wins
  if (utm_zone_ && (*utm_zone_ != msg->utm_zone || northern_ != msg->northern_hemisphere))
    ROS_WARN("tile writer: the datum changes to zone %d%s; tiles from now on use it", msg->utm_zone,
             msg->northern_hemisphere ? "N" : "S");
  utm_zone_ = msg->utm_zone;
  northern_ = msg->northern_hemisphere;
}

void TileWriterRos::onCameraInfo(const sensor_msgs::CameraInfoConstPtr& msg) { camera_info_ = msg; }

void TileWriterRos::onReconfigure(exocet_mosaic::TileWriterConfig& c, uint32_t) {
  compose::ComposerConfig next = composer_.config();
  next.frames_per_mosaic = c.frames_per_mosaic;
  next.blend = c.blend;
  next.feather_power = c.feather_power;
  next.min_key_frame_shift_fraction = c.min_key_frame_shift_fraction;
  next.max_extent_m = c.max_extent_m;
  next.max_memory_mb = c.max_memory_mb;
  next.navigation_jump_sigma = c.navigation_jump_sigma;
  next.navigation_jump_min_m = c.navigation_jump_min_m;
  next.lighting.enabled = c.lighting_enabled;
  const std::string error = next.validate();
  if (!error.empty()) {
    ROS_ERROR("tile writer: reconfiguration refused, keeping the settings in force: %s", error.c_str());
    // Show the operator what is in force.
    const compose::ComposerConfig& now = composer_.config();
    c.frames_per_mosaic = now.frames_per_mosaic;
    c.blend = now.blend;
    c.feather_power = now.feather_power;
    c.min_key_frame_shift_fraction = now.min_key_frame_shift_fraction;
    c.max_extent_m = now.max_extent_m;
    c.max_memory_mb = now.max_memory_mb;
    c.navigation_jump_sigma = now.navigation_jump_sigma;
    c.navigation_jump_min_m = now.navigation_jump_min_m;
    c.lighting_enabled = now.lighting.enabled;
    return;
  }
  {
    std::lock_guard<std::mutex> lock(compose_mutex_);
    composer_.setConfig(next);
  }
  {
    std::lock_guard<std::mutex> lock(write_mutex_);
    // Applied by the worker before its next write: it may be writing with the current writer now.
    tiles::TileWriterConfig files = files_update_ ? *files_update_ : writer_->config();
    files.write_cog = c.write_cog;
    files.write_kmz = c.write_kmz;
    files_update_ = files;
  }
  ROS_INFO("tile writer: reconfigured: %d images per mosaic, %s blending, key frames every %.2f image, lighting %s",
           next.frames_per_mosaic, next.blend.c_str(), next.min_key_frame_shift_fraction,
           next.lighting.enabled ? "on" : "off");
}

// ---------------------------------------------------------------------------------------------------------------
// Composition.

void TileWriterRos::processReady(std::vector<AssembledFrame> frames) {
  for (const AssembledFrame& frame : frames) compose(frame);
}

void TileWriterRos::compose(const AssembledFrame& frame) {
  compose::ComposerFrame input;
  input.index = next_frame_index_++;
  input.stamp_s = static_cast<double>(frame.stamp_ns) * 1e-9;
  // The colour image must be undistorted as the registration undistorted its grey one (at the reduction the composer
  // asks for: the undistorted reduced image is the undistorted image reduced).
  std::shared_ptr<const Undistorters> undistorters;
  if (frame.motion && frame.motion->undistorted && config_.undistort && camera_info_) {
    const sensor_msgs::CameraInfo& info = *camera_info_;
    const cv::Size size(static_cast<int>(info.width), static_cast<int>(info.height));
    std::array<double, 9> k{};
    std::array<double, 5> d{};
    std::copy(info.K.begin(), info.K.end(), k.begin());
    for (size_t i = 0; i < std::min<size_t>(5, info.D.size()); ++i) d[i] = info.D[i];
    try {
      if (!undistorters_ || !(*undistorters_)[0]->sameCalibration(size, k, d)) {
        auto made = std::make_shared<Undistorters>();
        (*made)[0] = std::make_shared<const registration::ImageUndistorter>(size, k, d);
        for (int i = 1; i < 4; ++i)
          if (size.width >= (1 << i) && size.height >= (1 << i))
            (*made)[i] = std::make_shared<const registration::ImageUndistorter>((*made)[0]->reducedBy(1 << i));
        undistorters_ = made;
      }
      if ((*undistorters_)[0]->active()) undistorters = undistorters_;
    } catch (const std::invalid_argument& e) {
      reject(std::string("cannot undistort the image like the registration did: ") + e.what());
    }
  }
  const cv::Size full_size = frame.image_size;
  auto load = [decode = frame.decode_image, undistorters, full_size](int reduction) {
    // A reduced decode where the format allows it (JPEG); otherwise the full image, which the composer reduces.
    const int log2 = reduction == 8 ? 3 : reduction == 4 ? 2 : reduction == 2 ? 1 : 0;
    const bool can_reduce = undistorters == nullptr || (*undistorters)[log2] != nullptr;
    cv::Mat image = decode(can_reduce ? reduction : 1);  // throws what is wrong with the message
    if (image.empty()) throw std::invalid_argument("empty image");
    if (!undistorters) return image;
    const bool full = image.size() == (*undistorters)[0]->size() || (!full_size.empty() && image.size() == full_size);
    return (*undistorters)[full ? 0 : log2]->apply(image);
  };
  if (!frame.image_size.empty() && frame.image_channels > 0) {
    // Decoded only if the composer draws it.
    input.load_image = load;
    input.image_size = frame.image_size;
    input.image_channels = frame.image_channels;
  } else {
    try {
      input.image = load(1);
    } catch (const std::exception& e) {
      reject(std::string("image cannot be used: ") + e.what());
      return;
    }
  }
  // The chain holds only between consecutive composed images.
  if (frame.motion && !frame.motion->failed && last_composed_stamp_ns_ &&
      frame.motion->previous_stamp_ns == *last_composed_stamp_ns_)
    input.current_from_previous_px = frame.motion->current_from_previous_px;
  if (frame.pose && frame.camera_height_m) {
    cv::Matx33d k = cv::Matx33d::eye();
    bool have_k = false;
    if (frame.motion && frame.motion->has_camera_matrix) {
      k = frame.motion->camera_matrix;
      have_k = true;
    } else if (camera_info_ && camera_info_->K[0] > 0.0) {
      const cv::Size calibrated(static_cast<int>(camera_info_->width), static_cast<int>(camera_info_->height));
      const cv::Size size = !frame.image_size.empty() ? frame.image_size
                            : !input.image.empty()    ? input.image.size()
                                                      : calibrated;
      if (!calibrated.empty() && size != calibrated) {
        reject("image of " + std::to_string(size.width) + "x" + std::to_string(size.height) +
               " px, not the camera_info's " + std::to_string(calibrated.width) + "x" +
               std::to_string(calibrated.height) + " px, and no camera matrix for it in its motion: not composed");
        return;
      }
      k = matrixFrom(camera_info_->K);
      have_k = true;
    }
    if (have_k) {
      compose::CameraGroundPose pose;
      pose.camera_en_m = frame.pose->camera_en_m;
      pose.position_cov_m2 = frame.pose->position_cov_m2;
      pose.world_from_camera = frame.pose->world_from_camera;
      pose.camera_height_m = *frame.camera_height_m;
      pose.camera_matrix = k;
      if (!config_.graph_corrections_topic.empty()) {
        // Where the pose graph puts the image (its latest correction there); kept to move the image again later.
        Eigen::Vector2d correction;
        {
          std::lock_guard<std::mutex> lock(corrections_mutex_);
          correction = corrections_.at(input.stamp_s);
        }
        pose.camera_en_m += correction;
        used_corrections_[input.index] = correction;
        while (used_corrections_.size() > 100000) used_corrections_.erase(used_corrections_.begin());
      }
      input.pose = pose;
    } else {
      last_problem_ = "no camera matrix (image motion or camera_info): images cannot be placed";
      ROS_WARN_THROTTLE(10.0, "tile writer: %s", last_problem_.c_str());
    }
  }
  std::optional<compose::ClosedMosaic> closed;
  {
    std::lock_guard<std::mutex> lock(compose_mutex_);
    try {
      closed = composer_.add(input);
    } catch (const std::exception& e) {
      reject(std::string("image not composed: ") + e.what());
      return;
    }
  }
  ++frames_composed_calls_;
  last_composed_stamp_ns_ = frame.stamp_ns;
  if (closed) {
    // The fit averages the navigation over the tile's images as if their errors were independent; the filter's
    // errors are correlated over many images, so the tile's position is no better than the fused 1-sigma.
    if (!tile_fused_sigmas_m_.empty()) {
      std::nth_element(tile_fused_sigmas_m_.begin(), tile_fused_sigmas_m_.begin() + tile_fused_sigmas_m_.size() / 2,
                       tile_fused_sigmas_m_.end());
      closed->anchor_sigma_m = std::max(closed->anchor_sigma_m, tile_fused_sigmas_m_[tile_fused_sigmas_m_.size() / 2]);
    }
    tile_fused_sigmas_m_.clear();
    waitForWriteRoom();
    enqueue(std::move(*closed));
  }
  if (input.pose) {
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eigen(input.pose->position_cov_m2);
    tile_fused_sigmas_m_.push_back(std::sqrt(std::max(0.0, eigen.eigenvalues().maxCoeff())));
  }
}

void TileWriterRos::flushAll(const std::string& reason) {
  std::vector<AssembledFrame> rest;
  {
    std::lock_guard<std::mutex> lock(compose_mutex_);
    rest = assembler_.popAll();
  }
  processReady(std::move(rest));
  waitForWriteRoom();  // before compose_mutex_, which the writer takes to save its progress
  std::lock_guard<std::mutex> lock(compose_mutex_);
  if (auto closed = composer_.flush(reason)) {
    if (!tile_fused_sigmas_m_.empty()) {
      std::sort(tile_fused_sigmas_m_.begin(), tile_fused_sigmas_m_.end());
      closed->anchor_sigma_m = std::max(closed->anchor_sigma_m, tile_fused_sigmas_m_[tile_fused_sigmas_m_.size() / 2]);
    }
    tile_fused_sigmas_m_.clear();
    enqueue(std::move(*closed));
  }
}

bool TileWriterRos::onFlush(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& response) {
  // The operator closes the open mosaic now (end of a line, before a transit); waits until it is on disk.
  std::int64_t written_before = 0;
  {
    std::lock_guard<std::mutex> lock(write_mutex_);
    written_before = tiles_written_ + write_failures_;
  }
  flushAll("operator");
  std::unique_lock<std::mutex> lock(write_mutex_);
  write_cv_.wait_for(lock, std::chrono::seconds(60), [this]() { return write_queue_.empty() && !writing_; });
  const std::int64_t done = tiles_written_ + write_failures_ - written_before;
  response.success = write_queue_.empty() && !writing_ && last_write_failed_ == false;
  response.message = done == 0          ? "no open mosaic"
                     : response.success ? "tile written"
                                        : "write failed: " + last_write_error_;
  return true;
}

void TileWriterRos::onTimer() {
  std::vector<AssembledFrame> ready;
  {
    std::lock_guard<std::mutex> lock(compose_mutex_);
    ready = assembler_.popReady(ros::WallTime::now().toSec());
  }
  processReady(std::move(ready));
  if (run_decided_ && images_ != progress_images_ &&
      (ros::WallTime::now() - last_progress_wall_).toSec() >= config_.progress_period_s) {
    last_progress_wall_ = ros::WallTime::now();
    progress_images_ = images_;
    saveProgress(false);
  }
  if (config_.preview_period_s > 0.0 &&
      (ros::WallTime::now() - last_preview_wall_).toSec() >= config_.preview_period_s) {
    last_preview_wall_ = ros::WallTime::now();
    publishPreview();
  }
  if (config_.exit_when_idle_s > 0.0 && received_input_ && !shutting_down_ &&
      (ros::WallTime::now() - last_input_wall_).toSec() > config_.exit_when_idle_s) {
    shutting_down_ = true;
    ROS_INFO("tile writer: no input for %.1f s: flushing the open mosaic and shutting down", config_.exit_when_idle_s);
    flushAll("flush");
    {
      std::unique_lock<std::mutex> lock(write_mutex_);
      write_cv_.wait(lock, [this]() { return write_queue_.empty() && !writing_; });
    }
    ros::shutdown();
  }
}

void TileWriterRos::publishPreview() {
  if (preview_pub_.getNumSubscribers() == 0) return;
  cv::Mat preview;
  {
    std::lock_guard<std::mutex> lock(compose_mutex_);
    preview = composer_.preview(config_.preview_max_side_px);
  }
  if (preview.empty()) return;
  std_msgs::Header header;
  header.stamp = ros::Time::now();
  header.frame_id = config_.frame_id;
  preview_pub_.publish(cv_bridge::CvImage(header, preview.channels() == 1 ? "mono8" : "bgr8", preview).toImageMsg());
}

// ---------------------------------------------------------------------------------------------------------------
// Writing (worker thread).

TileWriterRos::PendingTile TileWriterRos::pendingTile(compose::ClosedMosaic mosaic) {
  PendingTile pending;
  for (const auto& image : mosaic.images) {
    const auto used = used_corrections_.find(image.index);
    pending.image_corrections_m.push_back(used == used_corrections_.end() ? Eigen::Vector2d::Zero() : used->second);
  }
  // The next mosaic starts with this one's last image: what is older is no longer needed.
  used_corrections_.erase(used_corrections_.begin(), used_corrections_.lower_bound(mosaic.last_frame));
  pending.mosaic = std::move(mosaic);
  return pending;
}

void TileWriterRos::enqueue(compose::ClosedMosaic mosaic) {
  PendingTile pending = pendingTile(std::move(mosaic));
  {
    std::lock_guard<std::mutex> lock(write_mutex_);
    write_queue_.push_back(std::move(pending));
    tiles_queued_max_ = std::max(tiles_queued_max_, tilesQueuedLocked());
  }
  write_cv_.notify_all();
}

int TileWriterRos::tilesQueuedLocked() const {
  return static_cast<int>(std::count_if(write_queue_.begin(), write_queue_.end(),
                                        [](const PendingTile& p) { return !p.revision; }));
}

void TileWriterRos::waitForWriteRoom() {
  // A closed mosaic holds its raster and its kept images (tens of MB). When the input comes faster than this machine
  // writes tiles (a fast replay, a slow disk), the composition waits here, one tile at a time: the backlog is then
  // the subscriber's queue of compressed images, bounded by ~queue_size, and not this node's memory. A writer stuck
  // longer than kMaxWriteWaitS (a hung disk) is not waited for: the chain goes on and the wait is reported.
  constexpr double kMaxWriteWaitS = 60.0;
  std::unique_lock<std::mutex> lock(write_mutex_);
  if (tilesQueuedLocked() < config_.max_queued_tiles) return;
  ++composition_waits_;
  ROS_WARN_THROTTLE(10.0,
                    "tile writer: %d tiles wait to be written (~max_queued_tiles %d): the composition waits for the "
                    "writer (the images come faster than this machine writes tiles; the subscriber's queue holds them "
                    "meanwhile)",
                    tilesQueuedLocked(), config_.max_queued_tiles);
  const auto start = std::chrono::steady_clock::now();
  const auto deadline = start + std::chrono::duration<double>(kMaxWriteWaitS);
  while (!stop_writer_ && tilesQueuedLocked() >= config_.max_queued_tiles &&
         std::chrono::steady_clock::now() < deadline)
    write_cv_.wait_for(lock, std::chrono::milliseconds(200));
  composition_wait_s_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (tilesQueuedLocked() >= config_.max_queued_tiles && !stop_writer_) {
    last_write_error_ = "the writer wrote no tile for " + std::to_string(static_cast<int>(kMaxWriteWaitS)) +
                        " s: a closed mosaic is queued beyond ~max_queued_tiles";
    ROS_ERROR_THROTTLE(30.0, "tile writer: %s", last_write_error_.c_str());
  }
}

void TileWriterRos::writerLoop() {
  std::unique_lock<std::mutex> lock(write_mutex_);
  ros::WallTime last_retry = ros::WallTime::now();
  while (true) {
    write_cv_.wait_for(lock, std::chrono::milliseconds(500),
                       [this]() { return stop_writer_ || !write_queue_.empty(); });
    const bool retry_due =
        !failed_tiles_.empty() && (ros::WallTime::now() - last_retry).toSec() >= config_.retry_period_s;
    if (write_queue_.empty() && !retry_due) {
      if (stop_writer_) break;
      lock.unlock();
      updateMosaicVrt(false);  // a change the 2 s limit held back
      lock.lock();
      continue;
    }
    PendingTile pending;
    if (!write_queue_.empty()) {
      pending = std::move(write_queue_.front());
      write_queue_.pop_front();
    } else {
      pending = std::move(failed_tiles_.front());
      failed_tiles_.pop_front();
      last_retry = ros::WallTime::now();
    }
    if (pending.revision) {
      if (files_update_) {
        writer_ = std::make_unique<tiles::GeoTiffTileWriter>(*files_update_);
        files_update_.reset();
      }
      writeRevision(pending, writer_.get(), lock);
      continue;
    }
    if (!utm_zone_ && local_frame_.empty()) {
      // No zone yet (no datum): keep the mosaic until one arrives.
      last_write_error_ = "no UTM zone known (no /mosaic/datum and ~utm_zone is 0): tile kept in memory";
      failed_tiles_.push_back(std::move(pending));
      while (static_cast<int>(failed_tiles_.size()) > std::max(1, config_.max_failed_tiles_kept)) {
        failed_tiles_.pop_front();
        ++tiles_dropped_;
      }
      continue;
    }
    tiles::TileRaster raster = tiles::tileRaster(pending.mosaic, utm_zone_.value_or(0), northern_, local_frame_);
    std::optional<compose::TileGains> gains;
    if (config_.gain_compensation) {
      // Matched to the tiles written where they overlap (the compensator is this thread's).
      gains = gains_.estimate(raster, -1);
      raster = compose::TileGainCompensator::apply(raster, *gains);
    }
    const tiles::TileMetadata metadata = tiles::tileMetadata(pending.mosaic, config_.dive_name);
    if (files_update_) {
      writer_ = std::make_unique<tiles::GeoTiffTileWriter>(*files_update_);
      files_update_.reset();
    }
    tiles::GeoTiffTileWriter* writer = writer_.get();
    writing_ = true;
    lock.unlock();  // the write takes time: let the composition enqueue meanwhile
    const tiles::WrittenTile tile = writer->write(raster, metadata);
    std::optional<tiles::TileRecord> record;
    int levels_added = 0;  // the new images' levels, counted for the gain solve once the record is in records_
    if (tile.ok && config_.keep_images) record = keepRecord(pending, tile, *writer, gains, &levels_added);
    if (tile.ok && gains) gains_.record(tile.index, raster, *gains);
    lock.lock();
    if (tile.ok && gains) {
      char note[160];
      std::snprintf(note, sizeof(note), "tile %d: gains %.3f %.3f %.3f, level step %.1f -> %.1f grey over %d cells",
                    tile.index, gains->gain[0], gains->gain[1], gains->gain[2], gains->step_before_grey,
                    gains->step_after_grey, gains->common_cells);
      last_gain_note_ = note;
    }
    writing_ = false;
    last_write_failed_ = !tile.ok;
    if (!tile.ok) {
      ++write_failures_;
      last_write_error_ = tile.error;
      ROS_ERROR_THROTTLE(5.0, "tile writer: tile not written (kept in memory for a retry): %s", tile.error.c_str());
      ++pending.attempts;
      failed_tiles_.push_back(std::move(pending));
      while (static_cast<int>(failed_tiles_.size()) > config_.max_failed_tiles_kept) {
        ++tiles_dropped_;
        ROS_ERROR("tile writer: more than %d tiles failed to write: the oldest is dropped",
                  config_.max_failed_tiles_kept);
        failed_tiles_.pop_front();
      }
      write_cv_.notify_all();
      continue;
    }
    ++tiles_written_;
    noteCompanionErrorsLocked(tile);
    newest_frame_on_disk_ = std::max(newest_frame_on_disk_, pending.mosaic.last_frame);
    if (record) {
      tiles_changed_since_adjustment_ = true;
      images_kept_ += static_cast<std::int64_t>(record->images.size());
      images_not_kept_ += static_cast<std::int64_t>(pending.mosaic.images.size() - record->images.size());
      records_[record->index] = std::move(*record);
      // Counted only now: a solve between the levels and the record would take them without their tile (the
      // window is taken from records_) and not be due again until the next tile.
      std::lock_guard<std::mutex> gains_lock(image_gains_mutex_);
      image_levels_added_ += levels_added;
    }
    pending.mosaic.images.clear();  // on disk now
    ROS_INFO("tile writer: %s (%dx%d px, %.3f m/px, EPSG %d, frames %d-%d, %s) in %.0f ms", tile.geotiff_path.c_str(),
             tile.width_px, tile.height_px, tile.gsd_m, tile.epsg, pending.mosaic.first_frame,
             pending.mosaic.last_frame, pending.mosaic.close_reason.c_str(), tile.write_ms);
    publishTile(tile, pending.mosaic);
    vrt_stale_ = true;
    lock.unlock();
    updateMosaicVrt(false);
    saveProgress(false);  // what a crash from now on would lose
    lock.lock();
    write_cv_.notify_all();
  }
}

// ---------------------------------------------------------------------------------------------------------------
// Tiles that follow the pose graph.

void TileWriterRos::onCorrections(const exocet_msgs::PositionCorrectionsConstPtr& msg) {
  // Input too for ~exit_when_idle_s: after a fast replay the graph still closes the loops it fell behind on (its
  // workers yield the CPU to the chain), and the tiles follow those before the writer exits.
  last_input_wall_ = ros::WallTime::now();
  const std::size_t n = msg->stamps.size();
  if (msg->east_m.size() != n || msg->north_m.size() != n) {
    reject("graph corrections whose stamps, east_m and north_m differ in length: ignored");
    return;
  }
  std::vector<double> stamps;
  std::vector<Eigen::Vector2d> values;
  stamps.reserve(n);
  values.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    stamps.push_back(msg->stamps[i].toSec());
    values.emplace_back(msg->east_m[i], msg->north_m[i]);
  }
  std::map<double, std::array<double, 3>> sigmas;
  if (msg->east_sigma_m.size() == n && msg->north_sigma_m.size() == n && msg->east_north_correlation.size() == n) {
    for (std::size_t i = 0; i < n; ++i)
      if (std::isfinite(msg->east_sigma_m[i]) && std::isfinite(msg->north_sigma_m[i]))
        sigmas[stamps[i]] = {msg->east_sigma_m[i], msg->north_sigma_m[i], msg->east_north_correlation[i]};
  } else if (!msg->east_sigma_m.empty()) {
    ROS_WARN_THROTTLE(30.0,
                      "tile writer: graph corrections whose 1-sigma arrays differ in length from the stamps: "
                      "the sigmas are ignored");
  }
  int left_out = 0;
  {
    std::lock_guard<std::mutex> lock(corrections_mutex_);
    left_out = corrections_.set(stamps, values);
    correction_sigmas_ = std::move(sigmas);
    ++corrections_received_;
  }
  if (left_out > 0)
    ROS_WARN_THROTTLE(10.0, "tile writer: %d graph correction(s) not finite or not in time order: left out", left_out);
  rerender_cv_.notify_all();
}

namespace {

/// The tile gain over an image's footprint: the mean of compose::gainAt() on a grid of points of the image.
std::array<double, 3> drawnTileGain(const compose::TileGains& gains, const tiles::TileRecord& record,
                                    const tiles::RecordedImage& image) {
  constexpr int kSteps = 4;
  std::array<double, 3> sum{0, 0, 0};
  int n = 0;
  for (int i = 0; i < kSteps; ++i)
    for (int j = 0; j < kSteps; ++j) {
      const cv::Vec3d p = image.ground_from_px *
                          cv::Vec3d((i + 0.5) * image.width_px / kSteps, (j + 0.5) * image.height_px / kSteps, 1);
      if (!(std::abs(p[2]) > 1e-12)) continue;
      const std::array<double, 3> g = compose::gainAt(gains, record.ground_origin_en_m.x() + p[0] / p[2],
                                                      record.ground_origin_en_m.y() + p[1] / p[2]);
      for (int c = 0; c < 3; ++c) sum[c] += g[c];
      ++n;
    }
  if (n == 0) return compose::gainAt(gains, std::nan(""), std::nan(""));
  for (double& s : sum) s /= n;
  return sum;
}

}  // namespace

std::optional<tiles::TileRecord> TileWriterRos::keepRecord(const PendingTile& pending, const tiles::WrittenTile& tile,
                                                           const tiles::GeoTiffTileWriter& writer,
                                                           const std::optional<compose::TileGains>& tile_gains,
                                                           int* levels_added) {
  const compose::ClosedMosaic& mosaic = pending.mosaic;
  tiles::TileRecord record;
  record.index = tile.index;
  record.version = tile.version;
  record.ground_origin_en_m = mosaic.ground_origin_en_m;
  record.gsd_m = mosaic.gsd_m;
  record.utm_zone = utm_zone_.value_or(0);
  record.northern_hemisphere = northern_;
  record.local_frame = tile.local_frame;
  record.metadata = tile.metadata;
  for (std::size_t i = 0; i < mosaic.images.size(); ++i) {
    const compose::ComposedImage& image = mosaic.images[i];
    tiles::RecordedImage kept;
    kept.frame = image.index;
    kept.stamp_s = image.stamp_s;
    kept.file = tiles::recordedImageName(config_.files.prefix, image.stamp_s);
    kept.width_px = image.image.cols;
    kept.height_px = image.image.rows;
    kept.closed_ground_from_px = kept.ground_from_px = image.ground_from_px;
    if (config_.image_gain_compensation && tile_gains) kept.gain = drawnTileGain(*tile_gains, record, kept);
    kept.closed_correction_m =
        i < pending.image_corrections_m.size() ? pending.image_corrections_m[i] : Eigen::Vector2d::Zero();
    kept.closed_navigation_m = image.navigation_m;
    if (image.navigation_m) kept.closed_navigation_heading_rad = image.navigation_heading_rad;
    const std::string error =
        tiles::writeRecordedImage(images_dir_, kept.file, image.image, config_.kept_image_quality);
    if (!error.empty()) {
      ROS_WARN_THROTTLE(10.0, "tile writer: %s (the tile cannot be drawn again with it)", error.c_str());
      continue;
    }
    record.images.push_back(kept);
    if (config_.image_gain_compensation) {
      const compose::ImageGainsConfig& g = image_gains_.config();
      compose::ImageLevels levels = compose::imageLevels(image.image, g.grid_columns, g.grid_rows);
      std::lock_guard<std::mutex> lock(image_gains_mutex_);
      if (image_gains_.add(kept.file, std::move(levels))) ++*levels_added;
    }
  }
  saveRecord(record, writer);
  return record;
}

void TileWriterRos::saveRecord(const tiles::TileRecord& record, const tiles::GeoTiffTileWriter& writer) {
  try {
    exocet_common::writeJsonFileAtomically(images_dir_ + "/" + writer.baseName(record.index) + ".json",
                                           tiles::tileRecordToJson(record));
  } catch (const std::exception& e) {
    ROS_WARN_THROTTLE(10.0, "tile writer: record of tile %d not kept: %s", record.index, e.what());
  }
}

void TileWriterRos::waitWriterIdle(double timeout_s) {
  std::unique_lock<std::mutex> lock(write_mutex_);
  write_cv_.wait_for(lock, std::chrono::duration<double>(timeout_s),
                     [this]() { return write_queue_.empty() && !writing_; });
}

namespace {

/// What a Tile message and the log say about a tile drawn again (its record's metadata).
compose::ClosedMosaic summaryOf(const tiles::TileRecord& record) {
  compose::ClosedMosaic m;
  const tiles::TileMetadata& d = record.metadata;
  m.first_frame = d.first_frame;
  m.last_frame = d.last_frame;
  m.start_time_s = d.start_time_s;
  m.end_time_s = d.end_time_s;
  m.mean_camera_height_m = std::isfinite(d.mean_altitude_m) ? d.mean_altitude_m : 0.0;
  m.close_reason = d.close_reason;
  m.frames_composed = static_cast<int>(record.images.size());
  const auto sigma = d.extra.find("position_sigma_m");
  if (sigma != d.extra.end()) m.anchor_sigma_m = std::strtod(sigma->second.c_str(), nullptr);
  m.gsd_m = record.gsd_m;
  return m;
}

}  // namespace

void TileWriterRos::writeRevision(PendingTile& pending, tiles::GeoTiffTileWriter* writer,
                                  std::unique_lock<std::mutex>& lock) {
  tiles::RevisedTile& revision = *pending.revision;
  const tiles::TileRecord& record = revision.record;
  writing_ = true;
  lock.unlock();
  // Matched again to the others as they are now (its lighting and place changed; its own record left out), unless its
  // images carry their own gains: then its levels are kept as drawn, for the new tiles to match.
  std::optional<compose::TileGains> gains;
  if (config_.gain_compensation && !config_.image_gain_compensation) {
    gains = gains_.estimate(revision.raster, record.index);
  } else if (config_.gain_compensation) {
    gains = compose::TileGains();
    gains->channels = revision.raster.image.channels();
  }
  if (gains && gains->channels == revision.raster.image.channels())
    revision.raster = compose::TileGainCompensator::apply(revision.raster, *gains);
  const tiles::WrittenTile tile = writer->writeVersion(revision.raster, record.metadata, record.index, record.version);
  if (tile.ok && gains && gains->channels == revision.raster.image.channels())
    gains_.record(record.index, revision.raster, *gains);
  if (tile.ok) {
    // The previous version goes once the new one is complete.
    writer->removeVersion(record.index, record.version - 1);
    saveRecord(record, *writer);
  }
  lock.lock();
  writing_ = false;
  revision_pending_.erase(record.index);
  if (!tile.ok) {
    // The previous version stays; the next look tries again.
    ++rerender_failures_;
    last_rerender_problem_ = "tile " + std::to_string(record.index) + " not written again: " + tile.error;
    ROS_ERROR_THROTTLE(5.0, "tile writer: %s", last_rerender_problem_.c_str());
    write_cv_.notify_all();
    return;
  }
  noteCompanionErrorsLocked(tile);
  // Keep an adjustment made while this version was drawn (applied to the record since): it is the newer.
  const auto current = records_.find(record.index);
  tiles::TileRecord committed = record;
  if (current != records_.end()) committed.adjustment = current->second.adjustment;
  records_[record.index] = committed;
  tiles_changed_since_adjustment_ = true;
  ++tiles_rerendered_;
  ROS_INFO("tile writer: %s drawn again (version %d, images moved by up to %.3f m) in %.0f ms",
           tile.geotiff_path.c_str(), tile.version, revision.moved_max_m, tile.write_ms);
  publishTile(tile, pending.mosaic);
  vrt_stale_ = true;
  lock.unlock();
  updateMosaicVrt(false);
  lock.lock();
  write_cv_.notify_all();
}

void TileWriterRos::updateMosaicVrt(bool now) {
  if (!config_.mosaic_vrt || !vrt_stale_) return;
  if (!now && (ros::WallTime::now() - last_vrt_wall_).toSec() < 2.0) return;
  const std::vector<std::string> paths = tiles::listTiles(config_.files.output_dir);
  if (paths.empty()) return;
  const std::string vrt = config_.files.output_dir + "/" + config_.files.prefix + "_mosaic.vrt";
  const std::string error = tiles::writeTileMosaicVrt(vrt, paths);
  last_vrt_wall_ = ros::WallTime::now();
  if (!error.empty()) {
    ROS_WARN_THROTTLE(30.0, "tile writer: %s", error.c_str());
    return;
  }
  vrt_stale_ = false;
}

void TileWriterRos::rerenderLoop() {
  // Drawing tiles again may wait; the chain may not: this thread yields the CPU to the node's others.
  exocet_common::lowerThisThreadPriority();
  std::unique_lock<std::mutex> lock(rerender_mutex_);
  ros::WallTime last_save = ros::WallTime::now(), last_adjustment = ros::WallTime::now();
  while (!stop_rerender_) {
    rerender_cv_.wait_for(lock, std::chrono::duration<double>(config_.rerender_period_s),
                          [this]() { return stop_rerender_; });
    if (stop_rerender_) break;
    lock.unlock();
    loadKeptImageLevels();
    rerenderDue();
    if (!config_.graph_corrections_topic.empty() && config_.tile_adjustment_period_s > 0.0 &&
        (ros::WallTime::now() - last_adjustment).toSec() >= config_.tile_adjustment_period_s) {
      last_adjustment = ros::WallTime::now();
      if (adjustWrittenTiles() > 0) rerenderDue();
    }
    if (!config_.graph_corrections_topic.empty() && (ros::WallTime::now() - last_save).toSec() > 10.0) {
      saveCorrections();
      last_save = ros::WallTime::now();
    }
    lock.lock();
  }
}

int TileWriterRos::rerenderDue(bool every_tile) {
  tiles::PositionCorrectionTrack track;
  std::int64_t received = 0;
  {
    std::lock_guard<std::mutex> lock(corrections_mutex_);
    track = corrections_;
    received = corrections_received_;
  }
  if (track.empty() && !every_tile && !config_.image_gain_compensation) return 0;
  // The images are kept before the lighting correction: corrected with the field as it is now.
  std::shared_ptr<compose::LightingCorrector> lighting;
  {
    std::lock_guard<std::mutex> lock(compose_mutex_);
    lighting = std::make_shared<compose::LightingCorrector>(composer_.lightingSnapshot());
  }
  const bool gains = config_.image_gain_compensation;
  if (gains) solveImageGains(*lighting, every_tile);
  const auto gain_change = [&](int tile, const tiles::RecordedImage& image) {
    const std::array<double, 3> now = intendedGain(tile, image);
    double change = 0;
    for (int c = 0; c < 3; ++c) change = std::max(change, std::abs(now[c] / image.gain[c] - 1.0));
    return change;
  };
  std::vector<tiles::TileRecord> due;
  std::vector<bool> keep_placements;
  std::vector<double> urgency;     ///< how far past its thresholds a due tile is (the largest of the two ratios)
  std::vector<bool> out_of_place;  ///< moved by the graph beyond the threshold (not only relit)
  {
    std::lock_guard<std::mutex> lock(write_mutex_);
    for (const auto& [index, record] : records_) {
      if (revision_pending_.count(index)) continue;
      double largest_gain_change = 0.0;
      if (gains)
        for (const tiles::RecordedImage& image : record.images)
          largest_gain_change = std::max(largest_gain_change, gain_change(index, image));
      const bool relit = largest_gain_change > config_.image_gain_redraw_change;
      // Drawn with them, or near enough not to be drawn again for them: the tile's version on disk is what it lends.
      if (!relit) intended_gains_.erase(index);
      // Drawing it failed with these corrections: tried again with the next ones, or new gains (solved only when
      // images were added).
      const auto failed = revision_failed_at_.find(index);
      if (failed != revision_failed_at_.end() && failed->second == received && !relit) continue;
      const double moved_m = track.empty() ? 0.0 : tiles::tileDisplacementM(record, track, config_.revision);
      max_tile_move_m_ = std::max(max_tile_move_m_, moved_m);
      const bool moved = moved_m > config_.rerender_threshold_gsd * record.gsd_m;
      if (every_tile || relit || moved) {
        due.push_back(record);
        // Without the graph, or not moved by it: drawn where it is (placementsAt() would fit it to the navigation
        // again, without the tie to its neighbours the composer gave it).
        keep_placements.push_back(track.empty() || (!moved && !every_tile));
        out_of_place.push_back(moved);
        urgency.push_back(std::max(moved_m / (config_.rerender_threshold_gsd * record.gsd_m),
                                   largest_gain_change / config_.image_gain_redraw_change));
        if (relit && !every_tile && !moved) ++tiles_redrawn_for_gains_;
      }
    }
  }
  if (due.empty()) return 0;
  // The tiles out of place first, then the most out of tone; each drawn only when the writer holds fewer than
  // kMaxQueuedRevisions drawn tiles, as a drawn tile is a whole raster (tens of MB) and after a loop closure or a new
  // gain solution every tile of the dive may be due at once. The periodic pass stops when the node stops; the rest is
  // due again at the next pass (or at the last one, which draws every tile).
  std::vector<std::size_t> order(due.size());
  std::iota(order.begin(), order.end(), std::size_t{0});
  if (!every_tile)
    // Where a tile is comes before its tone: a fast replay writes tiles faster than this thread can draw them again,
    // and each new tile's image gains may relight several.
    std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
      if (out_of_place[a] != out_of_place[b]) return static_cast<bool>(out_of_place[a]);
      return urgency[a] > urgency[b];
    });
  if (gains)
    for (tiles::TileRecord& record : due)
      for (tiles::RecordedImage& image : record.images) image.gain = intendedGain(record.index, image);
  compose::PlacedImageRenderConfig render;
  render.blend = config_.composer.blend;
  render.feather_power = config_.composer.feather_power;
  render.multiband_bands = config_.composer.multiband_bands;
  const auto prepare = [lighting](const cv::Mat& image) { return lighting->correct(image); };
  int queued = 0;
  for (const std::size_t k : order) {
    if (!waitForRevisionRoom(!every_tile)) break;
    const tiles::TileRecord& record = due[k];
    const auto start = std::chrono::steady_clock::now();
    std::vector<cv::Matx33d> current;
    for (const tiles::RecordedImage& image : record.images) current.push_back(image.ground_from_px);
    tiles::RevisedTile revision =
        keep_placements[k] ? tiles::renderTileWith(record, current, images_dir_, render, prepare)
                           : tiles::renderTileAt(record, track, images_dir_, render, config_.revision, prepare);
    const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    std::lock_guard<std::mutex> lock(write_mutex_);
    last_rerender_ms_ = ms;
    if (revision.raster.image.empty()) {
      ++rerender_failures_;
      revision_failed_at_[record.index] = received;
      last_rerender_problem_ = "tile " + std::to_string(record.index) + " cannot be drawn again: " + revision.problem;
      ROS_WARN_THROTTLE(10.0, "tile writer: %s", last_rerender_problem_.c_str());
      continue;
    }
    if (!revision.problem.empty()) last_rerender_problem_ = revision.problem;
    revision.record.metadata.extra["blend"] = render.blend;
    revision_failed_at_.erase(record.index);
    revision_pending_.insert(record.index);
    PendingTile pending;
    pending.mosaic = summaryOf(revision.record);
    pending.revision = std::move(revision);
    write_queue_.push_back(std::move(pending));
    write_cv_.notify_all();
    ++queued;
  }
  return queued;
}

bool TileWriterRos::waitForRevisionRoom(bool interruptible) {
  const auto queued_revisions = [this]() {
    return std::count_if(write_queue_.begin(), write_queue_.end(),
                         [](const PendingTile& p) { return p.revision.has_value(); });
  };
  while (true) {
    {
      std::unique_lock<std::mutex> lock(write_mutex_);
      if (write_cv_.wait_for(lock, std::chrono::milliseconds(200),
                             [&]() { return stop_writer_ || queued_revisions() < kMaxQueuedRevisions; }))
        return !stop_writer_;
    }
    if (interruptible) {
      std::lock_guard<std::mutex> lock(rerender_mutex_);
      if (stop_rerender_) return false;
    }
  }
}

std::array<double, 3> TileWriterRos::intendedGain(int tile, const tiles::RecordedImage& image) const {
  const auto intended = intended_gains_.find(tile);
  if (intended == intended_gains_.end()) return image.gain;
  const auto g = intended->second.find(image.file);
  return g != intended->second.end() ? g->second : std::array<double, 3>{1.0, 1.0, 1.0};
}

void TileWriterRos::solveImageGains(const compose::LightingCorrector& lighting, bool always) {
  {
    std::lock_guard<std::mutex> lock(image_gains_mutex_);
    if (!always && image_levels_added_ == image_levels_solved_) return;
  }
  // The newest tiles solved against the gains the older tiles under them were drawn with: the solve's size does not
  // grow with the dive.
  tiles::GainWindow window;
  std::map<std::string, compose::ImagePlacement> placements;
  std::map<std::string, std::array<double, 3>> fixed;
  std::set<std::string> solved_files, window_files;
  {
    std::lock_guard<std::mutex> lock(write_mutex_);
    window = tiles::gainWindow(records_, config_.image_gain_window_tiles);
    const cv::Size grid(image_gains_.config().grid_columns, image_gains_.config().grid_rows);
    for (const int index : window.solved) {
      const tiles::TileRecord& record = records_.at(index);
      tiles::addImagePlacements(record, {}, &lighting, grid, &placements);
      if (!window.anchors.empty())
        for (const tiles::RecordedImage& image : record.images) solved_files.insert(image.file);
    }
    for (const int index : window.anchors) {
      const tiles::TileRecord& record = records_.at(index);
      tiles::addImagePlacements(record, {}, &lighting, grid, &placements);
      // An anchor lends the gains it is to be drawn with, not those of its version on disk if a drawing with newer
      // ones is due or under way.
      for (const tiles::RecordedImage& image : record.images)
        if (!solved_files.count(image.file)) fixed[image.file] = intendedGain(index, image);  // tiles share an image
    }
  }
  if (config_.image_gain_window_tiles > 0) {
    // The levels of the window's images that were let go, read back (a solve of every tile has them all).
    for (const auto& [file, placement] : placements) window_files.insert(file);
    const int read = readKeptLevels(std::vector<std::string>(window_files.begin(), window_files.end()), false, nullptr);
    std::lock_guard<std::mutex> lock(write_mutex_);
    levels_read_back_ += read;
  }
  const auto start = std::chrono::steady_clock::now();
  compose::ImageGainSolution solution;
  {
    std::lock_guard<std::mutex> lock(image_gains_mutex_);
    image_levels_solved_ = image_levels_added_;
    solution = image_gains_.solve(placements, fixed);
  }
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  if (config_.image_gain_window_tiles > 0) letGoOfLevels(window, window_files);
  if (solution.problem.empty()) {
    std::lock_guard<std::mutex> lock(write_mutex_);
    for (const int index : window.solved) {
      const auto record = records_.find(index);
      if (record == records_.end()) continue;
      std::map<std::string, std::array<double, 3>>& intended = intended_gains_[index];
      intended.clear();
      for (const tiles::RecordedImage& image : record->second.images) {
        const auto g = solution.gain.find(image.file);
        intended[image.file] = g != solution.gain.end() ? g->second : std::array<double, 3>{1.0, 1.0, 1.0};
      }
    }
  }
  solution.gain.clear();
  // Once per tile written (a solve follows new images), or at the last look.
  if (!window.solved.empty()) {
    const std::string outcome = solution.problem.empty()
                                    ? cv::format("%d pairs, level step %.1f -> %.1f grey, %.0f ms", solution.pairs,
                                                 solution.step_before_grey, solution.step_after_grey, ms)
                                    : "not solved: " + solution.problem;
    ROS_INFO("tile writer: image gains of tiles %d-%d (%d images, %d anchors from %zu older tiles): %s",
             window.solved.front(), window.solved.back(), solution.images - solution.fixed_images,
             solution.fixed_images, window.anchors.size(), outcome.c_str());
  }
  std::lock_guard<std::mutex> lock(write_mutex_);
  ++image_gain_solves_;
  last_image_gain_ms_ = ms;
  last_image_gains_ = solution;
}

int TileWriterRos::readKeptLevels(const std::vector<std::string>& files, bool new_images, int* unreadable) {
  const compose::ImageGainsConfig& g = image_gains_.config();
  int read = 0;
  for (const std::string& file : files) {
    {
      std::lock_guard<std::mutex> lock(image_gains_mutex_);
      // Consecutive tiles share an image; a file that could not be read is not tried at every solve.
      if (image_gains_.contains(file) || levels_unreadable_.count(file)) continue;
    }
    const cv::Mat image = cv::imread(images_dir_ + "/" + file, cv::IMREAD_UNCHANGED);
    std::lock_guard<std::mutex> lock(image_gains_mutex_);
    if (image.empty()) {
      levels_unreadable_.insert(file);  // left out of the solves (its tile is drawn without it too)
      if (unreadable) ++*unreadable;
      continue;
    }
    if (image_gains_.add(file, compose::imageLevels(image, g.grid_columns, g.grid_rows))) {
      ++read;
      if (new_images) ++image_levels_added_;
    }
  }
  return read;
}

void TileWriterRos::letGoOfLevels(const tiles::GainWindow& window, const std::set<std::string>& window_files) {
  if (!levels_cache_) levels_cache_ = std::make_unique<tiles::TileLevelsCache>(config_.image_gain_levels_cache_tiles);
  std::vector<int> used = window.solved;
  used.insert(used.end(), window.anchors.begin(), window.anchors.end());
  const std::vector<int> let_go = levels_cache_->use(used);
  if (let_go.empty()) return;
  std::vector<std::string> files;
  {
    std::lock_guard<std::mutex> lock(write_mutex_);
    for (const int index : let_go) {
      const auto record = records_.find(index);
      if (record == records_.end()) continue;
      for (const tiles::RecordedImage& image : record->second.images) {
        // An image a tile still in the cache shares stays (its levels are read back anyway if it goes).
        if (window_files.count(image.file)) continue;
        files.push_back(image.file);
      }
    }
  }
  std::int64_t removed = 0;
  {
    std::lock_guard<std::mutex> lock(image_gains_mutex_);
    for (const std::string& file : files)
      if (image_gains_.contains(file)) {
        image_gains_.remove(file);
        ++removed;
      }
  }
  std::lock_guard<std::mutex> lock(write_mutex_);
  levels_let_go_ += removed;
}

int TileWriterRos::adjustWrittenTiles() {
  std::vector<std::string> paths;
  std::map<std::string, std::pair<int, int>> tile_of_path;  // path -> (index, version)
  {
    std::lock_guard<std::mutex> lock(write_mutex_);
    if (!tiles_changed_since_adjustment_ || !revision_pending_.empty() || !write_queue_.empty() || writing_) return 0;
    tiles_changed_since_adjustment_ = false;
    for (const auto& [index, record] : records_) {
      const std::string path = config_.files.output_dir + "/" + writer_->baseName(index, record.version) + ".tif";
      paths.push_back(path);
      tile_of_path[path] = {index, record.version};
    }
  }
  if (paths.size() < 2) return 0;
  const tiles::TileAdjustmentResult network =
      tiles::measureAndSolve(paths, tiles::TileAdjustmentConfig(), &tile_pairs_);
  std::lock_guard<std::mutex> lock(write_mutex_);
  tile_pairs_measured_ = tile_pairs_.measured();
  tile_pairs_reused_ = tile_pairs_.reused();
  if (!network.ok) {
    last_rerender_problem_ = "tiles not registered with each other: " + network.error;
    ROS_WARN_THROTTLE(30.0, "tile writer: %s", last_rerender_problem_.c_str());
    return 0;
  }
  ++tile_adjustments_;
  last_adjustment_pair_max_px_ = 0;
  for (const auto& pair : network.pairs)
    last_adjustment_pair_max_px_ =
        std::max(last_adjustment_pair_max_px_, pair.offset_en_m.norm() / network.tiles[pair.a].gsd_m);
  int adjusted = 0;
  for (const tiles::AdjustedTile& t : network.tiles) {
    const auto which = tile_of_path.find(t.path);
    if (which == tile_of_path.end()) continue;
    const auto record = records_.find(which->second.first);
    // A tile drawn again meanwhile was measured in its previous version: its move waits for the next registration.
    if (record == records_.end() || record->second.version != which->second.second) continue;
    // A move under the redraw threshold is the registration's noise: left out, so that the tiles settle.
    const double half_diagonal_m = 0.5 * std::hypot(t.width_px, t.height_px) * t.gsd_m;
    const double move_m = t.shift_en_m.norm() + std::hypot(t.rotation_rad, t.scale_change) * half_diagonal_m;
    if (move_m <= config_.rerender_threshold_gsd * t.gsd_m) continue;
    tiles::applyTileAdjustment(&record->second, t.centre_en_m, t.shift_en_m, t.rotation_rad, t.scale_change);
    ++adjusted;
  }
  return adjusted;
}

void TileWriterRos::saveCorrections() {
  if (images_dir_.empty()) return;
  // The graph's 1-sigma in the last columns, empty where it has none: readPositionCorrections reads the first three.
  std::string text = "stamp_s,east_m,north_m,east_sigma_m,north_sigma_m,east_north_correlation\n";
  {
    std::lock_guard<std::mutex> lock(corrections_mutex_);
    if (corrections_.empty() || corrections_saved_ == corrections_received_) return;
    corrections_saved_ = corrections_received_;
    char line[160];
    for (std::size_t i = 0; i < corrections_.size(); ++i) {
      const double stamp_s = corrections_.stamps()[i];
      const int length = std::snprintf(line, sizeof(line), "%.6f,%.6f,%.6f", stamp_s, corrections_.corrections()[i].x(),
                                       corrections_.corrections()[i].y());
      text.append(line, length);
      const auto sigma = correction_sigmas_.find(stamp_s);
      if (sigma != correction_sigmas_.end()) {
        const int more = std::snprintf(line, sizeof(line), ",%.6f,%.6f,%.4f\n", sigma->second[0], sigma->second[1],
                                       sigma->second[2]);
        text.append(line, more);
      } else {
        text += ",,,\n";
      }
    }
  }
  try {
    exocet_common::writeFileAtomically(images_dir_ + "/graph_corrections.csv", text);
  } catch (const std::exception& e) {
    ROS_WARN_THROTTLE(30.0, "tile writer: graph corrections not saved: %s", e.what());
  }
}

void TileWriterRos::noteCompanionErrorsLocked(const tiles::WrittenTile& tile) {
  last_tile_lacks_companion_ = !tile.companion_errors.empty();
  for (const std::string& error : tile.companion_errors) {
    ++companion_failures_;
    last_companion_error_ = "tile " + std::to_string(tile.index) + " " + error;
    ROS_WARN_THROTTLE(5.0, "tile writer: %s written without its %s", tile.geotiff_path.c_str(), error.c_str());
  }
}

void TileWriterRos::publishTile(const tiles::WrittenTile& tile, const compose::ClosedMosaic& mosaic) {
  exocet_msgs::Tile msg;
  msg.header.stamp.fromSec(std::max(0.0, mosaic.end_time_s));
  msg.header.frame_id = tile.local_frame.empty() ? config_.frame_id : tile.local_frame;
  msg.index = tile.index;
  msg.version = tile.version;
  msg.geotiff_path = tile.geotiff_path;
  msg.world_file_path = tile.world_file_path;
  msg.cog_path = tile.cog_path;
  msg.kmz_path = tile.kmz_path;
  msg.epsg = tile.epsg;
  msg.utm_zone = utm_zone_.value_or(0);
  msg.northern_hemisphere = northern_;
  msg.min_easting_m = tile.min_easting_m;
  msg.min_northing_m = tile.min_northing_m;
  msg.max_easting_m = tile.max_easting_m;
  msg.max_northing_m = tile.max_northing_m;
  msg.west_deg = tile.west_deg;
  msg.south_deg = tile.south_deg;
  msg.east_deg = tile.east_deg;
  msg.north_deg = tile.north_deg;
  msg.gsd_m = tile.gsd_m;
  msg.width_px = tile.width_px;
  msg.height_px = tile.height_px;
  msg.first_frame = mosaic.first_frame;
  msg.last_frame = mosaic.last_frame;
  msg.start_time.fromSec(std::max(0.0, mosaic.start_time_s));
  msg.end_time.fromSec(std::max(0.0, mosaic.end_time_s));
  msg.frames_composed = mosaic.frames_composed;
  msg.mean_altitude_m = mosaic.mean_camera_height_m;
  msg.position_sigma_m = mosaic.anchor_sigma_m;
  msg.close_reason = mosaic.close_reason;
  msg.write_ms = tile.write_ms;
  tile_pub_.publish(msg);
  if (notifier_) {
    std::string error;
    if (!notifier_->send(tile, &error)) {
      ++udp_failures_;
      ROS_WARN_THROTTLE(10.0, "tile writer: UDP notification to %s not sent: %s", notifier_->destination().c_str(),
                        error.c_str());
    }
  }
  const std::array<Eigen::Vector2d, 4> outline = {Eigen::Vector2d(tile.min_easting_m, tile.min_northing_m),
                                                  Eigen::Vector2d(tile.max_easting_m, tile.min_northing_m),
                                                  Eigen::Vector2d(tile.max_easting_m, tile.max_northing_m),
                                                  Eigen::Vector2d(tile.min_easting_m, tile.max_northing_m)};
  const auto same = std::find_if(written_.begin(), written_.end(),
                                 [&](const tiles::WrittenTile& w) { return w.index == tile.index; });
  if (same != written_.end()) {  // a new version replaces the tile's footprint
    written_outlines_[same - written_.begin()] = outline;
    *same = tile;
    publishFootprints();
    return;
  }
  written_.push_back(tile);
  written_outlines_.push_back(outline);
  if (written_.size() > kMaxFootprints) {
    written_.erase(written_.begin());
    written_outlines_.erase(written_outlines_.begin());
  }
  publishFootprints();
}

void TileWriterRos::publishFootprints() {
  // rviz draws in single precision: UTM coordinates go relative to the map origin when the fusion gave one.
  const bool in_map = map_origin_en_m_.has_value() && local_frame_.empty();
  const Eigen::Vector2d origin = in_map ? *map_origin_en_m_ : Eigen::Vector2d::Zero();
  visualization_msgs::MarkerArray array;
  for (std::size_t i = 0; i < written_outlines_.size(); ++i) {
    visualization_msgs::Marker m;
    m.header.stamp = ros::Time::now();
    m.header.frame_id = in_map ? config_.map_frame : !local_frame_.empty() ? local_frame_ : config_.frame_id;
    m.ns = "tiles";
    m.id = written_[i].index;
    m.type = visualization_msgs::Marker::LINE_STRIP;
    m.action = visualization_msgs::Marker::ADD;
    m.pose.orientation.w = 1.0;
    m.scale.x = 0.05;
    m.color.r = 1.0f;
    m.color.g = 0.6f;
    m.color.b = 0.1f;
    m.color.a = 1.0f;
    for (int k = 0; k <= 4; ++k) {
      geometry_msgs::Point p;
      p.x = written_outlines_[i][k % 4].x() - origin.x();
      p.y = written_outlines_[i][k % 4].y() - origin.y();
      m.points.push_back(p);
    }
    array.markers.push_back(m);
  }
  footprints_pub_.publish(array);
}

// ---------------------------------------------------------------------------------------------------------------
// Health.

void TileWriterRos::diagnose(diagnostic_updater::DiagnosticStatusWrapper& status) {
  compose::ComposerStats stats;
  std::size_t pending = 0;
  {
    std::lock_guard<std::mutex> lock(compose_mutex_);
    stats = composer_.stats();
    pending = assembler_.pendingImages();
  }
  std::size_t queued = 0, failed = 0;
  std::int64_t written = 0, write_failures = 0, dropped = 0;
  std::string write_error, companion_error;
  bool writer_behind = false, lacks_companion = false;
  std::int64_t companion_failures = 0;
  {
    std::lock_guard<std::mutex> lock(write_mutex_);
    writer_behind = tilesQueuedLocked() >= config_.max_queued_tiles;
    queued = write_queue_.size();
    failed = failed_tiles_.size();
    written = tiles_written_;
    write_failures = write_failures_;
    dropped = tiles_dropped_;
    write_error = last_write_error_;
    lacks_companion = last_tile_lacks_companion_;
    companion_error = last_companion_error_;
    companion_failures = companion_failures_;
  }
  if (dropped > 0)
    status.summary(DiagnosticStatus::ERROR, "tiles lost: the output folder kept failing (" + write_error + ")");
  else if (failed > 0)
    status.summary(DiagnosticStatus::ERROR, "tiles waiting for a retry: " + write_error);
  else if (!utm_zone_ && local_frame_.empty())
    status.summary(DiagnosticStatus::WARN, "no UTM zone yet (/mosaic/datum or ~utm_zone)");
  else if (images_.load() > 0 && stats.frames_composed == 0)
    status.summary(DiagnosticStatus::WARN, "images arrive but none is composed: " + stats.last_problem);
  else if (lacks_companion)
    status.summary(DiagnosticStatus::WARN, "tiles written without a companion file: " + companion_error);
  else if (writer_behind)
    status.summary(DiagnosticStatus::WARN,
                   "the writer falls behind the images: the composition waits for it (~max_queued_tiles)");
  else
    status.summary(DiagnosticStatus::OK, "composing");
  {
    std::lock_guard<std::mutex> lock(write_mutex_);
    status.add("frame of the tiles", local_frame_.empty() ? "UTM" : "local frame '" + local_frame_ + "'");
  }
  status.add("run", run_note_.empty() ? std::string("waiting for the first image") : run_note_);
  status.add("images received", images_.load());
  status.add("images rejected", rejected_);
  status.add("frames composed", stats.frames_composed);
  status.add("frames skipped (no pose)", stats.frames_skipped_no_pose);
  status.add("frames skipped (no chain, no pose)", stats.frames_skipped_no_chain);
  status.add("registration gaps bridged by the navigation", stats.registration_fallbacks);
  status.add("navigation jumps", stats.navigation_jumps);
  status.add("frames waiting for motion/pose", pending);
  status.add("frames released incomplete (timeout)", assembler_.timedOut());
  status.add("late or repeated parts ignored", assembler_.lateParts() + assembler_.duplicateImages());
  status.add("clock jumps", clock_jumps_);
  status.add("open mosaic images", stats.open_frames);
  status.add("open mosaic extent (m)", stats.open_extent_m);
  status.add("open mosaic memory (MB)", static_cast<double>(stats.open_memory_bytes) / 1e6);
  status.add("lighting field ready", stats.lighting_ready);
  status.add("images composed at 1/reduction", stats.image_reduction);
  status.add("tiles written", written);
  {
    std::lock_guard<std::mutex> lock(write_mutex_);
    status.add("frames not on disk yet", framesNotOnDiskLocked(next_frame_index_ + static_cast<int>(pending)));
    status.addf("newest image stamp (s)", "%.3f", newest_image_stamp_s_.load());
    if (run_base_.restarts > 0) {
      status.add("tiles written (run)", run_base_.tiles_written + tiles_written_);
      status.add("restarts (run)", run_base_.restarts);
      status.add("frames lost at the last restart", frames_lost_at_restart_);
      status.add("frames lost (run)", run_base_.frames_lost);
    }
  }
  status.add("tiles queued", queued);
  {
    std::lock_guard<std::mutex> lock(write_mutex_);
    status.add("tiles queued (most at once)", tiles_queued_max_);
    status.add("composition waits for the writer", composition_waits_);
    status.addf("composition wait for the writer (s)", "%.1f", composition_wait_s_);
  }
  status.add("tiles waiting for a retry", failed);
  status.add("write failures", write_failures);
  status.add("tiles lost", dropped);
  status.add("companion files not written (COG, KMZ)", companion_failures);
  if (!companion_error.empty()) status.add("last companion file not written", companion_error);
  status.add("UDP failures", udp_failures_);
  if (config_.gain_compensation) {
    std::lock_guard<std::mutex> lock(write_mutex_);
    status.add("last tile gain correction", last_gain_note_.empty() ? "none yet" : last_gain_note_);
  }
  if (config_.keep_images) {
    std::lock_guard<std::mutex> lock(write_mutex_);
    status.add("images kept", images_kept_);
    status.add("images not kept", images_not_kept_);
    if (config_.image_gain_compensation) {
      status.add("image gain solves", image_gain_solves_);
      status.add("images in the last gain solve", last_image_gains_.images);
      status.add("of which anchors (gains as drawn)", last_image_gains_.fixed_images);
      status.add("overlapping image pairs", last_image_gains_.pairs);
      std::size_t levels_in_memory = 0;
      {
        std::lock_guard<std::mutex> gains_lock(image_gains_mutex_);
        levels_in_memory = image_gains_.size();
      }
      status.add("image levels in memory", levels_in_memory);
      status.add("image levels read back / let go",
                 std::to_string(levels_read_back_) + " / " + std::to_string(levels_let_go_));
      status.addf("largest level step between images (grey, before -> after their gains)", "%.1f -> %.1f",
                  last_image_gains_.step_before_grey, last_image_gains_.step_after_grey);
      status.addf("last image gain solve (ms)", "%.1f", last_image_gain_ms_);
      status.add("tiles drawn again for their gains", tiles_redrawn_for_gains_);
      if (!last_image_gains_.problem.empty()) status.add("image gains not solved", last_image_gains_.problem);
    }
    if (redraws_) {
      status.add("tiles drawn again", tiles_rerendered_);
      status.add("tiles waiting to be drawn again", revision_pending_.size());
      status.add("failures drawing a tile again", rerender_failures_);
      status.addf("largest move of a written tile's images (m)", "%.4f", max_tile_move_m_);
      status.addf("last drawing of a tile again (ms)", "%.0f", last_rerender_ms_);
      status.add("registrations of the tiles with each other", tile_adjustments_);
      status.add("tile pairs measured / reused by them",
                 std::to_string(tile_pairs_measured_) + " / " + std::to_string(tile_pairs_reused_));
      status.addf("largest offset between overlapping tiles at the last registration (px)", "%.2f",
                  last_adjustment_pair_max_px_);
      if (!last_rerender_problem_.empty()) status.add("last problem drawing a tile again", last_rerender_problem_);
    }
  }
  if (!config_.graph_corrections_topic.empty()) {
    std::lock_guard<std::mutex> lock(corrections_mutex_);
    status.add("graph corrections received", corrections_received_);
    status.add("graph key frames", corrections_.size());
  }
  status.add("last problem", last_problem_.empty() ? stats.last_problem : last_problem_);
  status.add("last write error", write_error);
  if (const auto heap = exocet_common::heapUsage()) {  // resident memory that rises while this stays flat is malloc's
    status.addf("heap in use (MB)", "%.1f", heap->in_use_mb);
    status.addf("heap freed, kept by malloc (MB)", "%.1f", heap->free_held_mb);
    status.add("heap allocator", exocet_common::heapAllocator());
  }
}

// ---------------------------------------------------------------------------------------------------------------
// A run carried over restarts.

void TileWriterRos::loadPreviousRun() {
  const std::string path = tiles::tileWriterProgressPath(config_.files.output_dir, config_.files.prefix);
  std::error_code error;
  if (!std::filesystem::exists(path, error)) return;
  try {
    const auto json = exocet_common::readJsonObjectFile<nlohmann::json>(path);
    if (!json) throw std::invalid_argument("not a JSON object");
    previous_run_ = tiles::tileWriterProgressFromJson(*json);
  } catch (const std::exception& e) {
    ROS_WARN("tile writer: %s cannot be read (%s): this instance starts a new run", path.c_str(), e.what());
    return;
  }
  if (config_.keep_images) {
    kept_tiles_ = tiles::loadKeptTiles(images_dir_, *writer_);
    for (const std::string& problem : kept_tiles_.problems)
      ROS_WARN("tile writer: record left out: %s", problem.c_str());
    if (kept_tiles_.versions_removed > 0)
      ROS_WARN("tile writer: removed %d older tile version(s) an interrupted redraw had left",
               kept_tiles_.versions_removed);
  }
  ROS_INFO(
      "tile writer: %s holds a run that %s (%lld tiles, newest image at %.3f s): carried on if the first image comes "
      "within %.0f s after it",
      config_.files.output_dir.c_str(), previous_run_->finished ? "ended normally" : "was interrupted",
      static_cast<long long>(previous_run_->tiles_written), previous_run_->newest_stamp_s, config_.resume_max_gap_s);
}

void TileWriterRos::decideRun(double first_stamp_s) {
  if (previous_run_) {
    const std::string why = tiles::continuationRefusal(*previous_run_, first_stamp_s, config_.resume_max_gap_s);
    if (why.empty()) {
      continueRun(*previous_run_, true);
    } else {
      run_note_ = "a new run: the one in the folder is not carried on (" + why + ")";
      ROS_WARN("tile writer: %s; its tiles stay as they are", run_note_.c_str());
    }
  } else {
    run_note_ = "a new run";
  }
  kept_tiles_ = tiles::KeptTiles();
  run_decided_ = true;
}

void TileWriterRos::continueRun(const tiles::TileWriterProgress& previous, bool adopt_tiles) {
  next_frame_index_ = previous.next_frame;
  std::size_t adopted = 0;
  {
    std::lock_guard<std::mutex> lock(write_mutex_);
    frames_lost_at_restart_ = previous.frames_not_on_disk;
    run_base_ = previous;
    run_base_.frames_lost += previous.frames_not_on_disk;
    run_base_.restarts += 1;
    run_base_.finished = false;
    newest_frame_on_disk_ = previous.next_frame - 1;
    if (adopt_tiles) {
      for (tiles::TileRecord& record : kept_tiles_.records) {
        images_kept_ += static_cast<std::int64_t>(record.images.size());
        records_[record.index] = std::move(record);
        ++adopted;
      }
      if (adopted > 0) tiles_changed_since_adjustment_ = true;
    }
  }
  // A solve of the whole dive needs every image's levels; a windowed one reads back those it takes.
  if (adopt_tiles && config_.image_gain_compensation && config_.image_gain_window_tiles == 0) {
    std::vector<std::string> files;
    {
      std::lock_guard<std::mutex> lock(write_mutex_);
      for (const auto& [index, record] : records_)
        for (const tiles::RecordedImage& image : record.images) files.push_back(image.file);
    }
    std::lock_guard<std::mutex> lock(image_gains_mutex_);
    levels_to_load_.insert(levels_to_load_.end(), files.begin(), files.end());
  }
  if (adopt_tiles && !config_.graph_corrections_topic.empty()) {
    const std::string path = images_dir_ + "/graph_corrections.csv";
    std::error_code error;
    if (std::filesystem::exists(path, error)) {
      try {
        int left_out = 0;
        tiles::PositionCorrectionTrack track = tiles::readPositionCorrections(path, &left_out);
        std::lock_guard<std::mutex> lock(corrections_mutex_);
        if (corrections_.empty()) corrections_ = std::move(track);
      } catch (const std::exception& e) {
        ROS_WARN("tile writer: the saved graph corrections are not read back: %s", e.what());
      }
    }
  }
  rerender_cv_.notify_all();
  char note[256];
  std::snprintf(note, sizeof(note),
                "carried on after a restart (restart %d of the run; the previous instance %s): %zu written tiles' "
                "records read back, %d frames it held were lost",
                previous.restarts + 1, previous.finished ? "ended normally" : "was interrupted", adopted,
                previous.frames_not_on_disk);
  run_note_ = note;
  ROS_WARN("tile writer: %s (%s)", run_note_.c_str(), config_.files.output_dir.c_str());
}

int TileWriterRos::framesNotOnDiskLocked(int next_frame) const {
  int held = next_frame - 1 - newest_frame_on_disk_;
  // Closed mosaics older than the newest tile on disk that are still waiting for a write (a full disk).
  for (const std::deque<PendingTile>* tiles : {&write_queue_, &failed_tiles_})
    for (const PendingTile& tile : *tiles)
      if (!tile.revision && tile.mosaic.last_frame <= newest_frame_on_disk_)
        held += tile.mosaic.last_frame - tile.mosaic.first_frame;
  return std::max(0, held);
}

void TileWriterRos::saveProgress(bool finished) {
  if (!run_decided_) return;
  std::lock_guard<std::mutex> progress_lock(progress_mutex_);
  tiles::TileWriterProgress progress;
  std::int64_t composed = 0;
  int pending = 0;
  {
    std::lock_guard<std::mutex> lock(compose_mutex_);
    pending = static_cast<int>(assembler_.pendingImages());
    composed = composer_.stats().frames_composed;
  }
  progress.next_frame = next_frame_index_ + pending;
  {
    std::lock_guard<std::mutex> lock(write_mutex_);
    progress.frames_not_on_disk = framesNotOnDiskLocked(progress.next_frame);
    progress.tiles_written = run_base_.tiles_written + tiles_written_;
    progress.images_received = run_base_.images_received + images_;
    progress.frames_composed = run_base_.frames_composed + composed;
    progress.frames_lost = run_base_.frames_lost;
    progress.restarts = run_base_.restarts;
  }
  progress.newest_stamp_s = newest_image_stamp_s_;
  progress.finished = finished;
  try {
    exocet_common::writeJsonFileAtomically(
        tiles::tileWriterProgressPath(config_.files.output_dir, config_.files.prefix),
        tiles::tileWriterProgressToJson(progress));
  } catch (const std::exception& e) {
    ++progress_failures_;
    last_progress_error_ = e.what();
    ROS_WARN_THROTTLE(30.0, "tile writer: the run's progress is not saved (a restart could not carry it on): %s",
                      e.what());
  }
}

void TileWriterRos::loadKeptImageLevels() {
  std::vector<std::string> files;
  {
    std::lock_guard<std::mutex> lock(image_gains_mutex_);
    files.swap(levels_to_load_);
  }
  if (files.empty()) return;
  int unreadable = 0;
  const int loaded = readKeptLevels(files, true, &unreadable);
  ROS_INFO("tile writer: the gains of %d kept image(s) of the run read back%s", loaded,
           unreadable > 0 ? (" (" + std::to_string(unreadable) + " unreadable)").c_str() : "");
}

// ---------------------------------------------------------------------------------------------------------------
// End of the run.

std::string TileWriterRos::noTileReason() {
  compose::ComposerStats stats;
  {
    std::lock_guard<std::mutex> lock(compose_mutex_);
    stats = composer_.stats();
  }
  std::lock_guard<std::mutex> lock(write_mutex_);
  if (tiles_written_ + run_base_.tiles_written > 0) return "";
  if (images_ + run_base_.images_received == 0) return "no image arrived on " + config_.image_topic;
  if (stats.frames_composed == 0) {
    std::string why = std::to_string(images_.load()) + " images received, none composed: ";
    const std::string problem = !stats.last_problem.empty() ? stats.last_problem : last_problem_;
    if (poses_ == 0)
      why += "no fused pose arrived from the fusion (" + config_.odometry_topic +
             "): see fusion_node's log and /diagnostics";
    else if (camera_heights_ == 0)
      why += "no camera height arrived from the fusion (" + config_.camera_height_topic +
             "): a dive without an altimeter needs the camera's height above the seabed, fusion's ~initial_altitude_m "
             "(replay: camera_height_m:=M), or the seabed's depth, ~seabed_depth_m (replay: seabed_depth_m:=M)";
    else if (stats.frames_skipped_no_pose > 0 || stats.frames_skipped_no_chain > 0)
      why += "no fused pose at their stamps; see fusion_node's log and /diagnostics";
    else
      why += "they waited for their motion, pose and camera height and timed out";
    if (!problem.empty()) why += " (last problem: " + problem + ")";
    return why;
  }
  if (!failed_tiles_.empty() || tiles_dropped_ > 0) return "tiles could not be written: " + last_write_error_;
  return std::to_string(stats.frames_composed) + " images composed but no mosaic closed";
}

void TileWriterRos::writeRunSummary() {
  const std::string reason = noTileReason();
  nlohmann::ordered_json summary;
  tiles::TileWriterProgress base;
  {
    std::lock_guard<std::mutex> lock(write_mutex_);
    base = run_base_;
    summary["tiles_written"] = base.tiles_written + tiles_written_;
    summary["tiles_not_written"] = static_cast<std::int64_t>(failed_tiles_.size()) + tiles_dropped_;
    summary["frame"] = local_frame_.empty() ? "utm" : local_frame_;
    summary["epsg"] = local_frame_.empty() && utm_zone_ ? tiles::epsgForUtm(*utm_zone_, northern_) : 0;
  }
  summary["images_received"] = base.images_received + images_;
  summary["poses_received"] = poses_;
  summary["camera_heights_received"] = camera_heights_;
  {
    std::lock_guard<std::mutex> lock(compose_mutex_);
    summary["frames_composed"] = base.frames_composed + composer_.stats().frames_composed;
  }
  summary["restarts"] = base.restarts;
  summary["frames_lost"] = base.frames_lost;
  summary["reason"] = reason.empty() ? nlohmann::ordered_json(nullptr) : nlohmann::ordered_json(reason);
  if (!reason.empty()) ROS_ERROR("tile writer: no tile written: %s", reason.c_str());
  const std::string path = config_.files.output_dir + "/run_summary.json";
  try {
    exocet_common::writeJsonFileAtomically(path, summary);
  } catch (const std::exception& e) {
    ROS_ERROR("tile writer: cannot write %s: %s", path.c_str(), e.what());
  }
}

}  // namespace exocet_mosaic
