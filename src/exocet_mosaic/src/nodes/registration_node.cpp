// registration_node: frame-to-frame registration of the camera images (KLT, RMR or auto), one
// exocet_msgs/ImageMotion per image pair on /mosaic/motion. Parameters: see registration_ros.h and config/registration/.
#include <iostream>

#include <ros/ros.h>

#include "exocet_mosaic/ros/registration_ros.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "registration_node");
  try {
    exocet_mosaic::RegistrationRos node(ros::NodeHandle(), ros::NodeHandle("~"));
    ros::spin();
  } catch (const std::invalid_argument& e) {
    // Also on stderr: a bad parameter can stop the node before rosconsole prints anything.
    std::cerr << "registration_node: " << e.what() << std::endl;
    ROS_FATAL("registration_node: %s", e.what());
    return 2;
  }
  return 0;
}
