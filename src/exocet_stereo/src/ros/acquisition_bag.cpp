#include "exocet_stereo/ros/acquisition_bag.h"

#include <map>
#include <stdexcept>

#include <cv_bridge/cv_bridge.h>
#include <geometry_msgs/PoseStamped.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/image_encodings.h>

namespace exocet_stereo {

namespace {

/// One stop of the acquisition, its messages.
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

/// The topic without a leading slash.
std::string relative(const std::string& topic) { return !topic.empty() && topic[0] == '/' ? topic.substr(1) : topic; }

}  // namespace

std::vector<mesh::CalibratedPair> readAcquisitionBag(const std::string& path, std::vector<std::string>* warnings) {
  std::map<ros::Time, Stop> stops;
  try {
    rosbag::Bag bag(path, rosbag::bagmode::Read);
    for (const rosbag::MessageInstance& m : rosbag::View(bag)) {
      Stop& s = stops[m.getTime()];
      const std::string topic = relative(m.getTopic());
      if (topic == "left/image_raw") s.left = m.instantiate<sensor_msgs::Image>();
      else if (topic == "right/image_raw") s.right = m.instantiate<sensor_msgs::Image>();
      else if (topic == "left/camera_info") s.left_info = m.instantiate<sensor_msgs::CameraInfo>();
      else if (topic == "right/camera_info") s.right_info = m.instantiate<sensor_msgs::CameraInfo>();
      else if (topic == "left/pose") s.left_pose = m.instantiate<geometry_msgs::PoseStamped>();
      else if (topic == "right/pose") s.right_pose = m.instantiate<geometry_msgs::PoseStamped>();
    }
  } catch (const rosbag::BagException& e) {
    throw std::runtime_error("cannot read the acquisition bag " + path + ": " + e.what());
  }
  std::vector<mesh::CalibratedPair> pairs;
  for (const auto& [stamp, s] : stops) {
    const std::string where = "stop at " + std::to_string(stamp.toSec());
    if (!s.complete()) {
      if (warnings) warnings->push_back(where + " lacks an image, a camera_info or a pose: left out");
      continue;
    }
    mesh::CalibratedPair pair;
    try {
      pair.left = cv_bridge::toCvCopy(s.left, sensor_msgs::image_encodings::MONO8)->image;
      pair.right = cv_bridge::toCvCopy(s.right, sensor_msgs::image_encodings::MONO8)->image;
    } catch (const std::exception& e) {
      if (warnings) warnings->push_back(where + ": image unreadable (" + e.what() + "): left out");
      continue;
    }
    pair.K_left = intrinsics(*s.left_info);
    pair.K_right = intrinsics(*s.right_info);
    pair.world_T_left = pose(s.left_pose->pose);
    pair.world_T_right = pose(s.right_pose->pose);
    pairs.push_back(pair);
  }
  return pairs;
}

}  // namespace exocet_stereo
