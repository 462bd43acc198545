/**
 * @file fusion_parameters.h
 * @brief The fusion node's private parameters, read and checked with their allowed ranges.
 */
#pragma once

#include <string>
#include <vector>

#include <ros/ros.h>

#include "exocet_mosaic/fusion/navigation_filter.h"
#include "exocet_mosaic/ros/dive_topics.h"

namespace exocet_mosaic {

/// Settings of the fusion node; each is the private parameter of the same name.
struct FusionNodeConfig {
  fusion::FilterConfig filter;  ///< ~filter/...: noise, gating, history (see navigation_filter.h)

  // Inputs. An empty topic disables that input.
  std::string motion_topic = topics::kMosaicMotion;     ///< exocet_msgs/ImageMotion
  std::string odometry_topic = topics::kNavOdometry;    ///< nav_msgs/Odometry, dead reckoning in the UTM grid
  std::string nav_fix_topic;                            ///< sensor_msgs/NavSatFix, dead reckoning in lat/lon
  std::string usbl_topic = topics::kNavUsbl;            ///< sensor_msgs/NavSatFix, absolute fixes (late)
  std::string imu_topic = topics::kNavImu;              ///< sensor_msgs/Imu: attitude, ENU
  std::string altitude_topic = topics::kNavAltitude;    ///< sensor_msgs/Range: altimeter
  std::string depth_topic = topics::kNavDepth;          ///< exocet_msgs/Depth: depth of base_link (~seabed_depth_m)
  std::string camera_info_topic = topics::kCameraInfo;  ///< K when a motion message carries none
  std::string datum_topic = topics::kNavDatum;          ///< exocet_msgs/GeoDatum: the dive's UTM zone

  // Frames.
  std::string utm_frame = frames::kUtm;               ///< frame of the odometry output and UTM inputs
  std::string map_frame = frames::kMap;               ///< local frame for rviz (utm -> map is a fixed offset)
  std::string base_frame = frames::kBaseLink;         ///< the vehicle body
  std::string camera_frame = frames::kCameraOptical;  ///< the camera, when a motion message names no frame
  std::string fused_camera_frame = "camera_fused";    ///< child frame of the published odometry and tf
  bool publish_tf = true;                             ///< map -> fused_camera_frame, and utm -> map (static)
  double map_origin_grid_m = 100.0;                   ///< the map origin is the first position rounded to this (m)

  // Geography: the UTM zone, when neither /nav/datum nor a latitude/longitude gives it. 0 = not given.
  int utm_zone = 0;  ///< [0, 60]; 0: not given
  bool northern_hemisphere = true;

  // Navigation inputs.
  double fix_sigma_m = 2.0;             ///< 1-sigma used when a fix carries no covariance (0, 1000] m
  double dead_reckoning_sigma_m = 0.5;  ///< 1-sigma used when the dead reckoning carries no covariance (0, 1000] m
  double reorder_delay_s = 0.3;         ///< inputs are put in stamp order over this delay [0, 10] s
  /// Wall seconds [0, 60] (the tile writer waits as long for its frames) the inputs wait for the registration's motion
  /// of an image announced by its camera_info (0: no wait). Replays faster than real time delay the motions by more
  /// than reorder_delay_s of sim time.
  double motion_wait_s = 10.0;
  double clock_jump_s = 10.0;       ///< a stamp older than the newest by more than this resets everything (0, 1e6]
  double attitude_max_gap_s = 0.5;  ///< attitude samples further apart are not interpolated (0, 60]
  double altitude_max_gap_s = 2.0;  ///< altimeter samples further apart are not interpolated (0, 600]
  /// Roll, pitch and altimeter range fitted over +-this window at each image's stamp (their white noise averaged);
  /// 0: interpolated. Set ~reorder_delay_s at least as long, so that the window's samples have arrived [0, 10] s.
  double view_half_window_s = 0.0;
  double altimeter_sigma_m = 0.0;  ///< one altimeter range's 1-sigma (datasheet), 0 = taken as exact [0, 10] m

  // No navigation: the operator's first point (NaN = not given); also settable through ~set_initial_pose.
  double initial_latitude_deg = NAN, initial_longitude_deg = NAN;
  double initial_easting_m = NAN, initial_northing_m = NAN;
  double initial_heading_deg = NAN;  ///< grid heading, clockwise from north [0, 360)
  double initial_altitude_m = NAN;   ///< camera height above the seabed (0, 1000] m
  /// Depth of the seabed (m): without an altimeter, camera height = this - the camera's depth (/nav/depth), a flat
  /// seabed assumed; NaN: not used; (0, 12000] m.
  double seabed_depth_m = NAN;
  double initial_sigma_m = 1.0;  ///< (0, 10000] m

  // Outputs.
  std::string odometry_out_topic = "/mosaic/odometry";
  std::string path_topic = "/mosaic/path";                        ///< fused track
  std::string navigation_path_topic = "/mosaic/path_navigation";  ///< dead reckoning as received
  std::string image_path_topic = "/mosaic/path_image";            ///< image motion alone from the first position
  std::string smoothed_path_topic = "/mosaic/path_smoothed";      ///< RTS smoother, on ~smooth
  /// Run the key frames' pose graph beside the filter (exocet_mosaic_graph: image odometry between key frames, the
  /// fixes at their stamps, headings; solved in a worker thread) and publish its key frames on graph_path_topic.
  bool pose_graph = false;
  std::string graph_path_topic = "/mosaic/path_graph";
  /// With pose_graph: each published state again, moved by the graph's correction at the latest solved key frame
  /// (graph pose - the filter's position there), for a tile writer that follows the graph.
  std::string graph_odometry_topic = "/mosaic/odometry_graph";
  /// With pose_graph: exocet_msgs/PositionCorrections after each solve (graph pose - the filter's position at every
  /// key frame), for a tile writer that draws its tiles again where the graph moved their images.
  std::string graph_corrections_topic = "/mosaic/graph_corrections";
  /// With pose_graph: the share of the graph worker's time spent on the key frames' position marginals (the 1-sigma
  /// sent with the corrections), [0, 1]; 0: none computed (graph::BackgroundPoseGraphConfig::marginals_duty_cycle).
  double graph_marginals_duty_cycle = 0.1;
  /// With pose_graph: look for loops live (graph::LoopCloser: the key frames' images from loop_image_topic, the
  /// candidates whose footprints may overlap, verified by registration, added to the graph in a worker thread).
  bool loop_closure = false;
  std::string loop_image_topic = "/camera/image_raw/compressed";  ///< sensor_msgs/CompressedImage
  /// With loop_closure: the folder of the key frames' images beyond the few kept in memory (graph::KeyFrameImageStore;
  /// emptied of an earlier run's at start); empty: all in memory, which grows with the dive. Default
  /// defaultLoopImageFolder() for the node.
  std::string loop_image_folder;
  /// With loop_closure: the compressed images of the last seconds kept for the key frames to come (the feeder makes a
  /// key frame when the image's motion arrives), at most 10 s, 250 images and this many MB, [1, 4096]: a 4K camera's
  /// JPEGs (about 1.3 MB each) would otherwise hold 330 MB.
  double loop_image_buffer_mb = 64.0;
  /// sensor_msgs/Range at each published state: the camera's height above the seabed (for the tile writer).
  std::string camera_height_topic = "/mosaic/camera_height";
  std::string datum_out_topic = "/mosaic/datum";  ///< exocet_msgs/GeoDatum, latched: the UTM zone of the outputs
  double path_rate_hz = 1.0;                      ///< paths are republished at this rate (0, 100]
  /// Poses of a path closer than this to the one before are not kept (the newest replaces the path's last) [0, 100]
  double path_min_spacing_m = 0.05;
  /// Beyond, every other pose of a path is dropped and its spacing doubles (bounded memory) [100, 1e7]
  int max_path_poses = 5000;
  bool keep_smoother_log = true;  ///< keep the whole dive for the RTS smoother and the track files
  /// With keep_smoother_log: the file the filter's older steps are written to as the dive goes (about 1.7 kB a
  /// step), so that the node's memory does not grow with the dive; empty: held in memory. Default
  /// defaultSmootherLogFile() for the node.
  std::string smoother_log_file;
  std::string track_csv;                   ///< written at shutdown: the filtered track (empty: not written)
  std::string smoothed_track_csv;          ///< written at shutdown: the RTS-smoothed track (empty: not written)
  double max_position_sigma_m = 10.0;      ///< /diagnostics warns above this 1-sigma (0, 1e6] m
  double max_navigation_silence_s = 10.0;  ///< /diagnostics warns when no navigation arrived for this long (0, 1e6]

  // Restart mid-dive.
  /// The last published state, kept on disk (atomically, at most every state_save_period_s) for a restarted fusion
  /// to resume from; empty: none. Default defaultFusionStateFile() for the node.
  std::string state_file;
  double state_max_age_s = 30.0;     ///< the saved state starts the filter when the first input is at most this much
                                     ///< later (s, (0, 3600]); see fusion::resumeRefusal
  double state_save_period_s = 1.0;  ///< wall seconds between two saves of the state (0, 60]
};

/// $ROS_HOME/exocet_fusion_state_<node>.json (~/.ros when ROS_HOME is unset), <node> the private namespace with its
/// slashes as underscores: two fusions on one machine keep their own.
std::string defaultFusionStateFile(const std::string& private_namespace);
/// $ROS_HOME/exocet_loop_images_<node>_pid<pid>/ (~/.ros when ROS_HOME is unset), <node> as in
/// defaultFusionStateFile: this process's own scratch folder.
std::string defaultLoopImageFolder(const std::string& private_namespace);
/// $ROS_HOME/exocet_fusion_steps_<node>_pid<pid>.bin, as defaultLoopImageFolder: this process's own scratch file.
std::string defaultSmootherLogFile(const std::string& private_namespace);
/// Removes the default scratch files and folders of the node's earlier processes that are gone (a SIGKILL leaves
/// them); returns their paths.
std::vector<std::string> removeStaleFusionScratch(const std::string& private_namespace);

/// @throws std::invalid_argument naming the parameter, its value and the allowed range.
FusionNodeConfig readFusionNodeConfig(const ros::NodeHandle& private_nh);

}  // namespace exocet_mosaic
