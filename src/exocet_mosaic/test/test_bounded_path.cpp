// The fusion's bounded display paths (ros/bounded_path.h).
#include <cmath>
#include <stdexcept>

#include <gtest/gtest.h>

#include "exocet_mosaic/ros/bounded_path.h"

namespace exocet_mosaic {
namespace {

double gap(const geometry_msgs::PoseStamped& a, const geometry_msgs::PoseStamped& b) {
  return std::hypot(b.pose.position.x - a.pose.position.x, b.pose.position.y - a.pose.position.y);
}

TEST(BoundedPath, KeepsPosesAtTheSpacingAndEndsAtTheNewest) {
  BoundedPath path(0.5, 1000, "map");
  // 0.1 m steps over 10 m: kept poses at least 0.5 m apart, the newest always last.
  for (int k = 0; k <= 100; ++k) {
    path.append(ros::Time(100.0 + 0.1 * k), Eigen::Vector2d(0.1 * k, 2.0));
    ASSERT_NEAR(path.path().poses.back().pose.position.x, 0.1 * k, 1e-9);
    ASSERT_EQ(path.path().header.stamp, ros::Time(100.0 + 0.1 * k));
  }
  const auto& poses = path.path().poses;
  EXPECT_GE(poses.size(), 18u);
  EXPECT_LE(poses.size(), 22u);
  EXPECT_EQ(path.path().header.frame_id, "map");
  EXPECT_EQ(poses.front().header.frame_id, "map");
  EXPECT_NEAR(poses.front().pose.position.x, 0.0, 1e-9);
  for (size_t i = 1; i + 1 < poses.size(); ++i) EXPECT_GE(gap(poses[i - 1], poses[i]), 0.5 - 1e-9) << i;
  EXPECT_DOUBLE_EQ(poses.back().pose.orientation.w, 1.0);
}

TEST(BoundedPath, StaysBoundedAtOneDensityOverALongDive) {
  // Two hours at 0.5 m/s, a position every 0.1 s, 5 cm apart: 72000 positions into 500 poses.
  BoundedPath path(0.05, 500, "map");
  for (int k = 0; k < 72000; ++k) {
    path.append(ros::Time(1.0 + 0.1 * k), Eigen::Vector2d(0.05 * k, 0.0));
    ASSERT_LE(path.path().poses.size(), 500u);
  }
  const auto& poses = path.path().poses;
  EXPECT_GE(poses.size(), 250u);
  EXPECT_DOUBLE_EQ(poses.front().pose.position.x, 0.0);
  EXPECT_NEAR(poses.back().pose.position.x, 0.05 * 71999, 1e-6);
  // 3600 m in at most 500 poses: the spacing doubled until 0.05 * 2^k * 500 covers it, i.e. 12.8 m.
  EXPECT_NEAR(path.spacingM(), 12.8, 1e-9);
  // One density from the start to the end: no gap of the older part is much wider than those of the newer.
  double old_max = 0.0, new_min = 1e9;
  for (size_t i = 1; i + 1 < poses.size(); ++i) {
    if (i < poses.size() / 4) old_max = std::max(old_max, gap(poses[i - 1], poses[i]));
    if (i > 3 * poses.size() / 4) new_min = std::min(new_min, gap(poses[i - 1], poses[i]));
  }
  EXPECT_LE(old_max, 2.0 * new_min + 1e-6);
  for (size_t i = 1; i < poses.size(); ++i) EXPECT_LT(poses[i - 1].header.stamp, poses[i].header.stamp);
}

TEST(BoundedPath, ClearReturnsToTheFirstSpacing) {
  BoundedPath path(0.05, 10, "map");
  for (int k = 0; k < 100; ++k) path.append(ros::Time(1.0 + k), Eigen::Vector2d(0.05 * k, 0.0));
  EXPECT_GT(path.spacingM(), 0.05);
  path.clear();
  EXPECT_TRUE(path.path().poses.empty());
  EXPECT_DOUBLE_EQ(path.spacingM(), 0.05);
  EXPECT_EQ(path.path().header.frame_id, "map");
}

TEST(BoundedPath, ZeroSpacingKeepsEveryPoseUpToTheBound) {
  BoundedPath path(0.0, 1000, "map");
  for (int k = 0; k < 1000; ++k) path.append(ros::Time(1.0 + k), Eigen::Vector2d(1.0, 1.0));
  EXPECT_EQ(path.path().poses.size(), 1000u);
}

TEST(BoundedPath, RefusesValuesOutOfRange) {
  EXPECT_THROW(BoundedPath(-0.1, 100, "map"), std::invalid_argument);
  EXPECT_THROW(BoundedPath(std::nan(""), 100, "map"), std::invalid_argument);
  EXPECT_THROW(BoundedPath(0.1, 2, "map"), std::invalid_argument);
}

}  // namespace
}  // namespace exocet_mosaic
