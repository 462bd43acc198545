// odometry_path_node: a nav_msgs/Path of an odometry stream for rviz (the simulator's ground truth beside the fused
// track). Parameters: see ros/odometry_path_recorder.h.
#include <iostream>

#include <ros/ros.h>

#include "exocet_mosaic/ros/odometry_path_recorder.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "odometry_path_node");
  try {
    exocet_mosaic::OdometryPathRecorder node(ros::NodeHandle(), ros::NodeHandle("~"));
    ros::spin();
  } catch (const std::invalid_argument& e) {
    std::cerr << "odometry_path_node: " << e.what() << std::endl;
    ROS_FATAL("odometry_path_node: %s", e.what());
    return 2;
  }
  return 0;
}
