// web_map_node: serves the dive's mosaic as a live web map (Leaflet, no internet) and keeps the site folder as a
// static copy. Parameters: see web_map_parameters.h and README.md.
#include <iostream>

#include <ros/ros.h>

#include "exocet_web/ros/web_map_ros.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "web_map_node");
  try {
    exocet_web::WebMapRos node(ros::NodeHandle(), ros::NodeHandle("~"));
    ros::spin();
  } catch (const std::exception& e) {
    // Also on stderr: a bad parameter can stop the node before rosconsole prints anything.
    std::cerr << "web_map_node: " << e.what() << std::endl;
    ROS_FATAL("web_map_node: %s", e.what());
    return 2;
  }
  return 0;
}
