// arm_rig_simulator_node: the 6-DOF arm carrying the stereo rig in front of a vent; takes the left camera's velocity,
// publishes both cameras' images, depths, camera_info, joint states and tf. See arm_rig_simulator_ros.h.
#include <iostream>

#include <ros/ros.h>

#include "exocet_servo/ros/arm_rig_simulator_ros.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "arm_rig_simulator");
  try {
    exocet_servo::ArmRigSimulatorRos node(ros::NodeHandle(), ros::NodeHandle("~"));
    ros::spin();
  } catch (const std::invalid_argument& e) {
    std::cerr << "arm_rig_simulator: " << e.what() << std::endl;
    ROS_FATAL("arm_rig_simulator: %s", e.what());
    return 2;
  }
  return 0;
}
