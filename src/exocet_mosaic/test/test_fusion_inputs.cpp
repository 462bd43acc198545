// The fusion node's ROS-free input helpers: attitude/altitude histories and the heading read from image motion.
#include <cmath>

#include <gtest/gtest.h>

#include "exocet_mosaic/fusion/image_heading.h"
#include "exocet_mosaic/fusion/measurement_history.h"
#include "exocet_common/camera_model.h"
#include "exocet_mosaic/sim/dive_synthesizer.h"
#include "exocet_mosaic/sim/image_motion_truth.h"

namespace exocet_mosaic {
namespace fusion {
namespace {

Eigen::Quaterniond yaw(double rad) { return Eigen::Quaterniond(Eigen::AngleAxisd(rad, Eigen::Vector3d::UnitZ())); }

TEST(AttitudeHistory, InterpolatesBetweenSamplesAndRefusesGaps) {
  AttitudeHistory history(30.0, 0.5);
  history.add(10.0, yaw(0.0));
  history.add(10.2, yaw(0.2));
  history.add(12.0, yaw(1.0));  // 1.8 s after the previous sample: a gap
  const auto mid = history.at(10.05);
  ASSERT_TRUE(mid.has_value());
  EXPECT_NEAR(mid->angularDistance(yaw(0.05)), 0.0, 1e-12);
  EXPECT_FALSE(history.at(11.0).has_value()) << "no interpolation across a gap longer than max_interpolation_gap_s";
  ASSERT_TRUE(history.at(12.2).has_value()) << "within half the gap past the newest sample";
  EXPECT_FALSE(history.at(12.3).has_value());
  EXPECT_FALSE(history.at(9.7).has_value());
}

TEST(AttitudeHistory, ClockJumpClearsAndWindowBoundsMemory) {
  AttitudeHistory history(1.0, 0.5);
  for (int i = 0; i <= 100; ++i) history.add(100.0 + 0.1 * i, yaw(0.01 * i));
  EXPECT_FALSE(history.at(100.0).has_value()) << "older than the window";
  EXPECT_TRUE(history.at(109.5).has_value());
  history.add(50.0, yaw(0.3));  // time went back
  EXPECT_FALSE(history.at(109.5).has_value());
  ASSERT_TRUE(history.at(50.0).has_value());
  EXPECT_NEAR(history.at(50.0)->angularDistance(yaw(0.3)), 0.0, 1e-12);
}

TEST(ScalarHistory, InterpolatesLinearly) {
  ScalarHistory altitude(30.0, 1.0);
  altitude.add(1.0, 2.0);
  altitude.add(1.5, 3.0);
  ASSERT_TRUE(altitude.at(1.25).has_value());
  EXPECT_DOUBLE_EQ(*altitude.at(1.25), 2.5);
  EXPECT_DOUBLE_EQ(*altitude.at(1.0), 2.0);
  EXPECT_FALSE(altitude.at(3.0).has_value());
}

// The heading change read from the true seabed homography of two views of a camera looking down from a vehicle that
// turns, rolls and pitches: the yaw change must come back within a small fraction of a degree.
TEST(ImageHeading, YawChangeFromTrueSeabedHomography) {
  const exocet_common::CameraModel camera = exocet_common::CameraModel::pal(60.0);
  sim::CameraRig rig;
  rig.lever_arm_m = Eigen::Vector3d(0.4, 0.0, -0.3);
  const Eigen::Isometry3d base_from_camera = rig.baseFromCamera();
  const Eigen::Matrix3d k = (Eigen::Matrix3d() << camera.fx, 0, camera.cx, 0, camera.fy, camera.cy, 0, 0, 1).finished();
  for (double yaw_change_deg : {-3.0, -0.5, 0.0, 0.7, 2.5}) {
    auto vehicle = [](double x, double y, double z, double roll, double pitch, double heading) {
      Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
      t.linear() = (Eigen::AngleAxisd(heading, Eigen::Vector3d::UnitZ()) *
                    Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) * Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()))
                       .toRotationMatrix();
      t.translation() = Eigen::Vector3d(x, y, z);
      return t;
    };
    const double deg = M_PI / 180.0;
    const Eigen::Isometry3d a = vehicle(0.0, 0.0, 2.5, 0.5 * deg, -0.8 * deg, 0.3);
    const Eigen::Isometry3d b = vehicle(0.08, 0.03, 2.52, 0.2 * deg, -0.5 * deg, 0.3 + yaw_change_deg * deg);
    const Eigen::Matrix3d h = sim::seabedPlaneHomography(camera, a * base_from_camera, b * base_from_camera);
    const double estimated = yawChangeFromImageMotion_rad(h, k, base_from_camera);
    EXPECT_NEAR(estimated / deg, yaw_change_deg, 0.05) << "yaw change " << yaw_change_deg << " deg";
  }
}

}  // namespace
}  // namespace fusion
}  // namespace exocet_mosaic
