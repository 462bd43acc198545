// Logs a dive's trajectories (ground truth, dead reckoning, USBL fixes) to CSV: see ros/trajectory_logger.h.
#include <exception>

#include <ros/ros.h>

#include "exocet_mosaic/ros/trajectory_logger.h"

int main(int argc, char** argv) {
  // Our own SIGINT/SIGTERM handling lets the logger drain the last messages of a bag before it exits.
  ros::init(argc, argv, "trajectory_logger", ros::init_options::NoSigintHandler);
  exocet_mosaic::installStopSignalHandlers();
  // Outlive the logger: destroying the last node handle shuts ROS (and its logging) down before ROS_FATAL prints.
  ros::NodeHandle nh;
  ros::NodeHandle private_nh("~");
  try {
    exocet_mosaic::TrajectoryLogger logger(nh, private_nh);
    logger.spinUntilStopped();
  } catch (const std::exception& e) {
    ROS_FATAL("trajectory_logger: %s", e.what());
    ros::shutdown();
    return 1;
  }
  ros::shutdown();
  return 0;
}
