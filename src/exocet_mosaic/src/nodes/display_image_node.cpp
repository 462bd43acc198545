// display_image_node: the camera's images decoded for rviz while it watches (ros/display_image_publisher.h).
#include <iostream>

#include <ros/ros.h>

#include "exocet_mosaic/ros/display_image_publisher.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "display_image_node");
  try {
    exocet_mosaic::DisplayImagePublisher node(ros::NodeHandle(), ros::NodeHandle("~"));
    ros::spin();
  } catch (const std::invalid_argument& e) {
    std::cerr << "display_image_node: " << e.what() << std::endl;
    ROS_FATAL("display_image_node: %s", e.what());
    return 2;
  }
  return 0;
}
