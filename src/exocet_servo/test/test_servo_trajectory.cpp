// Tests of the rig-induced trajectories (2D4 report 2.2, eq. 9): SE(3) maps, the screw (cylinder) decomposition of
// the rig transform against composed transforms, the acquisition planner, and repeated simulated servoing against
// the predicted poses.
#include <cmath>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "exocet_servo/sim/point_scene.h"
#include "exocet_servo/sim/servo_simulation.h"
#include "exocet_servo/trajectory/acquisition_planner.h"
#include "exocet_servo/trajectory/rig_geometry.h"
#include "exocet_servo/trajectory/screw_motion.h"
#include "exocet_servo/trajectory/se3.h"

namespace {

using namespace exocet_servo;
using namespace exocet_servo::trajectory;

double deg(double d) { return d * M_PI / 180.0; }

void expectPoseNear(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b, double tol, const std::string& what) {
  EXPECT_LT((a.matrix() - b.matrix()).cwiseAbs().maxCoeff(), tol) << what;
}

TEST(ServoSe3, ExpLogRoundTrip) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int i = 0; i < 200; ++i) {
    Twist t;
    for (int j = 0; j < 6; ++j) t(j) = u(rng);
    t.tail<3>() *= (i % 4 == 0 ? 1e-9 : 2.5) / std::max(1e-12, t.tail<3>().norm()) * std::abs(u(rng));
    const Twist back = logSe3(expSe3(t));
    EXPECT_LT((back - t).cwiseAbs().maxCoeff(), 1e-9) << i;
  }
  // exp of a pure rotation and of a pure translation.
  Twist r = Twist::Zero();
  r(5) = M_PI / 2;
  EXPECT_LT((expSe3(r).linear() - Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()).toRotationMatrix()).norm(),
            1e-12);
  Twist tr = Twist::Zero();
  tr.head<3>() << 1, 2, 3;
  EXPECT_LT((expSe3(tr).translation() - Eigen::Vector3d(1, 2, 3)).norm(), 1e-15);
}

TEST(ServoScrew, CylinderPredictsComposedTransforms) {
  struct Case {
    double baseline, pan, tilt;
  };
  const std::vector<Case> cases = {
      {0.3, deg(18), 0.0}, {0.3, deg(18), deg(4)}, {0.2, deg(15), -deg(7)}, {0.3, 0.0, 0.0}, {0.5, deg(-30), deg(20)}};
  for (const auto& c : cases) {
    RigGeometry rig;
    rig.baseline_m = c.baseline;
    rig.pan_rad = c.pan;
    rig.tilt_rad = c.tilt;
    ASSERT_EQ(rig.validate(), "");
    const Eigen::Isometry3d t = rig.leftFromRight();
    const ScrewMotion s = screwFromTransform(t);
    const auto composed = composedPowers(t, 25);
    for (int k = 0; k <= 25; ++k)
      expectPoseNear(s.pose(k), composed[k], 1e-9, "pan " + std::to_string(c.pan) + " k " + std::to_string(k));
    if (s.pure_translation) {
      EXPECT_EQ(c.pan, 0.0);
      EXPECT_NEAR(s.pitch_per_step_m, c.baseline, 1e-12);  // parallel cameras: a straight line
      continue;
    }
    // The camera centres lie on the cylinder: at the radius from the axis, rising by the pitch each step.
    for (int k = 0; k <= 25; ++k) {
      const Eigen::Vector3d p = composed[k].translation() - s.axis_point;
      EXPECT_NEAR((p - p.dot(s.axis) * s.axis).norm(), s.radius_m, 1e-9);
      EXPECT_NEAR(p.dot(s.axis), k * s.pitch_per_step_m, 1e-9);
    }
    EXPECT_NEAR(s.u.dot(s.v), 0.0, 1e-12);
    EXPECT_NEAR(s.u.cross(s.v).dot(s.axis), 1.0, 1e-12);  // direct trihedron
    if (c.tilt == 0.0) {
      // Pan only: a circle of radius b / (2 sin(pan / 2)), turning by the pan each step, about the camera's y axis.
      EXPECT_NEAR(s.pitch_per_step_m, 0.0, 1e-12);
      EXPECT_NEAR(s.radius_m, c.baseline / (2.0 * std::sin(std::abs(c.pan) / 2.0)), 1e-12);
      EXPECT_NEAR(s.angle_per_step_rad, std::abs(c.pan), 1e-12);
      EXPECT_NEAR(std::abs(s.axis.y()), 1.0, 1e-12);
    } else {
      EXPECT_GT(std::abs(s.pitch_per_step_m), 1e-3);  // pan and tilt: a helix
    }
  }
  // The report's rig: 0.3 m, 18 deg: about 0.96 m from the axis, 20 servoings for a full turn.
  const ScrewMotion s = screwFromTransform(RigGeometry().leftFromRight());
  EXPECT_NEAR(s.radius_m, 0.959, 1e-3);
  EXPECT_NEAR(2 * M_PI / s.angle_per_step_rad, 20.0, 1e-4);
}

TEST(ServoPlanner, QuarterCirclesWithUTurnsCoverTheHeight) {
  AcquisitionPlanConfig c;
  c.object_base_m = Eigen::Vector3d(0.5, -0.2, 0.0);
  c.object_height_m = 0.3;
  c.distance_m = 0.96;
  c.start_height_m = 0.05;
  c.end_height_m = 0.25;
  AcquisitionPlan plan;
  ASSERT_EQ(planAcquisition(c, &plan), "");
  ASSERT_EQ(plan.legs.size(), 3u);
  const int steps = plan.legs[0].steps;
  EXPECT_EQ(steps, 5);  // 90 deg / ~18 deg
  EXPECT_EQ(plan.poses.size(), static_cast<size_t>(1 + 3 * steps));
  EXPECT_NEAR(plan.rise_per_step_m, 0.2 / 15, 1e-12);
  EXPECT_GT(plan.tilt_rad, 0.0);
  double prev_height = -1.0, prev_azimuth = 0.0;
  for (size_t i = 0; i < plan.poses.size(); ++i) {
    const Eigen::Vector3d centre = plan.poses[i].translation() - c.object_base_m;
    // On the cylinder around the object's axis, at the planned height.
    EXPECT_NEAR(centre.head<2>().norm(), c.distance_m, 1e-9) << i;
    EXPECT_NEAR(centre.z(), c.start_height_m + i * plan.rise_per_step_m, 1e-9) << i;
    EXPECT_GT(centre.z(), prev_height);
    prev_height = centre.z();
    // Looking at the object: the optical axis points within 15 deg of the axis, horizontally.
    Eigen::Vector3d look = plan.poses[i].linear().col(2);
    Eigen::Vector3d to_axis = -centre;
    look.z() = to_axis.z() = 0.0;
    EXPECT_GT(look.normalized().dot(to_axis.normalized()), std::cos(deg(15))) << i;
    // Azimuth goes forwards on even legs and backwards on odd ones (the U-turns).
    const double azimuth = std::atan2(centre.y(), centre.x());
    if (i > 0) {
      const int leg = plan.pose_leg[i];
      EXPECT_NEAR(azimuth - prev_azimuth, (leg % 2 == 0 ? 1 : -1) * plan.angle_per_step_rad, 1e-9) << i;
    }
    prev_azimuth = azimuth;
  }
  // Each leg is its rig transform repeated, and the U-turn rolls the camera by 180 deg in place.
  for (size_t l = 0; l < plan.legs.size(); ++l) {
    const auto composed = composedPowers(plan.legs[l].rig.leftFromRight(), steps);
    for (int k = (l == 0 ? 0 : 1); k <= steps; ++k)  // leg l's pose k is poses[l * steps + k]
      expectPoseNear(plan.legs[l].world_T_left_start * composed[k], plan.poses[l * steps + k], 1e-9,
                     "leg " + std::to_string(l) + " k " + std::to_string(k));
    if (l > 0) {
      const Eigen::Isometry3d end_prev = plan.poses[l * steps];
      const Eigen::Isometry3d start = plan.legs[l].world_T_left_start;
      EXPECT_LT((end_prev.translation() - start.translation()).norm(), 1e-9);
      EXPECT_NEAR(rotationAngleRad(end_prev.linear().transpose() * start.linear()), M_PI, deg(10));
      EXPECT_EQ(plan.legs[l].direction, -plan.legs[l - 1].direction);
      EXPECT_NEAR(plan.legs[l].rig.tilt_rad, -plan.legs[l - 1].rig.tilt_rad, 1e-12);
    }
  }
  // A radius the baseline cannot reach, and a bad config, are refused with a message.
  c.distance_m = 0.1;
  c.baseline_m = 0.3;
  EXPECT_NE(planAcquisition(c, &plan), "");
  c = AcquisitionPlanConfig();
  c.legs = 0;
  EXPECT_NE(planAcquisition(c, &plan).find("legs"), std::string::npos);
}

// Servoing the left camera to the right camera's pose, again and again, walks the rig along the predicted circle.
TEST(ServoRepeated, SimulatedServoingFollowsThePrediction) {
  sim::VentConfig vent;
  vent.points = 60;
  const auto points = sim::makeVentPoints(vent);
  RigGeometry rig;  // 0.3 m, 18 deg
  const ScrewMotion screw = screwFromTransform(rig.leftFromRight());
  const Eigen::Isometry3d start =
      alignScrewWithAxis(screw, Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitZ(), 0.0, 0.15);
  sim::PinholeCamera left, right;
  left.k = sim::intrinsics(800, 812, 322, 236);
  right.k = sim::intrinsics(905, 880, 301, 257, 1.5);
  control::ServoConfig servo;
  servo.convergence_threshold = 1e-7;
  servo.max_iterations = 100;
  sim::ServoSimConfig simc;
  simc.noise_px = 0.0;  // with 0.5 px noise each servoing ends ~20 mm off (see test_servo_control)
  std::vector<sim::ServoSimResult> results;
  const int rounds = 5;  // a quarter circle
  const auto poses =
      sim::simulateRepeatedServoing(points, left, right, rig.leftFromRight(), start, rounds, servo, simc, &results);
  ASSERT_EQ(poses.size(), static_cast<size_t>(rounds + 1));
  for (int k = 0; k <= rounds; ++k) {
    if (k > 0) {
      EXPECT_EQ(results[k - 1].status, control::ServoStatus::kConverged) << results[k - 1].message;
    }
    const Eigen::Isometry3d predicted = start * screw.pose(k);
    const sim::PoseError e = sim::poseError(poses[k], predicted);
    EXPECT_LT(e.position_mm, 1.0) << k;
    EXPECT_LT(e.rotation_deg, 0.05) << k;
    // And the camera stays on the cylinder around the object's axis.
    EXPECT_NEAR(poses[k].translation().head<2>().norm(), screw.radius_m, 1e-3) << k;
  }
}

}  // namespace
