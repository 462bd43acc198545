/**
 * @file web_map_parameters.h
 * @brief Parameters of web_map_node, read from its private namespace, each checked against its allowed range
 * (README.md lists them).
 */
#pragma once

#include <string>

#include <ros/node_handle.h>

#include "exocet_web/server/web_server.h"
#include "exocet_web/site/web_map.h"

namespace exocet_web {

struct WebMapNodeConfig {
  site::WebMapConfig site;      ///< tiles_dir required; site_dir default <tiles_dir>/web
  server::ServerConfig server;  ///< bind_address default 127.0.0.1 (loopback), port 8080
  // Inputs ("" turns the optional ones off).
  std::string tile_topic = "/mosaic/tile";          ///< exocet_msgs/Tile: the tile writer's (~tile_topic)
  std::string odometry_topic = "/mosaic/odometry";  ///< nav_msgs/Odometry: the fusion's (~odometry_out_topic)
  std::string datum_topic = "/mosaic/datum";        ///< exocet_msgs/GeoDatum: the fusion's (~datum_out_topic)
  std::string usbl_topic = "/nav/usbl";             ///< sensor_msgs/NavSatFix; optional
  std::string imu_topic = "/nav/imu";               ///< sensor_msgs/Imu (ENU, the utm grid): the heading; optional
  double imu_max_age_s = 2.0;  ///< an older IMU attitude is not the vehicle's heading any more, (0, 3600] s
};

/// @throws std::invalid_argument naming the parameter, its value and its allowed range.
WebMapNodeConfig readWebMapNodeConfig(const ros::NodeHandle& private_nh);

}  // namespace exocet_web
