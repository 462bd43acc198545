// The rule that turns an odometry stream into a bounded rviz path (ros/odometry_path_recorder.h).
#include <cmath>
#include <limits>

#include <gtest/gtest.h>

#include "exocet_mosaic/ros/odometry_path_recorder.h"

namespace exocet_mosaic {
namespace {

geometry_msgs::PoseStamped poseAt(double stamp_s, double x_m, double y_m, const std::string& frame = "utm") {
  geometry_msgs::PoseStamped p;
  p.header.stamp = ros::Time(stamp_s);
  p.header.frame_id = frame;
  p.pose.position.x = x_m;
  p.pose.position.y = y_m;
  p.pose.orientation.w = 1.0;
  return p;
}

TEST(OdometryPath, KeepsPosesAtTheSpacingAndFollowsTheStream) {
  OdometryPathConfig config;
  config.min_spacing_m = 0.5;
  nav_msgs::Path path;
  // 0.1 m steps: one pose in five is kept (the 0.5 m spacing, with rounding margin, keeps every 5th or 6th).
  int appended = 0;
  for (int k = 0; k <= 100; ++k)
    if (appendToPath(poseAt(100.0 + 0.1 * k, 500000.0 + 0.1 * k, 4.7e6), config, &path) == PathUpdate::kAppended)
      ++appended;
  EXPECT_EQ(int(path.poses.size()), appended);
  EXPECT_GE(appended, 17);
  EXPECT_LE(appended, 21);
  EXPECT_EQ(path.header.frame_id, "utm");
  EXPECT_NEAR(path.poses.front().pose.position.x, 500000.0, 1e-9);
  for (size_t i = 1; i < path.poses.size(); ++i)
    EXPECT_GE(path.poses[i].pose.position.x - path.poses[i - 1].pose.position.x, 0.5 - 1e-6);
}

TEST(OdometryPath, MemoryStaysBoundedAndTheExtentIsKept) {
  OdometryPathConfig config;
  config.min_spacing_m = 0.0;
  config.max_poses = 100;
  nav_msgs::Path path;
  for (int k = 0; k < 100000; ++k) appendToPath(poseAt(1.0 + k, k, 0.0), config, &path);
  EXPECT_LE(int(path.poses.size()), 100);
  EXPECT_GE(int(path.poses.size()), 50);
  EXPECT_DOUBLE_EQ(path.poses.front().pose.position.x, 0.0);
  EXPECT_DOUBLE_EQ(path.poses.back().pose.position.x, 99999.0);
  for (size_t i = 1; i < path.poses.size(); ++i) EXPECT_LT(path.poses[i - 1].header.stamp, path.poses[i].header.stamp);
}

TEST(OdometryPath, ClockJumpOrNewFrameStartsANewPath) {
  OdometryPathConfig config;
  nav_msgs::Path path;
  for (int k = 0; k < 10; ++k) appendToPath(poseAt(50.0 + k, k, 0.0), config, &path);
  ASSERT_EQ(path.poses.size(), 10u);
  EXPECT_EQ(appendToPath(poseAt(10.0, 3.0, 3.0), config, &path), PathUpdate::kRestarted);  // bag replayed again
  EXPECT_EQ(path.poses.size(), 1u);
  EXPECT_EQ(appendToPath(poseAt(11.0, 4.0, 3.0, "map"), config, &path), PathUpdate::kRestarted);
  EXPECT_EQ(path.header.frame_id, "map");
  EXPECT_EQ(path.poses.size(), 1u);
}

TEST(OdometryPath, NonFinitePosesAndZeroStampsAreRefused) {
  OdometryPathConfig config;
  nav_msgs::Path path;
  appendToPath(poseAt(1.0, 0.0, 0.0), config, &path);
  geometry_msgs::PoseStamped bad = poseAt(2.0, std::numeric_limits<double>::quiet_NaN(), 0.0);
  EXPECT_EQ(appendToPath(bad, config, &path), PathUpdate::kRejectedNotFinite);
  bad = poseAt(2.0, 1.0, 0.0);
  bad.pose.orientation.z = std::numeric_limits<double>::infinity();
  EXPECT_EQ(appendToPath(bad, config, &path), PathUpdate::kRejectedNotFinite);
  EXPECT_EQ(appendToPath(poseAt(0.0, 1.0, 0.0), config, &path), PathUpdate::kRejectedNotFinite);
  EXPECT_EQ(path.poses.size(), 1u);
}

}  // namespace
}  // namespace exocet_mosaic
