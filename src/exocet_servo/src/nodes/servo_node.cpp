// servo_node: intrinsics-free stereo visual servoing (2D4 report, section 2): on ~capture_reference the right
// camera's image becomes the reference and the left camera is servoed to where the right one took it. See
// servo_ros.h.
#include <iostream>

#include <ros/ros.h>

#include "exocet_servo/ros/servo_ros.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "servo");
  try {
    exocet_servo::ServoRos node(ros::NodeHandle(), ros::NodeHandle("~"));
    ros::spin();
  } catch (const std::invalid_argument& e) {
    std::cerr << "servo: " << e.what() << std::endl;
    ROS_FATAL("servo: %s", e.what());
    return 2;
  }
  return 0;
}
