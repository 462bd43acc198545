// reconstruct_acquisition: the offline reconstruction of an acquisition (2D4 report, section 3, carried on to every
// pair and a dense surface). Reads the bag written by exocet_servo's acquisition_sequencer_node (at each stop:
// left/right image_raw, camera_info and pose), turns each stereo pair into a depth map (rectification, dense stereo
// over a depth range), fuses the depth maps of all pairs into one cloud, builds its surface and writes
// fused_cloud.ply, surface.ply, surface.obj and surface.wrl into the output folder. Progress on stdout.
#include <chrono>
#include <filesystem>
#include <iostream>
#include <map>
#include <string>
#include <vector>

#include <cv_bridge/cv_bridge.h>
#include <geometry_msgs/PoseStamped.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/image_encodings.h>

#include "exocet_stereo/io/mesh_export.h"
#include "exocet_stereo/mesh/cloud_fusion.h"
#include "exocet_stereo/mesh/cloud_surface.h"
#include "exocet_stereo/mesh/pair_depth.h"

namespace {

using namespace exocet_stereo;
using Clock = std::chrono::steady_clock;

int usage(const std::string& error) {
  if (!error.empty()) std::cerr << "reconstruct_acquisition: " << error << "\n";
  std::cerr << "usage: reconstruct_acquisition --bag ACQUISITION.bag --output-dir DIR [--method sgm] "
               "[--min-depth-m 0.4] [--max-depth-m 1.0] [--voxel-m 0.002] [--min-confirmations 1]\n"
               "  The bag: exocet_servo's acquisition_sequencer_node (left|right/image_raw, camera_info, pose per "
               "stop).\n";
  return error.empty() ? 0 : 2;
}

/// One stop of the acquisition, its messages by topic.
struct Stop {
  sensor_msgs::ImageConstPtr left, right;
  sensor_msgs::CameraInfoConstPtr left_info, right_info;
  geometry_msgs::PoseStampedConstPtr left_pose, right_pose;
  bool complete() const { return left && right && left_info && right_info && left_pose && right_pose; }
};

Eigen::Matrix3d intrinsics(const sensor_msgs::CameraInfo& info) {
  Eigen::Matrix3d k;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) k(r, c) = info.K[3 * r + c];
  return k;
}

Eigen::Isometry3d pose(const geometry_msgs::Pose& p) {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.linear() = Eigen::Quaterniond(p.orientation.w, p.orientation.x, p.orientation.y, p.orientation.z)
                   .normalized()
                   .toRotationMatrix();
  t.translation() = Eigen::Vector3d(p.position.x, p.position.y, p.position.z);
  return t;
}

double seconds(Clock::time_point start) { return std::chrono::duration<double>(Clock::now() - start).count(); }

}  // namespace

int main(int argc, char** argv) {
  std::string bag_path, output_dir;
  mesh::PairDepthConfig depth_config;
  depth_config.min_depth_m = 0.4;  // an object 0.5-0.8 m in front of the rig on the arm
  depth_config.max_depth_m = 1.0;
  mesh::CloudFusionConfig fusion;
  fusion.voxel_m = 0.002;
  fusion.depth_tolerance = 0.005;
  fusion.min_confirmations = 1;
  try {
    for (int i = 1; i < argc; ++i) {
      const std::string arg = argv[i];
      if (arg == "--help" || arg == "-h") return usage("");
      if (i + 1 >= argc) return usage("option " + arg + " needs a value");
      const std::string value = argv[++i];
      if (arg == "--bag") bag_path = value;
      else if (arg == "--output-dir") output_dir = value;
      else if (arg == "--method") depth_config.method = value;
      else if (arg == "--min-depth-m") depth_config.min_depth_m = std::stod(value);
      else if (arg == "--max-depth-m") depth_config.max_depth_m = std::stod(value);
      else if (arg == "--voxel-m") fusion.voxel_m = std::stod(value);
      else if (arg == "--min-confirmations") fusion.min_confirmations = std::stoi(value);
      else return usage("unknown option " + arg);
    }
  } catch (const std::exception&) {
    return usage("a numeric option has a value that is not a number");
  }
  if (bag_path.empty() || output_dir.empty()) return usage("--bag and --output-dir are required");
  std::string problems = depth_config.validate();
  if (problems.empty()) problems = fusion.validate();
  if (!problems.empty()) return usage(problems);

  // The stops, by stamp.
  std::map<ros::Time, Stop> stops;
  try {
    rosbag::Bag bag(bag_path, rosbag::bagmode::Read);
    for (const rosbag::MessageInstance& m : rosbag::View(bag)) {
      Stop& s = stops[m.getTime()];
      const std::string& topic = m.getTopic();
      if (topic == "left/image_raw" || topic == "/left/image_raw") s.left = m.instantiate<sensor_msgs::Image>();
      else if (topic == "right/image_raw" || topic == "/right/image_raw") s.right = m.instantiate<sensor_msgs::Image>();
      else if (topic == "left/camera_info" || topic == "/left/camera_info")
        s.left_info = m.instantiate<sensor_msgs::CameraInfo>();
      else if (topic == "right/camera_info" || topic == "/right/camera_info")
        s.right_info = m.instantiate<sensor_msgs::CameraInfo>();
      else if (topic == "left/pose" || topic == "/left/pose") s.left_pose = m.instantiate<geometry_msgs::PoseStamped>();
      else if (topic == "right/pose" || topic == "/right/pose")
        s.right_pose = m.instantiate<geometry_msgs::PoseStamped>();
    }
  } catch (const rosbag::BagException& e) {
    std::cerr << "reconstruct_acquisition: cannot read " << bag_path << ": " << e.what() << "\n";
    return 1;
  }
  std::vector<Stop> complete;
  for (const auto& [stamp, s] : stops) {
    if (s.complete())
      complete.push_back(s);
    else
      std::cerr << "reconstruct_acquisition: stop at " << stamp.toSec()
                << " lacks an image, a camera_info or a pose: left out\n";
  }
  if (complete.empty()) {
    std::cerr << "reconstruct_acquisition: " << bag_path << " holds no complete stop (left|right image_raw, "
              << "camera_info and pose at one stamp)\n";
    return 1;
  }
  std::cout << "reconstruct_acquisition: " << complete.size() << " stereo pairs in " << bag_path << "\n";

  const auto start = Clock::now();
  std::vector<mesh::DepthView> views;
  for (size_t k = 0; k < complete.size(); ++k) {
    const Stop& s = complete[k];
    mesh::CalibratedPair pair;
    try {
      pair.left = cv_bridge::toCvShare(s.left, sensor_msgs::image_encodings::MONO8)->image;
      pair.right = cv_bridge::toCvShare(s.right, sensor_msgs::image_encodings::MONO8)->image;
    } catch (const std::exception& e) {
      std::cerr << "reconstruct_acquisition: pair " << k + 1 << ": image unreadable (" << e.what() << "): left out\n";
      continue;
    }
    pair.K_left = intrinsics(*s.left_info);
    pair.K_right = intrinsics(*s.right_info);
    pair.world_T_left = pose(s.left_pose->pose);
    pair.world_T_right = pose(s.right_pose->pose);
    try {
      mesh::PairDepthStats stats;
      views.push_back(mesh::depthFromPair(pair, depth_config, &stats));
      std::cout << "  pair " << k + 1 << " of " << complete.size() << ": " << stats.depth_pixels << " depths, "
                << stats.disparities_px << " disparities searched, " << seconds(start) << " s\n";
    } catch (const std::exception& e) {
      std::cerr << "reconstruct_acquisition: pair " << k + 1 << ": " << e.what() << ": left out\n";
    }
  }
  if (views.empty()) {
    std::cerr << "reconstruct_acquisition: no pair gave a depth map\n";
    return 1;
  }
  mesh::CloudFusionStats fusion_stats;
  const mesh::FusedCloud cloud = mesh::fuseDepthMaps(views, fusion, &fusion_stats);
  std::cout << "  fused cloud: " << cloud.size() << " points, " << seconds(start) << " s\n";
  if (cloud.size() == 0) {
    std::cerr << "reconstruct_acquisition: the depth maps do not confirm each other (no fused point); try "
                 "--min-confirmations 0 or a wider --min-depth-m/--max-depth-m\n";
    return 1;
  }
  mesh::CloudSurfaceConfig surface_config;
  surface_config.cell_m = fusion.voxel_m;
  surface_config.radius_m = 3.0 * fusion.voxel_m;
  mesh::CloudSurfaceStats surface_stats;
  const mesh::TexturedMesh surface = mesh::surfaceFromCloud(cloud, surface_config, &surface_stats);
  std::cout << "  surface: " << surface.vertices.size() << " vertices, " << surface.triangles.size() << " triangles, "
            << seconds(start) << " s\n";
  try {
    std::filesystem::create_directories(output_dir);
    const std::filesystem::path dir(output_dir);
    io::writePointCloudPly((dir / "fused_cloud.ply").string(), cloud.points, cloud.colors);
    if (!surface.empty()) {
      io::writePly((dir / "surface.ply").string(), surface);
      io::writeObj((dir / "surface.obj").string(), surface);
      io::writeVrml((dir / "surface.wrl").string(), surface);
    }
  } catch (const std::exception& e) {
    std::cerr << "reconstruct_acquisition: cannot write into " << output_dir << ": " << e.what() << "\n";
    return 1;
  }
  std::cout << "reconstruct_acquisition: wrote " << output_dir << "/fused_cloud.ply"
            << (surface.empty() ? "" : ", surface.ply, surface.obj, surface.wrl") << " (" << seconds(start)
            << " s)\n";
  return 0;
}
