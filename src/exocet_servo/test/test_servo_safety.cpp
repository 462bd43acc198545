// Tests of the servo safety monitor (issue 6): each stop triggers with its status and a clear message on a scripted
// sequence of iterations, the stops latch until reset(), and a normal converging sequence (noisy, decaying error,
// slowly shrinking point set, camera moving inside the workspace) never stops.
#include <cmath>
#include <random>
#include <string>

#include <gtest/gtest.h>

#include "exocet_servo/control/servo_safety.h"

namespace {

using namespace exocet_servo;
using control::SafetyInput;
using control::SafetyStatus;
using control::ServoSafetyConfig;
using control::ServoSafetyMonitor;

/// A healthy iteration: 60 points, the given error, the camera 0.6 m in front of the origin.
SafetyInput healthy(double error_norm, const Eigen::Vector3d& position = Eigen::Vector3d(0.6, 0.0, 0.0)) {
  SafetyInput in;
  in.tracked_points = 60;
  in.error_norm = error_norm;
  in.camera_position_m = position;
  return in;
}

bool contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

TEST(ServoSafety, NormalConvergingSequenceNeverStops) {
  ServoSafetyConfig config;
  config.workspace_centre_m = Eigen::Vector3d(1.0, 0.0, 0.0);
  config.workspace_radius_m = 0.8;
  ServoSafetyMonitor monitor(config);
  std::mt19937 rng(4);
  std::uniform_real_distribution<double> wobble(0.7, 1.3);  // noisy |e|: +-30 % around the decay
  for (int it = 0; it < 300; ++it) {
    SafetyInput in;
    in.tracked_points = 80 - it / 10;  // tracks lost slowly: 51 left at the end
    in.error_norm = std::max(1e-4, 0.5 * std::exp(-0.05 * it)) * wobble(rng);
    in.camera_position_m = Eigen::Vector3d(0.4 + 0.3 * it / 300.0, 0.1 * std::sin(0.05 * it), 0.05);
    in.arm_status = it % 7 == 0 ? arm::ArmStatus::kVelocityScaled : arm::ArmStatus::kOk;
    // A singular warning does not stop by default (the arm damps the motion).
    if (it == 150) in.arm_status = arm::ArmStatus::kSingular;
    ASSERT_EQ(monitor.update(in), SafetyStatus::kOk) << "iteration " << it << ": " << monitor.message();
  }
  EXPECT_FALSE(monitor.stopped());
  EXPECT_EQ(monitor.message(), "");
  EXPECT_EQ(monitor.iterations(), 300);
  EXPECT_LT(monitor.minErrorNorm(), 2e-4);
}

TEST(ServoSafety, TooFewTrackedPointsStopsOnLostTracking) {
  ServoSafetyMonitor monitor{ServoSafetyConfig()};
  int counts[] = {60, 52, 41, 30, 19, 12, 8, 5, 3};
  int it = 0;
  for (int n : counts) {
    SafetyInput in = healthy(0.1);
    in.tracked_points = n;
    const SafetyStatus s = monitor.update(in);
    ++it;
    if (n >= 8) {
      ASSERT_EQ(s, SafetyStatus::kOk) << n;
    } else {
      ASSERT_EQ(s, SafetyStatus::kLostTracking);
      break;
    }
  }
  EXPECT_EQ(it, 8);  // the first count below 8
  EXPECT_EQ(monitor.message(), "lost tracking: 5 tracked points < 8 at iteration 8");
  EXPECT_EQ(control::toString(monitor.status()), "lost tracking");
}

TEST(ServoSafety, GrowingErrorStopsAfterTheConsecutiveIterationsButNotOnATransient) {
  ServoSafetyConfig config;
  config.growth_factor = 2.0;
  config.growth_iterations = 5;
  ServoSafetyMonitor monitor(config);
  // Decay to 0.1, then a 4-iteration spike above 2 x 0.1 (one short of the count), back down: no stop.
  for (double e : {0.8, 0.4, 0.2, 0.1, 0.25, 0.3, 0.35, 0.3, 0.15, 0.12}) {
    ASSERT_EQ(monitor.update(healthy(e)), SafetyStatus::kOk) << e << ": " << monitor.message();
  }
  EXPECT_DOUBLE_EQ(monitor.minErrorNorm(), 0.1);
  // Divergence: above 0.2 from here on; the 5th consecutive iteration stops.
  int it = 0;
  for (double e : {0.21, 0.3, 0.5, 0.8, 1.3, 2.0}) {
    ++it;
    if (monitor.update(healthy(e)) != SafetyStatus::kOk) break;
  }
  EXPECT_EQ(it, 5);
  EXPECT_EQ(monitor.status(), SafetyStatus::kErrorGrowing);
  EXPECT_TRUE(contains(monitor.message(), "error growing: |e| = 1.3 > 2 x its minimum 0.1 for 5 consecutive"))
      << monitor.message();
}

TEST(ServoSafety, NoiseBelowTheGrowthFloorIsNotAGrowthButADivergenceAboveItIs) {
  ServoSafetyConfig config;
  config.growth_factor = 10.0;
  config.growth_iterations = 10;
  config.growth_floor = 0.003;
  ServoSafetyMonitor monitor(config);
  // Near the goal |e| is the measurement's noise (1e-3 .. 3e-3, as the re-anchored points give): one lucky sample
  // of 2e-4 makes every later one look 10 x larger. 30 such images are no growth.
  for (double e : {0.4, 0.05, 0.004, 0.0002}) ASSERT_EQ(monitor.update(healthy(e)), SafetyStatus::kOk);
  for (int i = 0; i < 30; ++i) {
    const double e = i % 3 == 0 ? 0.003 : 0.0012 + 0.0005 * (i % 2);
    ASSERT_EQ(monitor.update(healthy(e)), SafetyStatus::kOk) << i << ": " << monitor.message();
  }
  // Leaving the goal for real (above the floor and 10 x the minimum): stops after the 10th image.
  int it = 0;
  while (monitor.update(healthy(0.004 * (1.0 + 0.1 * it))) == SafetyStatus::kOk && it < 100) ++it;
  EXPECT_EQ(it + 1, 10);
  EXPECT_EQ(monitor.status(), SafetyStatus::kErrorGrowing);
  // Without the floor the noise alone stops it.
  config.growth_floor = 0.0;
  ServoSafetyMonitor strict(config);
  for (double e : {0.4, 0.05, 0.004, 0.0002}) ASSERT_EQ(strict.update(healthy(e)), SafetyStatus::kOk);
  int noisy = 0;
  while (strict.update(healthy(0.0025)) == SafetyStatus::kOk && noisy < 100) ++noisy;
  EXPECT_EQ(strict.status(), SafetyStatus::kErrorGrowing);
}

TEST(ServoSafety, LeavingTheWorkspaceBoxOrSphereStops) {
  ServoSafetyConfig config;
  config.workspace_min_m = Eigen::Vector3d(0.0, -0.5, -0.3);
  config.workspace_max_m = Eigen::Vector3d(1.0, 0.5, 0.5);
  {
    ServoSafetyMonitor monitor(config);
    // The camera drifts down 7 cm per iteration from z = 0: the box floor -0.3 is crossed at z = -0.35.
    int it = 0;
    for (; it < 20; ++it) {
      if (monitor.update(healthy(0.1, Eigen::Vector3d(0.5, 0.0, -0.07 * it))) != SafetyStatus::kOk) break;
    }
    EXPECT_EQ(it, 5);
    EXPECT_EQ(monitor.status(), SafetyStatus::kLeftWorkspace);
    EXPECT_TRUE(contains(monitor.message(), "its z = -0.35 m is outside the box [-0.3, 0.5] m")) << monitor.message();
  }
  {
    config.workspace_centre_m = Eigen::Vector3d(1.0, 0.0, 0.0);
    config.workspace_radius_m = 0.7;
    ServoSafetyMonitor monitor(config);
    EXPECT_EQ(monitor.update(healthy(0.1, Eigen::Vector3d(0.4, 0.0, 0.0))), SafetyStatus::kOk);
    EXPECT_EQ(monitor.update(healthy(0.1, Eigen::Vector3d(0.2, 0.0, 0.0))), SafetyStatus::kLeftWorkspace);
    EXPECT_TRUE(contains(monitor.message(), "0.8 m from the workspace centre")) << monitor.message();
    EXPECT_TRUE(contains(monitor.message(), "beyond its radius 0.7 m")) << monitor.message();
  }
}

TEST(ServoSafety, ArmJointLimitStopsQuotingTheArm) {
  ServoSafetyMonitor monitor{ServoSafetyConfig()};
  EXPECT_EQ(monitor.update(healthy(0.3)), SafetyStatus::kOk);
  SafetyInput in = healthy(0.2);
  in.arm_status = arm::ArmStatus::kJointLimit;
  in.arm_message = "joint 5 (wrist pitch) would cross its lower limit -2.3562 rad (-135.0 deg) within 0.1 s";
  EXPECT_EQ(monitor.update(in), SafetyStatus::kJointLimit);
  EXPECT_EQ(monitor.message(),
            "joint limit: joint 5 (wrist pitch) would cross its lower limit -2.3562 rad (-135.0 deg) within 0.1 s at "
            "iteration 2");
}

TEST(ServoSafety, SingularStopsOnlyWhenAsked) {
  ServoSafetyConfig config;
  config.stop_on_singular = true;
  ServoSafetyMonitor monitor(config);
  SafetyInput in = healthy(0.2);
  in.arm_status = arm::ArmStatus::kSingular;
  in.arm_message = "near a singularity";
  EXPECT_EQ(monitor.update(in), SafetyStatus::kSingular);
  EXPECT_TRUE(contains(monitor.message(), "singular: near a singularity")) << monitor.message();
}

TEST(ServoSafety, IterationBudgetStops) {
  ServoSafetyConfig config;
  config.max_iterations = 25;
  ServoSafetyMonitor monitor(config);
  int it = 0;
  while (monitor.update(healthy(0.1)) == SafetyStatus::kOk && it < 100) ++it;
  EXPECT_EQ(it, 24);  // the 25th update stops
  EXPECT_EQ(monitor.status(), SafetyStatus::kMaxIterations);
  EXPECT_TRUE(contains(monitor.message(), "budget of 25 iterations spent")) << monitor.message();
}

TEST(ServoSafety, StopsLatchUntilResetAndBadInputStops) {
  ServoSafetyMonitor monitor{ServoSafetyConfig()};
  SafetyInput lost = healthy(0.1);
  lost.tracked_points = 2;
  EXPECT_EQ(monitor.update(lost), SafetyStatus::kLostTracking);
  const std::string message = monitor.message();
  // Later good iterations do not resume, nor count.
  EXPECT_EQ(monitor.update(healthy(0.05)), SafetyStatus::kLostTracking);
  EXPECT_EQ(monitor.message(), message);
  EXPECT_EQ(monitor.iterations(), 1);
  monitor.reset();
  EXPECT_FALSE(monitor.stopped());
  EXPECT_EQ(monitor.update(healthy(0.05)), SafetyStatus::kOk);
  EXPECT_EQ(monitor.update(healthy(std::nan(""))), SafetyStatus::kInvalidInput);
  EXPECT_TRUE(contains(monitor.message(), "error_norm finite")) << monitor.message();
  monitor.reset();
  SafetyInput refused = healthy(0.05);
  refused.arm_status = arm::ArmStatus::kInvalidInput;
  EXPECT_EQ(monitor.update(refused), SafetyStatus::kInvalidInput);
}

TEST(ServoSafety, ConfigValidationListsEveryBadField) {
  ServoSafetyConfig c;
  EXPECT_EQ(c.validate(), "");
  c.min_tracked_points = 3;
  c.growth_factor = 1.0;
  c.growth_iterations = 0;
  c.growth_floor = -1.0;
  c.workspace_max_m.x() = -5.0;
  c.workspace_radius_m = -1.0;
  c.max_iterations = 0;
  const std::string e = c.validate();
  for (const char* field :
       {"min_tracked_points must be in [4, 100000]", "growth_factor must be in (1, 1e6]",
        "growth_iterations must be in [1, 10000]", "growth_floor must be in [0, 1]", "workspace_min_m, workspace_max_m",
        "workspace_radius_m must be in [0, 1000]", "max_iterations must be in [1, 10000000]"}) {
    EXPECT_TRUE(contains(e, field)) << field << " missing from: " << e;
  }
  EXPECT_THROW(ServoSafetyMonitor{c}, std::invalid_argument);
}

}  // namespace
