#include "exocet_mosaic/ros/fusion_parameters.h"

#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <stdexcept>
#include <vector>

#include "exocet_common/ros/parameter_reader.h"

namespace exocet_mosaic {

namespace {

/// ~filter/...: the Kalman filter's noise, gating and history (fusion/navigation_filter.h documents each).
void readFilterConfig(const ros::NodeHandle& filter_nh, fusion::FilterConfig* f) {
  const exocet_common::ParameterReader p(filter_nh);
  p.readDouble("position_noise_m2_per_s", &f->position_noise_m2_per_s, 0.0, 100.0,
               "position random walk with image motion (m^2/s)");
  p.readDouble("image_step_noise_along_m", &f->image_step_noise_along_m, 0.0, 10.0,
               "extra 1-sigma per image step along its motion (m)");
  p.readDouble("image_step_noise_across_m", &f->image_step_noise_across_m, 0.0, 10.0,
               "extra 1-sigma per image step across its motion (m)");
  p.readPositiveDouble("no_motion_position_noise_m2_per_s", &f->no_motion_position_noise_m2_per_s, 1e4,
                       "position random walk where no image motion covers the time (m^2/s)");
  p.readDouble("no_motion_speed_mps", &f->no_motion_speed_mps, 0.0, 20.0,
               "assumed speed for the dead-reckoning offset growth without image motion (m/s)");
  p.readDouble("initial_pixel_size_correction_sigma", &f->initial_pixel_size_correction_sigma, 0.0, 0.49,
               "1-sigma of the pixel-size correction at the start (relative)");
  p.readDouble("pixel_size_correction_noise_per_sqrt_s", &f->pixel_size_correction_noise_per_sqrt_s, 0.0, 1.0,
               "random walk of the pixel-size correction (1/sqrt(s))");
  p.readDouble("initial_heading_sigma_rad", &f->initial_heading_sigma_rad, 0.0, 0.5,
               "1-sigma of the attitude's heading error at the start (rad; the filter linearises in it)");
  p.readDouble("initial_heading_drift_sigma_rps", &f->initial_heading_drift_sigma_rps, 0.0, 1.0,
               "1-sigma of the gyro bias at the start (rad/s)");
  p.readDouble("heading_noise_rad_per_sqrt_s", &f->heading_noise_rad_per_sqrt_s, 0.0, 1.0,
               "heading angle random walk (rad/sqrt(s))");
  p.readDouble("heading_drift_noise_rps_per_sqrt_s", &f->heading_drift_noise_rps_per_sqrt_s, 0.0, 1.0,
               "gyro bias instability (rad/s/sqrt(s))");
  p.readPositiveDouble("dr_measurement_sigma_m", &f->dr_measurement_sigma_m, 100.0,
                       "white noise of one dead-reckoning position (m)");
  p.readDouble("dr_offset_noise_m2_per_m", &f->dr_offset_noise_m2_per_m, 0.0, 100.0,
               "dead-reckoning offset random walk per metre travelled (m^2/m)");
  p.readDouble("dr_offset_noise_m2_per_s", &f->dr_offset_noise_m2_per_s, 0.0, 100.0,
               "dead-reckoning offset random walk per second (m^2/s)");
  p.readDouble("initial_dr_scale_sigma", &f->initial_dr_scale_sigma, 0.0, 0.49,
               "1-sigma of the dead reckoning's velocity scale error at the start (relative)");
  p.readDouble("dr_scale_noise_per_sqrt_s", &f->dr_scale_noise_per_sqrt_s, 0.0, 1.0,
               "random walk of the dead reckoning's velocity scale error (1/sqrt(s))");
  p.readBool("dr_shares_heading", &f->dr_shares_heading,
             "the dead reckoning's heading comes from the gyro that gives the images' attitude");
  double gate = f->gate_probability;
  p.readDouble("gate_probability", &gate, 0.5, 0.999999999, "probability of the chi-square gate on fixes and DR");
  f->gate_probability = gate;
  p.readInt("recovery_rejections", &f->recovery_rejections, 1, 1000,
            "consecutive rejections of one source after which the filter recovers");
  p.readPositiveDouble("history_s", &f->history_s, 3600.0, "history kept for late fixes (s)");
  p.readPositiveDouble("max_prediction_gap_s", &f->max_prediction_gap_s, 1e6,
                       "largest forward jump between two inputs before it counts as a clock jump (s)");
  const std::string problems = f->validate();
  if (!problems.empty()) throw std::invalid_argument("parameters ~filter/...: " + problems);
}

/// `name` (from "/") in $ROS_HOME, or ~/.ros when ROS_HOME is unset.
std::string inRosHome(const std::string& name) {
  const char* ros_home = std::getenv("ROS_HOME");
  if (ros_home != nullptr && *ros_home != '\0') return std::string(ros_home) + name;
  const char* home = std::getenv("HOME");
  return std::string(home != nullptr ? home : ".") + "/.ros" + name;
}

std::string nodeSuffix(const std::string& private_namespace) {
  std::string node = private_namespace;
  std::replace(node.begin(), node.end(), '/', '_');
  return node;
}

}  // namespace

std::string defaultFusionStateFile(const std::string& private_namespace) {
  return inRosHome("/exocet_fusion_state" + nodeSuffix(private_namespace) + ".json");
}

// The scratch files are the process's own (two masters on one machine may each run a /fusion, as parallel rostests
// do): named with the pid, and those of processes that are gone removed at start.
std::string defaultLoopImageFolder(const std::string& private_namespace) {
  return inRosHome("/exocet_loop_images" + nodeSuffix(private_namespace) + "_pid" + std::to_string(::getpid()));
}

std::string defaultSmootherLogFile(const std::string& private_namespace) {
  return inRosHome("/exocet_fusion_steps" + nodeSuffix(private_namespace) + "_pid" + std::to_string(::getpid()) +
                   ".bin");
}

std::vector<std::string> removeStaleFusionScratch(const std::string& private_namespace) {
  namespace fs = std::filesystem;
  const fs::path folder = fs::path(inRosHome("/")).parent_path();
  const std::string node = nodeSuffix(private_namespace);
  std::vector<std::string> removed;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(folder, ec)) {
    const std::string name = entry.path().filename().string();
    for (const std::string& prefix : {"exocet_loop_images" + node + "_pid", "exocet_fusion_steps" + node + "_pid"}) {
      if (name.compare(0, prefix.size(), prefix) != 0) continue;
      char* end = nullptr;
      const long pid = std::strtol(name.c_str() + prefix.size(), &end, 10);
      if (end == name.c_str() + prefix.size() || pid <= 0 || pid == ::getpid()) continue;
      if (::kill(static_cast<pid_t>(pid), 0) == 0 || errno != ESRCH) continue;  // alive (or not ours to ask)
      std::error_code remove_error;
      fs::remove_all(entry.path(), remove_error);
      if (!remove_error) removed.push_back(entry.path().string());
    }
  }
  return removed;
}

FusionNodeConfig readFusionNodeConfig(const ros::NodeHandle& private_nh) {
  FusionNodeConfig c;
  c.state_file = defaultFusionStateFile(private_nh.getNamespace());
  c.loop_image_folder = defaultLoopImageFolder(private_nh.getNamespace());
  c.smoother_log_file = defaultSmootherLogFile(private_nh.getNamespace());
  const exocet_common::ParameterReader params(private_nh);
  readFilterConfig(ros::NodeHandle(private_nh, "filter"), &c.filter);

  for (auto [name, topic] :
       {std::make_pair("motion_topic", &c.motion_topic), std::make_pair("odometry_topic", &c.odometry_topic),
        std::make_pair("nav_fix_topic", &c.nav_fix_topic), std::make_pair("usbl_topic", &c.usbl_topic),
        std::make_pair("imu_topic", &c.imu_topic), std::make_pair("altitude_topic", &c.altitude_topic),
        std::make_pair("depth_topic", &c.depth_topic), std::make_pair("camera_info_topic", &c.camera_info_topic),
        std::make_pair("datum_topic", &c.datum_topic)}) {
    params.readOptionalTopic(name, topic);  // "" turns an input off
  }
  for (auto [name, topic] :
       {std::make_pair("odometry_out_topic", &c.odometry_out_topic), std::make_pair("path_topic", &c.path_topic),
        std::make_pair("navigation_path_topic", &c.navigation_path_topic),
        std::make_pair("image_path_topic", &c.image_path_topic),
        std::make_pair("smoothed_path_topic", &c.smoothed_path_topic),
        std::make_pair("graph_path_topic", &c.graph_path_topic),
        std::make_pair("graph_odometry_topic", &c.graph_odometry_topic),
        std::make_pair("graph_corrections_topic", &c.graph_corrections_topic),
        std::make_pair("loop_image_topic", &c.loop_image_topic),
        std::make_pair("camera_height_topic", &c.camera_height_topic),
        std::make_pair("datum_out_topic", &c.datum_out_topic)}) {
    params.readTopic(name, topic);
  }
  if (!c.odometry_topic.empty() && !c.nav_fix_topic.empty())
    throw std::invalid_argument(
        "parameters ~odometry_topic and ~nav_fix_topic are both set: give the dead reckoning in UTM (odometry) or in "
        "latitude/longitude (nav_fix), not both (set the other to \"\")");

  for (auto [name, frame] :
       {std::make_pair("utm_frame", &c.utm_frame), std::make_pair("map_frame", &c.map_frame),
        std::make_pair("base_frame", &c.base_frame), std::make_pair("camera_frame", &c.camera_frame),
        std::make_pair("fused_camera_frame", &c.fused_camera_frame)})
    params.readString(name, frame, {}, "tf frame name");
  params.readBool("publish_tf", &c.publish_tf, "publish map -> fused camera frame and utm -> map on tf");
  params.readPositiveDouble("map_origin_grid_m", &c.map_origin_grid_m, 1e6,
                            "the map frame's origin is the first position rounded to this many metres");

  params.readInt("utm_zone", &c.utm_zone, 0, 60, "UTM zone of the UTM inputs when no datum gives it, 0 = not given");
  params.readBool("northern_hemisphere", &c.northern_hemisphere, "hemisphere of ~utm_zone");

  params.readPositiveDouble("fix_sigma_m", &c.fix_sigma_m, 1000.0, "1-sigma of a fix that carries no covariance (m)");
  params.readPositiveDouble("dead_reckoning_sigma_m", &c.dead_reckoning_sigma_m, 1000.0,
                            "1-sigma of a dead reckoning that carries no covariance (m)");
  params.readDouble("reorder_delay_s", &c.reorder_delay_s, 0.0, 10.0,
                    "inputs are put in stamp order over this delay (s)");
  params.readDouble("motion_wait_s", &c.motion_wait_s, 0.0, 60.0,
                    "wall seconds the inputs wait for the image motion of an image seen on camera_info, 0: none");
  params.readPositiveDouble("clock_jump_s", &c.clock_jump_s, 1e6,
                            "a stamp older than the newest by more than this resets the filter (s)");
  params.readPositiveDouble("attitude_max_gap_s", &c.attitude_max_gap_s, 60.0,
                            "attitude samples further apart are not interpolated (s)");
  params.readPositiveDouble("altitude_max_gap_s", &c.altitude_max_gap_s, 600.0,
                            "altimeter samples further apart are not interpolated (s)");
  params.readDouble("view_half_window_s", &c.view_half_window_s, 0.0, 10.0,
                    "roll, pitch and altimeter range are fitted over +-this many seconds at each image, 0: "
                    "interpolated");
  params.readDouble("altimeter_sigma_m", &c.altimeter_sigma_m, 0.0, 10.0,
                    "1-sigma of one altimeter range (m), 0 = taken as exact");

  params.readDouble("initial_latitude_deg", &c.initial_latitude_deg, -90.0, 90.0,
                    "first position's WGS 84 latitude (degrees), unset for none");
  params.readDouble("initial_longitude_deg", &c.initial_longitude_deg, -180.0, 360.0,
                    "first position's WGS 84 longitude (degrees), unset for none");
  params.readDouble("initial_easting_m", &c.initial_easting_m, -1e7, 1e7,
                    "first position's UTM easting (m), unset for none");
  params.readDouble("initial_northing_m", &c.initial_northing_m, -1e7, 2e7,
                    "first position's UTM northing (m), unset for none");
  params.readDouble("initial_heading_deg", &c.initial_heading_deg, -360.0, 360.0,
                    "first heading, clockwise from grid north (degrees), unset for the IMU's");
  params.readDouble("initial_altitude_m", &c.initial_altitude_m, 1e-3, 1000.0,
                    "camera height above the seabed without an altimeter (m), unset for none");
  params.readDouble("seabed_depth_m", &c.seabed_depth_m, 1e-3, 12000.0,
                    "depth of the seabed (m): without an altimeter the camera height is this minus the camera's depth "
                    "(/nav/depth), unset for none");
  params.readPositiveDouble("initial_sigma_m", &c.initial_sigma_m, 10000.0, "1-sigma of the first position (m)");
  if (std::isfinite(c.initial_latitude_deg) != std::isfinite(c.initial_longitude_deg))
    throw std::invalid_argument("parameters ~initial_latitude_deg and ~initial_longitude_deg go together");
  if (std::isfinite(c.initial_easting_m) != std::isfinite(c.initial_northing_m))
    throw std::invalid_argument("parameters ~initial_easting_m and ~initial_northing_m go together");
  if (std::isfinite(c.initial_easting_m) && c.utm_zone == 0)
    ROS_WARN(
        "fusion: ~initial_easting_m/northing_m given without ~utm_zone: the zone will come from /nav/datum or "
        "the first latitude/longitude");

  params.readPositiveDouble("path_rate_hz", &c.path_rate_hz, 100.0, "rate at which the paths are republished (Hz)");
  params.readDouble("path_min_spacing_m", &c.path_min_spacing_m, 0.0, 100.0,
                    "spacing of the poses kept in the fused, navigation and image paths (m)");
  params.readInt("max_path_poses", &c.max_path_poses, 100, 10000000,
                 "poses per path; beyond, every other one is dropped and the spacing doubles");
  params.readBool("pose_graph", &c.pose_graph,
                  "run the key frames' pose graph beside the filter and publish it on ~graph_path_topic");
  params.readBool("loop_closure", &c.loop_closure,
                  "with ~pose_graph: find, verify and add loops live from the key frames' images (~loop_image_topic)");
  if (c.loop_closure && !c.pose_graph)
    throw std::invalid_argument("parameter ~loop_closure is true but ~pose_graph is false: loops need the pose graph");
  params.readDouble("graph_marginals_duty_cycle", &c.graph_marginals_duty_cycle, 0.0, 1.0,
                    "with ~pose_graph: share of the graph worker's time spent on the key frames' 1-sigma (0: none)");
  params.readOptionalString(
      "loop_image_folder", &c.loop_image_folder,
      "folder of the loop closer's key-frame images beyond the few in memory; empty: all in memory");
  params.readDouble("loop_image_buffer_mb", &c.loop_image_buffer_mb, 1.0, 4096.0,
                    "recent compressed images kept for the loop closer's key frames (MB)");
  params.readBool("keep_smoother_log", &c.keep_smoother_log,
                  "keep the whole dive for the RTS smoother and the track files");
  params.readOptionalString("smoother_log_file", &c.smoother_log_file,
                            "file the filter's older steps are written to (bounded memory); empty: held in memory");
  params.readOptionalString("track_csv", &c.track_csv, "file for the filtered track at shutdown, empty for none");
  params.readOptionalString("smoothed_track_csv", &c.smoothed_track_csv,
                            "file for the RTS-smoothed track at shutdown, empty for none");
  params.readPositiveDouble("max_position_sigma_m", &c.max_position_sigma_m, 1e6,
                            "/diagnostics warns above this position 1-sigma (m)");
  params.readPositiveDouble("max_navigation_silence_s", &c.max_navigation_silence_s, 1e6,
                            "/diagnostics warns when no navigation arrived for this long (s)");
  params.readOptionalString("state_file", &c.state_file,
                            "file of the last published state, for a restarted fusion to resume from; empty for none");
  params.readPositiveDouble("state_max_age_s", &c.state_max_age_s, 3600.0,
                            "a saved state starts the filter when the first input is at most this much later (s)");
  params.readPositiveDouble("state_save_period_s", &c.state_save_period_s, 60.0,
                            "wall seconds between two saves of the state");
  return c;
}

}  // namespace exocet_mosaic
