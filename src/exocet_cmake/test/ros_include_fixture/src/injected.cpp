#include <ros/time.h>
#include "fixture/clean.h"
namespace fixture {
double nowSeconds() { return ros::WallTime::now().toSec(); }
}
