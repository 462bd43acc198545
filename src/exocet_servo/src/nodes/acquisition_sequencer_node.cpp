// acquisition_sequencer_node: repeated servoings along the rig-induced trajectory, a stereo pair and the arm pose
// recorded into a bag at each stop. See acquisition_sequencer_ros.h.
#include <iostream>

#include <ros/ros.h>

#include "exocet_servo/ros/acquisition_sequencer_ros.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "acquisition_sequencer");
  try {
    exocet_servo::AcquisitionSequencerRos node(ros::NodeHandle(), ros::NodeHandle("~"));
    ros::spin();
  } catch (const std::exception& e) {
    std::cerr << "acquisition_sequencer: " << e.what() << std::endl;
    ROS_FATAL("acquisition_sequencer: %s", e.what());
    return 2;
  }
  return 0;
}
