#pragma once
// A third-party header that happens to include ROS: a grep of the core sources does not see it.
#include <ros/time.h>
namespace vendor {
inline double seconds() { return ros::WallTime::now().toSec(); }
}
