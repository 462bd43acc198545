#include "exocet_stereo/ros/reconstruction_ros.h"

#include <sensor_msgs/PointCloud2.h>
#include <sensor_msgs/point_cloud2_iterator.h>
#include <std_msgs/String.h>
#include <visualization_msgs/Marker.h>

#include "exocet_common/ros/parameter_reader.h"
#include "exocet_stereo/ros/acquisition_bag.h"

namespace exocet_stereo {

namespace {

mesh::AcquisitionReconstructionConfig readConfig(const ros::NodeHandle& pnh) {
  mesh::AcquisitionReconstructionConfig c;
  const exocet_common::ParameterReader p(pnh);
  p.readString("method", &c.depth.method, {"ssd", "dp", "so", "sgm", "gc", "bd", "sgbm", "pm"}, "dense stereo method");
  p.readPositiveDouble("min_depth_m", &c.depth.min_depth_m, 1e4, "nearest depth searched (m)");
  p.readPositiveDouble("max_depth_m", &c.depth.max_depth_m, 1e4, "farthest depth searched (m), above min_depth_m");
  p.readPositiveDouble("voxel_m", &c.fusion.voxel_m, 1e3, "voxel of the fused cloud and cell of its surface (m)");
  p.readInt("min_confirmations", &c.fusion.min_confirmations, 0, 64, "other views that must confirm a point");
  p.readBool("texture", &c.texture, "texture the surface from the pairs' left images");
  p.readDouble("atlas_scale", &c.texturing.atlas_scale, 1e-3, 1.0, "scale of the images in the texture atlas");
  const std::string problems = c.validate();
  if (!problems.empty()) throw std::invalid_argument("parameters: " + problems);
  return c;
}

}  // namespace

ReconstructionRos::ReconstructionRos(ros::NodeHandle nh, ros::NodeHandle private_nh)
    : nh_(nh), pnh_(private_nh), diagnostics_(nh, private_nh) {
  readConfig(pnh_);  // refuse bad parameters at start; they are read again at each request
  exocet_common::ParameterReader(pnh_).readString("frame_id", &frame_id_, {}, "frame of the bag's camera poses");
  progress_pub_ = pnh_.advertise<std_msgs::String>("progress", 5, true);
  cloud_pub_ = pnh_.advertise<sensor_msgs::PointCloud2>("cloud", 1, true);
  surface_pub_ = pnh_.advertise<visualization_msgs::Marker>("surface", 1, true);
  reconstruct_srv_ = pnh_.advertiseService("reconstruct", &ReconstructionRos::onReconstruct, this);
  diagnostics_.setHardwareID("exocet reconstruction");
  diagnostics_.add("reconstruction", this, &ReconstructionRos::diagnose);
  diagnostics_timer_ = nh_.createTimer(ros::Duration(1.0), [this](const ros::TimerEvent&) { diagnostics_.update(); });
  setProgress("idle");
}

ReconstructionRos::~ReconstructionRos() {
  if (worker_.joinable()) worker_.join();
}

void ReconstructionRos::setProgress(const std::string& text) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    progress_ = text;
  }
  std_msgs::String s;
  s.data = text;
  progress_pub_.publish(s);
}

bool ReconstructionRos::onReconstruct(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
  res.success = false;
  if (busy_) {
    std::lock_guard<std::mutex> lock(mutex_);
    res.message = "a reconstruction is running: " + progress_;
    return true;
  }
  std::string bag, output_dir;
  mesh::AcquisitionReconstructionConfig config;
  try {
    const exocet_common::ParameterReader p(pnh_);
    p.readString("bag", &bag, {}, "acquisition bag to reconstruct");
    p.readString("output_dir", &output_dir, {}, "folder of the files written");
    config = readConfig(pnh_);
  } catch (const std::invalid_argument& e) {
    res.message = e.what();
    return true;
  }
  if (bag.empty() || output_dir.empty()) {
    res.message = "parameters ~bag and ~output_dir are required";
    return true;
  }
  if (worker_.joinable()) worker_.join();
  busy_ = true;
  failed_ = false;
  worker_ = std::thread(&ReconstructionRos::work, this, bag, output_dir, config);
  res.success = true;
  res.message = "reconstructing " + bag + " into " + output_dir + " (progress on " + progress_pub_.getTopic() + ")";
  return true;
}

void ReconstructionRos::work(std::string bag, std::string output_dir, mesh::AcquisitionReconstructionConfig config) {
  try {
    std::vector<std::string> warnings;
    const std::vector<mesh::CalibratedPair> pairs = readAcquisitionBag(bag, &warnings);
    for (const std::string& w : warnings) ROS_WARN("reconstruction: %s", w.c_str());
    if (pairs.empty()) throw std::runtime_error(bag + " holds no complete stop");
    const mesh::AcquisitionReconstruction result =
        mesh::reconstructPairs(pairs, config, [this](const std::string& stage, double fraction) {
          setProgress(stage + " (" + std::to_string(static_cast<int>(100.0 * fraction + 0.5)) + " %)");
        });
    for (const std::string& w : result.warnings) ROS_WARN("reconstruction: %s", w.c_str());
    const std::vector<std::string> files = mesh::writeReconstruction(result, output_dir);
    publishResult(result);
    const std::string done = "done: " + std::to_string(result.views.size()) + " pairs, " +
                             std::to_string(result.cloud.size()) + " points, " +
                             std::to_string(result.surface.triangles.size()) + " triangles, " +
                             std::to_string(files.size()) + " files in " + output_dir;
    setProgress(done);
    ROS_INFO("reconstruction: %s", done.c_str());
  } catch (const std::exception& e) {
    failed_ = true;
    setProgress(std::string("failed: ") + e.what());
    ROS_ERROR("reconstruction: %s", e.what());
  }
  busy_ = false;
}

void ReconstructionRos::publishResult(const mesh::AcquisitionReconstruction& result) {
  const ros::Time stamp = ros::Time::now();
  sensor_msgs::PointCloud2 cloud;
  cloud.header.stamp = stamp;
  cloud.header.frame_id = frame_id_;
  sensor_msgs::PointCloud2Modifier modifier(cloud);
  modifier.setPointCloud2FieldsByString(2, "xyz", "rgb");
  modifier.resize(result.cloud.size());
  sensor_msgs::PointCloud2Iterator<float> x(cloud, "x"), y(cloud, "y"), z(cloud, "z");
  sensor_msgs::PointCloud2Iterator<uint8_t> r(cloud, "r"), g(cloud, "g"), b(cloud, "b");
  const bool colored = result.cloud.colors.size() == result.cloud.size();
  for (size_t i = 0; i < result.cloud.size(); ++i, ++x, ++y, ++z, ++r, ++g, ++b) {
    const Eigen::Vector3d& p = result.cloud.points[i];
    *x = static_cast<float>(p.x());
    *y = static_cast<float>(p.y());
    *z = static_cast<float>(p.z());
    const cv::Vec3b c = colored ? result.cloud.colors[i] : cv::Vec3b(200, 200, 200);
    *r = c[0];
    *g = c[1];
    *b = c[2];
  }
  cloud_pub_.publish(cloud);

  visualization_msgs::Marker marker;
  marker.header = cloud.header;
  marker.ns = "reconstruction";
  marker.id = 0;
  marker.type = visualization_msgs::Marker::TRIANGLE_LIST;
  marker.action = visualization_msgs::Marker::ADD;
  marker.pose.orientation.w = 1.0;
  marker.scale.x = marker.scale.y = marker.scale.z = 1.0;
  marker.color.r = marker.color.g = marker.color.b = 0.8f;
  marker.color.a = 1.0f;
  const bool vertex_colors = result.surface.colors.size() == result.surface.vertices.size();
  for (const Eigen::Vector3i& t : result.surface.triangles) {
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d& v = result.surface.vertices[t[k]];
      geometry_msgs::Point p;
      p.x = v.x();
      p.y = v.y();
      p.z = v.z();
      marker.points.push_back(p);
      if (vertex_colors) {
        std_msgs::ColorRGBA c;
        const cv::Vec3b& rgb = result.surface.colors[t[k]];
        c.r = rgb[0] / 255.0f;
        c.g = rgb[1] / 255.0f;
        c.b = rgb[2] / 255.0f;
        c.a = 1.0f;
        marker.colors.push_back(c);
      }
    }
  }
  surface_pub_.publish(marker);
}

void ReconstructionRos::diagnose(diagnostic_updater::DiagnosticStatusWrapper& status) {
  using diagnostic_msgs::DiagnosticStatus;
  std::lock_guard<std::mutex> lock(mutex_);
  status.summary(failed_ ? DiagnosticStatus::ERROR : DiagnosticStatus::OK, progress_);
  status.add("busy", busy_ ? "yes" : "no");
}

}  // namespace exocet_stereo
