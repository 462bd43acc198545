#include <ros/time.h>
#include "fixture/clean.h"
namespace fixture {
double halfNow() { return halve(ros::WallTime::now().toSec()); }
}
