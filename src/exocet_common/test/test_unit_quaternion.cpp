#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "exocet_common/unit_quaternion.h"

namespace exocet_common {
namespace {

TEST(UnitQuaternion, AcceptsRotationsAsMessagesCarryThem) {
  EXPECT_TRUE(isUnitQuaternion(1.0, 0.0, 0.0, 0.0));
  const double h = std::sqrt(0.5);
  EXPECT_TRUE(isUnitQuaternion(h, 0.0, 0.0, h));
  // Four printed decimals, and float32 rounding.
  EXPECT_TRUE(isUnitQuaternion(0.7071, 0.0, 0.0, 0.7071));
  EXPECT_TRUE(isUnitQuaternion(static_cast<float>(h), 0.0, static_cast<float>(h), 0.0));
}

TEST(UnitQuaternion, RefusesZeroNonFiniteAndUnnormalised) {
  EXPECT_FALSE(isUnitQuaternion(0.0, 0.0, 0.0, 0.0));
  EXPECT_FALSE(isUnitQuaternion(std::numeric_limits<double>::quiet_NaN(), 0.0, 0.0, 0.0));
  EXPECT_FALSE(isUnitQuaternion(std::numeric_limits<double>::infinity(), 0.0, 0.0, 0.0));
  EXPECT_FALSE(isUnitQuaternion(1.02, 0.0, 0.0, 0.0));
  EXPECT_FALSE(isUnitQuaternion(0.5, 0.5, 0.5, 0.0));
}

}  // namespace
}  // namespace exocet_common
