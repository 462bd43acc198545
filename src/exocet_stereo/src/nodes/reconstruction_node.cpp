// reconstruction_node: reconstructs an acquisition bag on ~reconstruct (fused cloud, surface, PLY/OBJ/VRML) and
// shows the result in rviz. See reconstruction_ros.h.
#include <iostream>

#include <ros/ros.h>

#include "exocet_stereo/ros/reconstruction_ros.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "reconstruction");
  try {
    exocet_stereo::ReconstructionRos node(ros::NodeHandle(), ros::NodeHandle("~"));
    ros::spin();
  } catch (const std::invalid_argument& e) {
    std::cerr << "reconstruction: " << e.what() << std::endl;
    ROS_FATAL("reconstruction: %s", e.what());
    return 2;
  }
  return 0;
}
