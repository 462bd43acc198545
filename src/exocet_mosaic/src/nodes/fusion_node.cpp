// fusion_node: fuses the registration's image motion with the vehicle's navigation (dead reckoning, USBL) in a
// Kalman filter and publishes the camera's position in UTM. Parameters: see fusion_parameters.h and config/fusion/.
#include <iostream>

#include <ros/ros.h>

#include "exocet_mosaic/ros/fusion_ros.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "fusion_node");
  try {
    exocet_mosaic::FusionRos node(ros::NodeHandle(), ros::NodeHandle("~"));
    ros::spin();
  } catch (const std::invalid_argument& e) {
    // Also on stderr: a bad parameter can stop the node before rosconsole prints anything.
    std::cerr << "fusion_node: " << e.what() << std::endl;
    ROS_FATAL("fusion_node: %s", e.what());
    return 2;
  }
  return 0;
}
