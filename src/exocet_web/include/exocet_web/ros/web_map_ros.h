/**
 * @file web_map_ros.h
 * @brief ROS layer of web_map_node: feeds the web map (site/web_map.h) the tile writer's tiles, the fused track, the
 * USBL fixes and the IMU heading, serves it (server/web_server.h) and reports on /diagnostics.
 */
#pragma once

#include <memory>
#include <optional>

#include <diagnostic_updater/diagnostic_updater.h>
#include <exocet_msgs/GeoDatum.h>
#include <exocet_msgs/Tile.h>
#include <nav_msgs/Odometry.h>
#include <ros/ros.h>
#include <sensor_msgs/Imu.h>
#include <sensor_msgs/NavSatFix.h>

#include "exocet_common/utm_grid.h"
#include "exocet_web/ros/web_map_parameters.h"
#include "exocet_web/server/web_server.h"
#include "exocet_web/site/web_map.h"

namespace exocet_web {

/**
 * Subscribes to ~tile_topic, ~odometry_topic, ~datum_topic, ~usbl_topic and ~imu_topic; the GeoTIFFs are cut in the
 * web map's worker thread, never in a callback. ~tiles_dir is also looked at every 2 s and at shutdown for GeoTIFFs
 * whose message was missed (written while the node was down or its subscription not yet connected: a respawn). The
 * fused positions (UTM easting/northing in the datum's frame) are converted to WGS 84 with the datum's zone
 * (exocet_common::UtmGrid, GeographicLib); positions that come before the datum wait for it (the last 10000). The
 * heading is the IMU's yaw (ENU in the utm grid, as the fusion reads it) turned to true north with the grid
 * convergence; without an IMU the page shows the course over ground.
 */
class WebMapRos {
 public:
  /// @throws std::invalid_argument for a bad parameter; std::runtime_error when the site cannot be written or the
  ///         server cannot listen
  WebMapRos(ros::NodeHandle nh, ros::NodeHandle private_nh);
  /// Stops the server, cuts what is queued, writes the state files and the MBTiles export.
  ~WebMapRos();
  WebMapRos(const WebMapRos&) = delete;
  WebMapRos& operator=(const WebMapRos&) = delete;

  /// "http://<address>:<port>/".
  std::string url() const;

 private:
  void onTile(const exocet_msgs::TileConstPtr& msg);
  void onOdometry(const nav_msgs::OdometryConstPtr& msg);
  void onDatum(const exocet_msgs::GeoDatumConstPtr& msg);
  void onUsbl(const sensor_msgs::NavSatFixConstPtr& msg);
  void onImu(const sensor_msgs::ImuConstPtr& msg);
  void onTimer(const ros::WallTimerEvent& event);
  void addPosition(const nav_msgs::Odometry& msg);
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& status);

  ros::NodeHandle nh_;
  ros::NodeHandle private_nh_;
  WebMapNodeConfig config_;
  std::unique_ptr<site::WebMap> map_;
  std::unique_ptr<server::WebServer> server_;
  diagnostic_updater::Updater updater_;
  ros::Subscriber tile_sub_, odometry_sub_, datum_sub_, usbl_sub_, imu_sub_;
  ros::WallTimer timer_;  ///< vehicle events held back, diagnostics every second, the tiles folder looked at
  ros::WallTimer free_heap_timer_;  ///< hands the heap's free pages back every 10 s
  ros::WallTime last_diagnostics_;
  ros::WallTime last_folder_look_;

  std::optional<exocet_common::UtmGrid> grid_;
  std::string datum_frame_;
  std::vector<nav_msgs::Odometry> waiting_for_datum_;
  std::optional<double> imu_yaw_rad_;  ///< ENU yaw of base_link, counter-clockwise from grid east
  ros::Time imu_stamp_;
  uint64_t tiles_received_ = 0, positions_ = 0, fixes_ = 0, rejected_ = 0;
  uint64_t tiles_found_without_message_ = 0;
  std::string last_rejection_;
};

}  // namespace exocet_web
