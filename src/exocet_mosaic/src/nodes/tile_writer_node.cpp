// tile_writer_node: composes the camera images at their fused poses into mosaics and writes each closed mosaic as a
// geo-referenced GeoTIFF tile. Parameters: see tile_writer_parameters.h and config/tiles/.
#include <iostream>

#include <ros/ros.h>

#include "exocet_mosaic/ros/tile_writer_ros.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "tile_writer_node");
  try {
    exocet_mosaic::TileWriterRos node(ros::NodeHandle(), ros::NodeHandle("~"));
    ros::spin();
  } catch (const std::exception& e) {
    // Also on stderr: a bad parameter can stop the node before rosconsole prints anything.
    std::cerr << "tile_writer_node: " << e.what() << std::endl;
    ROS_FATAL("tile_writer_node: %s", e.what());
    return 2;
  }
  return 0;
}
