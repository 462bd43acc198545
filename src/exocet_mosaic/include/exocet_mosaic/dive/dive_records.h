/**
 * @file dive_records.h
 * @brief Plain records of a dive (camera frames, navigation, ground truth), with no ROS in them.
 *
 * The simulator and the importer produce these; the ROS bridge (ros/dive_bag_writer.h) writes them into a bag.
 * Frames: positions are in the dive's metric world frame (UTM easting, northing, up: metres); orientations are
 * body-to-world rotations in that frame (ENU, REP-103); body frame base_link is x forward, y left, z up.
 * Times are seconds since the Unix epoch (double).
 */
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "exocet_common/geo_reference.h"

namespace exocet_mosaic {
namespace dive {

/// One camera image. `image` is 8-bit BGR (CV_8UC3), 8-bit gray (CV_8UC1) or 16-bit gray (CV_16UC1).
struct CameraFrame {
  double stamp_s = 0.0;  ///< mid-exposure time
  int index = 0;         ///< frame number in the dive, from 0
  cv::Mat image;
  std::string encoding;  ///< sensor_msgs encoding of `image` once written: bgr8, rgb8, mono8, mono16, bayer_rggb8
  /// `image` already compressed for storage (e.g. JPEG bytes, on the thread that rendered it), with its
  /// sensor_msgs/CompressedImage format string; empty when not compressed ahead.
  std::vector<uint8_t> compressed;
  std::string compressed_format;
};

/// A pose with velocities and covariance: ground truth or dead-reckoning navigation of base_link.
struct PoseRecord {
  double stamp_s = 0.0;
  Eigen::Vector3d position_m = Eigen::Vector3d::Zero();  ///< world frame (UTM E, N, up)
  Eigen::Quaterniond orientation = Eigen::Quaterniond::Identity();  ///< body to world
  Eigen::Vector3d linear_velocity_mps = Eigen::Vector3d::Zero();   ///< in the body frame
  Eigen::Vector3d angular_velocity_rps = Eigen::Vector3d::Zero();  ///< in the body frame
  Eigen::Matrix<double, 6, 6> pose_covariance = Eigen::Matrix<double, 6, 6>::Zero();  ///< x y z roll pitch yaw
  Eigen::Matrix<double, 6, 6> twist_covariance = Eigen::Matrix<double, 6, 6>::Zero();
};

/// Inertial/attitude measurement (sensor_msgs/Imu semantics: orientation body-to-world, rates and specific force
/// in the body frame, gravity included: +9.81 m/s^2 on z at rest).
struct ImuRecord {
  double stamp_s = 0.0;
  Eigen::Quaterniond orientation = Eigen::Quaterniond::Identity();
  Eigen::Vector3d angular_velocity_rps = Eigen::Vector3d::Zero();
  Eigen::Vector3d linear_acceleration_mps2 = Eigen::Vector3d::Zero();
  double orientation_sigma_rad = 0.0;  ///< 1-sigma of each attitude angle (roll, pitch, yaw)
  double angular_velocity_sigma_rps = 0.0;
  double linear_acceleration_sigma_mps2 = 0.0;
};

/// Velocity over the seabed from a Doppler velocity log, in the body frame.
struct DvlRecord {
  double stamp_s = 0.0;
  Eigen::Vector3d velocity_mps = Eigen::Vector3d::Zero();
  double sigma_mps = 0.0;
};

/// Depth below the surface from the pressure sensor.
struct DepthRecord {
  double stamp_s = 0.0;
  double depth_m = 0.0;  ///< positive down
  double sigma_m = 0.0;
};

/// Altimeter range to the seabed along the body's -z axis (sensor_msgs/Range semantics).
struct AltitudeRecord {
  double stamp_s = 0.0;
  double range_m = 0.0;
  double sigma_m = 0.0;
  double min_range_m = 0.1;
  double max_range_m = 50.0;
  double field_of_view_rad = 0.05;
};

/// Absolute position fix (USBL), WGS 84. `stamp_s` is the measurement time, `arrival_s` when it reached the
/// surface computer (stamp + latency): the bag records it at arrival, so the fusion sees it late, as at sea.
struct FixRecord {
  double stamp_s = 0.0;
  double arrival_s = 0.0;
  double latitude_deg = 0.0;
  double longitude_deg = 0.0;
  double altitude_m = 0.0;  ///< height above the WGS 84 ellipsoid (approximately minus depth)
  double horizontal_sigma_m = 0.0;
  double vertical_sigma_m = 0.0;
};

/// Rigid transform between two frames (e.g. base_link -> camera_optical): child pose in the parent frame.
struct StaticTransform {
  std::string parent_frame;
  std::string child_frame;
  Eigen::Isometry3d parent_from_child = Eigen::Isometry3d::Identity();
};

}  // namespace dive
}  // namespace exocet_mosaic
