#include "exocet_web/ros/web_map_ros.h"

#include <chrono>
#include <cmath>

#include "exocet_common/free_heap.h"

namespace exocet_web {

namespace {

constexpr size_t kMaxPositionsWaitingForDatum = 10000;
constexpr double kDegPerRad = 180.0 / M_PI;
// A listing of the tiles folder: cheap, and a missed tile shows within this.
constexpr double kFolderLookPeriod_s = 2.0;
// A GeoTIFF younger than this may have its message still on the way: left for the next look.
constexpr std::chrono::milliseconds kMessageGrace(1000);

}  // namespace

WebMapRos::WebMapRos(ros::NodeHandle nh, ros::NodeHandle private_nh)
    : nh_(nh), private_nh_(private_nh), config_(readWebMapNodeConfig(private_nh)), updater_(nh, private_nh) {
  // Each kind of message throttled on its own, so that a flood of one does not hide another.
  map_ = std::make_unique<site::WebMap>(
      config_.site, [](site::WebMap::Severity severity, const std::string& topic, const std::string& message) {
        if (severity == site::WebMap::Severity::kDebug) {
          ROS_DEBUG("web map: %s", message.c_str());
        } else if (severity == site::WebMap::Severity::kInfo) {
          ROS_INFO("web map: %s", message.c_str());
        } else if (topic == "geotiff") {
          ROS_WARN_THROTTLE(5.0, "web map: %s", message.c_str());
        } else if (topic == "cut") {
          ROS_WARN_THROTTLE(5.0, "web map: %s", message.c_str());
        } else {
          ROS_ERROR_THROTTLE(5.0, "web map: %s", message.c_str());
        }
      });
  map_->start();
  server_ = std::make_unique<server::WebServer>(config_.server, config_.site.site_dir, &map_->events(),
                                                [this] { return map_->snapshotJson(); });
  server_->start();
  ROS_INFO("web map: %s (site %s, GeoTIFF tiles of %s)", url().c_str(), config_.site.site_dir.c_str(),
           config_.site.tiles_dir.c_str());
  private_nh_.setParam("url", url());  // the port chosen when ~port is 0
  if (config_.server.bind_address != "127.0.0.1" && config_.server.bind_address != "localhost" &&
      config_.server.bind_address != "::1")
    ROS_WARN("web map: listening on %s, not only this computer: anyone on that network can read the dive's map",
             config_.server.bind_address.c_str());

  tile_sub_ = nh_.subscribe(config_.tile_topic, 100, &WebMapRos::onTile, this);
  odometry_sub_ = nh_.subscribe(config_.odometry_topic, 1000, &WebMapRos::onOdometry, this);
  datum_sub_ = nh_.subscribe(config_.datum_topic, 10, &WebMapRos::onDatum, this);
  if (!config_.usbl_topic.empty()) usbl_sub_ = nh_.subscribe(config_.usbl_topic, 100, &WebMapRos::onUsbl, this);
  if (!config_.imu_topic.empty()) imu_sub_ = nh_.subscribe(config_.imu_topic, 200, &WebMapRos::onImu, this);
  timer_ = nh_.createWallTimer(ros::WallDuration(0.5), &WebMapRos::onTimer, this);
  // The cutter's warps and the server's threads free large buffers in several threads for hours: their pages go back
  // to the system (as the fusion and the tile writer do).
  free_heap_timer_ = nh_.createWallTimer(ros::WallDuration(10.0),
                                         [](const ros::WallTimerEvent&) { exocet_common::releaseFreeHeap(); });
  updater_.setHardwareID("web_map");
  updater_.add("web map", this, &WebMapRos::diagnose);
}

WebMapRos::~WebMapRos() {
  timer_.stop();
  if (server_) server_->stop();
  if (map_) {
    // The last tile's message may still be on its way when a replay's launch stops the node.
    map_->queueUnseenGeoTiffs();
    const auto stats = map_->stats();
    ROS_INFO("web map: cutting the %d GeoTIFF tiles still queued, writing the site", stats.queue_length);
    const std::string errors = map_->shutdown();
    if (!errors.empty()) ROS_ERROR("web map: at shutdown: %s", errors.c_str());
  }
}

std::string WebMapRos::url() const {
  const std::string& a = config_.server.bind_address;
  const std::string host = a == "0.0.0.0" ? "127.0.0.1" : (a.find(':') != std::string::npos ? "[" + a + "]" : a);
  return "http://" + host + ":" + std::to_string(server_ ? server_->port() : config_.server.port) + "/";
}

void WebMapRos::onTile(const exocet_msgs::TileConstPtr& msg) {
  ++tiles_received_;
  if (msg->geotiff_path.empty()) {
    ++rejected_;
    last_rejection_ = "tile " + std::to_string(msg->index) + " without a GeoTIFF path";
    ROS_WARN_THROTTLE(5.0, "web map: %s: ignored", last_rejection_.c_str());
    return;
  }
  map_->enqueueGeoTiff(msg->geotiff_path);
}

void WebMapRos::onDatum(const exocet_msgs::GeoDatumConstPtr& msg) {
  if (msg->utm_zone < 0 || msg->utm_zone > 60) {
    ++rejected_;
    last_rejection_ = "datum with UTM zone " + std::to_string(msg->utm_zone) + " (allowed 0..60)";
    ROS_WARN_THROTTLE(5.0, "web map: %s: ignored", last_rejection_.c_str());
    return;
  }
  grid_ = exocet_common::UtmGrid::fromZone(msg->utm_zone, msg->northern_hemisphere);
  datum_frame_ = msg->frame_id;
  map_->setDatum(msg->utm_zone, msg->northern_hemisphere, grid_->epsg());
  std::vector<nav_msgs::Odometry> waiting;
  waiting.swap(waiting_for_datum_);
  for (const auto& odometry : waiting) addPosition(odometry);
}

void WebMapRos::onOdometry(const nav_msgs::OdometryConstPtr& msg) {
  if (!grid_) {
    if (waiting_for_datum_.size() >= kMaxPositionsWaitingForDatum) waiting_for_datum_.erase(waiting_for_datum_.begin());
    waiting_for_datum_.push_back(*msg);
    ROS_WARN_THROTTLE(10.0, "web map: no datum on %s yet: the track waits for it (a dive in a local frame has none)",
                      config_.datum_topic.c_str());
    return;
  }
  addPosition(*msg);
}

void WebMapRos::addPosition(const nav_msgs::Odometry& msg) {
  const auto& p = msg.pose.pose.position;
  if (!datum_frame_.empty() && msg.header.frame_id != datum_frame_) {
    ++rejected_;
    last_rejection_ = "odometry in frame '" + msg.header.frame_id + "', the datum's is '" + datum_frame_ + "'";
    ROS_WARN_THROTTLE(5.0, "web map: %s: ignored", last_rejection_.c_str());
    return;
  }
  if (!std::isfinite(p.x) || !std::isfinite(p.y)) {
    ++rejected_;
    last_rejection_ = "odometry with a non-finite position";
    ROS_WARN_THROTTLE(5.0, "web map: %s: ignored", last_rejection_.c_str());
    return;
  }
  try {
    const Eigen::Vector2d lat_lon = grid_->toLatLon(p.x, p.y);
    double heading_deg = std::nan("");
    if (imu_yaw_rad_ && std::abs((msg.header.stamp - imu_stamp_).toSec()) <= config_.imu_max_age_s) {
      // ENU yaw in the grid -> clockwise from grid north -> from true north (convergence: grid north's bearing).
      const double grid_heading_deg = 90.0 - *imu_yaw_rad_ * kDegPerRad;
      heading_deg = std::fmod(grid_heading_deg + grid_->convergence_rad(p.x, p.y) * kDegPerRad + 720.0, 360.0);
    }
    map_->addVehiclePose(msg.header.stamp.toSec(), lat_lon.x(), lat_lon.y(), heading_deg);
    ++positions_;
  } catch (const std::exception& e) {
    ++rejected_;
    last_rejection_ = std::string("odometry outside the datum's zone: ") + e.what();
    ROS_WARN_THROTTLE(5.0, "web map: %s", last_rejection_.c_str());
  }
}

void WebMapRos::onUsbl(const sensor_msgs::NavSatFixConstPtr& msg) {
  if (!std::isfinite(msg->latitude) || !std::isfinite(msg->longitude) || msg->status.status < 0) {
    ++rejected_;
    last_rejection_ = "USBL fix without a position";
    ROS_WARN_THROTTLE(5.0, "web map: %s: ignored", last_rejection_.c_str());
    return;
  }
  const auto& c = msg->position_covariance;
  const double sigma_m = msg->position_covariance_type == sensor_msgs::NavSatFix::COVARIANCE_TYPE_UNKNOWN
                             ? std::nan("")
                             : std::sqrt(std::max(0.0, 0.5 * (c[0] + c[4])));
  map_->addUsblFix(msg->header.stamp.toSec(), msg->latitude, msg->longitude, sigma_m);
  ++fixes_;
}

void WebMapRos::onImu(const sensor_msgs::ImuConstPtr& msg) {
  const auto& q = msg->orientation;
  const double norm = std::sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w);
  if (!(norm > 0.5) || !std::isfinite(norm) || msg->orientation_covariance[0] < 0.0) return;  // no attitude
  const double x = q.x / norm, y = q.y / norm, z = q.z / norm, w = q.w / norm;
  imu_yaw_rad_ = std::atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z));
  imu_stamp_ = msg->header.stamp;
}

void WebMapRos::onTimer(const ros::WallTimerEvent&) {
  map_->flushVehicleEvents();
  if ((ros::WallTime::now() - last_folder_look_).toSec() >= kFolderLookPeriod_s) {
    last_folder_look_ = ros::WallTime::now();
    const int found = map_->queueUnseenGeoTiffs(kMessageGrace);
    if (found > 0) {
      tiles_found_without_message_ += found;
      ROS_INFO_THROTTLE(10.0,
                        "web map: %d GeoTIFF tiles of %s came without a tile message (written while this node "
                        "was down or not yet connected): queued",
                        found, config_.site.tiles_dir.c_str());
    }
  }
  // Wall time: a replay's sim clock may run fast, stop or go back.
  if ((ros::WallTime::now() - last_diagnostics_).toSec() >= 1.0) {
    last_diagnostics_ = ros::WallTime::now();
    updater_.force_update();
  }
}

void WebMapRos::diagnose(diagnostic_updater::DiagnosticStatusWrapper& status) {
  const site::WebMapStats s = map_->stats();
  const server::ServerStats w = server_->stats();
  if (s.errors > 0)
    status.summaryf(diagnostic_msgs::DiagnosticStatus::WARN, "%lu errors, last: %s", (unsigned long)s.errors,
                    s.last_error.c_str());
  else if (s.sources == 0)
    status.summary(diagnostic_msgs::DiagnosticStatus::OK, "serving, no GeoTIFF tile yet");
  else
    status.summaryf(diagnostic_msgs::DiagnosticStatus::OK, "serving %d GeoTIFF tiles as %d web tiles", s.sources,
                    s.web_tiles);
  status.add("url", url());
  status.add("site folder", config_.site.site_dir);
  status.add("clients connected", w.connections);
  status.add("live event streams", w.event_streams);
  status.add("requests", w.requests);
  status.add("requests refused busy (503)", w.busy);
  status.add("requests refused (400, 403, 405)", w.refused);
  status.add("requests not found (404)", w.not_found);
  status.add("tile messages received", tiles_received_);
  status.add("GeoTIFF tiles found without a message", tiles_found_without_message_);
  status.add("GeoTIFF tiles cut", s.geotiffs_cut);
  status.add("web tiles cut", s.web_tiles_written);
  status.add("web tiles on disk", s.web_tiles);
  status.add("zoom levels", std::to_string(s.min_zoom) + " to " + std::to_string(s.max_zoom));
  status.add("queue length", s.queue_length);
  status.addf("last cut latency (ms)", "%.0f", s.last_latency_ms);
  status.addf("max cut latency (ms)", "%.0f", s.max_latency_ms);
  status.addf("cut time per web tile (ms)", "%.1f", s.cut_ms_per_web_tile);
  status.add("track points", s.track_points);
  status.add("USBL fixes", s.usbl_fixes);
  status.add("positions waiting for a datum", waiting_for_datum_.size());
  status.add("errors", s.errors);
  status.add("last error", s.last_error);
  status.add("inputs rejected", rejected_);
  status.add("last rejection", last_rejection_);
}

}  // namespace exocet_web
