/**
 * @file reconstruction_ros.h
 * @brief ROS bridge of the offline reconstruction (mesh/acquisition_reconstruction.h): on `~reconstruct`
 * (std_srvs/Trigger) it reads the acquisition bag `~bag` (exocet_servo's acquisition_sequencer_node), reconstructs it
 * in a worker thread and writes the files into `~output_dir`; it reports progress and shows the result in rviz.
 *
 * Out: `~progress` (std_msgs/String, latched: "pair k of N", ..., "done: ..." or "failed: ..."), `~cloud`
 * (sensor_msgs/PointCloud2 x y z rgb, latched), `~surface` (visualization_msgs/Marker TRIANGLE_LIST, latched), both
 * in `~frame_id` (the frame of the bag's poses, default "arm_base"), and /diagnostics.
 * Parameters: `~bag`, `~output_dir`, `~method` (sgm), `~min_depth_m` (0.4), `~max_depth_m` (1.0), `~voxel_m` (0.002),
 * `~min_confirmations` (1), `~frame_id`.
 */
#pragma once

#include <atomic>
#include <mutex>
#include <string>
#include <thread>

#include <diagnostic_updater/diagnostic_updater.h>
#include <ros/ros.h>
#include <std_srvs/Trigger.h>

#include "exocet_stereo/mesh/acquisition_reconstruction.h"

namespace exocet_stereo {

class ReconstructionRos {
 public:
  /// @throws std::invalid_argument for a bad parameter.
  ReconstructionRos(ros::NodeHandle nh, ros::NodeHandle private_nh);
  ~ReconstructionRos();

 private:
  bool onReconstruct(std_srvs::Trigger::Request& req, std_srvs::Trigger::Response& res);
  void work(std::string bag, std::string output_dir, mesh::AcquisitionReconstructionConfig config);
  void setProgress(const std::string& text);
  void publishResult(const mesh::AcquisitionReconstruction& result);
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& status);

  ros::NodeHandle nh_, pnh_;
  std::string frame_id_ = "arm_base";
  ros::Publisher progress_pub_, cloud_pub_, surface_pub_;
  ros::ServiceServer reconstruct_srv_;
  diagnostic_updater::Updater diagnostics_;
  ros::Timer diagnostics_timer_;
  std::thread worker_;
  std::atomic<bool> busy_{false};
  std::mutex mutex_;
  std::string progress_ = "idle";
  bool failed_ = false;
};

}  // namespace exocet_stereo
