// Tests of the arm (issue 6): DH kinematics and Jacobian against finite differences, inverse kinematics round trips
// and refusals, resolved-rate velocity scaling and joint-limit stops, the pre-programmed alternative (joint targets of
// the acquisition plan executed open loop), and the intrinsics-free servo closing the loop through the arm at point
// level (with the safety monitor watching, and a lost-tracking stop when the camera turns away).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "exocet_servo/control/invariant_servo.h"
#include "exocet_servo/control/servo_safety.h"
#include "exocet_servo/arm/arm_kinematics.h"
#include "exocet_servo/sim/arm_rig_simulator.h"
#include "exocet_servo/sim/point_scene.h"
#include "exocet_servo/trajectory/acquisition_planner.h"
#include "exocet_servo/trajectory/arm_inverse_kinematics.h"
#include "exocet_servo/trajectory/se3.h"

namespace {

using namespace exocet_servo;
using arm::JointVector;
using Vector6 = Eigen::Matrix<double, 6, 1>;

/// Random joint angles within the limits shrunk by `margin` rad.
JointVector randomJoints(const arm::ArmModel& arm, std::mt19937& rng, double margin) {
  JointVector q;
  for (int i = 0; i < arm::kArmJoints; ++i) {
    q(i) = std::uniform_real_distribution<double>(arm.minLimits()(i) + margin, arm.maxLimits()(i) - margin)(rng);
  }
  return q;
}

double positionDistance(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  return (a.translation() - b.translation()).norm();
}
double rotationDistance(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  return trajectory::rotationAngleRad(a.linear() * b.linear().transpose());
}

TEST(ServoArmKinematics, JacobianMatchesFiniteDifferences) {
  const arm::ArmModel arm(arm::ArmModel::defaultConfig());
  std::mt19937 rng(11);
  const double h = 1e-6;
  for (int k = 0; k < 30; ++k) {
    const JointVector q = randomJoints(arm, rng, 0.0);
    const arm::ArmJacobian jb = arm.jacobianBase(q);
    const arm::ArmJacobian jf = arm.jacobianFlange(q);
    const Eigen::Isometry3d t = arm.forward(q);
    for (int i = 0; i < arm::kArmJoints; ++i) {
      JointVector qp = q, qm = q;
      qp(i) += h;
      qm(i) -= h;
      const Eigen::Isometry3d tp = arm.forward(qp), tm = arm.forward(qm);
      // Base frame: velocity of the flange origin and angular velocity (R+ R-^T = exp([2 h omega]x)).
      Vector6 fd;
      fd.head<3>() = (tp.translation() - tm.translation()) / (2 * h);
      const Eigen::AngleAxisd aa(tp.linear() * tm.linear().transpose());
      fd.tail<3>() = aa.angle() * aa.axis() / (2 * h);
      EXPECT_LT((fd - jb.col(i)).norm(), 1e-7) << "base frame, joint " << i << ", sample " << k;
      // Flange frame: R^T times the origin velocity, and the relative rotation R-^T R+ in the flange frame.
      Vector6 fd_flange;
      fd_flange.head<3>() = t.linear().transpose() * fd.head<3>();
      const Eigen::AngleAxisd ab(tm.linear().transpose() * tp.linear());
      fd_flange.tail<3>() = ab.angle() * ab.axis() / (2 * h);
      EXPECT_LT((fd_flange - jf.col(i)).norm(), 1e-7) << "flange frame, joint " << i << ", sample " << k;
    }
  }
  // The frames chain to forward(), and the DH geometry gives the documented zero pose: upper arm along +x, forearm
  // and flange axis straight down.
  const JointVector zero = JointVector::Zero();
  const Eigen::Isometry3d f0 = arm.forward(zero);
  EXPECT_LT((f0.translation() - Eigen::Vector3d(0.75, 0.0, 0.25 - 0.50 - 0.12)).norm(), 1e-12);
  EXPECT_LT((f0.linear().col(2) - Eigen::Vector3d(0, 0, -1)).norm(), 1e-12);
  EXPECT_LT((arm.frames(zero).back().matrix() - f0.matrix()).norm(), 1e-15);
  EXPECT_NEAR(arm.reachBoundM(), 0.10 + 0.60 + std::hypot(0.05, 0.0) + 0.50 + 0.12, 1e-12);
}

TEST(ServoArmKinematics, ConfigValidationListsEveryBadField) {
  arm::ArmModelConfig c = arm::ArmModel::defaultConfig();
  EXPECT_EQ(c.validate(), "");
  c.joints[2].min_rad = 1.0;
  c.joints[2].max_rad = 0.5;
  c.joints[4].max_velocity_rad_s = 0.0;
  c.singular_threshold = -1.0;
  const std::string e = c.validate();
  EXPECT_NE(e.find("joints[2].min_rad, max_rad"), std::string::npos) << e;
  EXPECT_NE(e.find("joints[4].max_velocity_rad_s must be in (0, 100]"), std::string::npos) << e;
  EXPECT_NE(e.find("singular_threshold must be in (0, 1]"), std::string::npos) << e;
  EXPECT_THROW(arm::ArmModel{c}, std::invalid_argument);
}

TEST(ServoArmIk, ForwardInverseRoundTripOnRandomReachablePoses) {
  const arm::ArmModel arm(arm::ArmModel::defaultConfig());
  const sim::ArmRigConfig rig;
  std::mt19937 rng(5);
  trajectory::IkConfig near_seed;
  near_seed.restarts = 0;  // from a nearby seed the local solver alone must converge
  int total_iterations = 0;
  for (int k = 0; k < 200; ++k) {
    const JointVector q = randomJoints(arm, rng, 0.05);
    JointVector seed = q;
    for (int i = 0; i < arm::kArmJoints; ++i) seed(i) += std::uniform_real_distribution<double>(-0.3, 0.3)(rng);
    const Eigen::Isometry3d target = arm.forward(q);
    const trajectory::IkResult r = trajectory::solveFlangeIk(arm, target, seed, near_seed);
    ASSERT_EQ(r.status, trajectory::IkStatus::kConverged) << k << ": " << r.message;
    total_iterations += r.iterations;
    // Residuals measured here, not trusted from the solver.
    const Eigen::Isometry3d reached = arm.forward(r.q);
    EXPECT_LT(positionDistance(reached, target), 1e-6) << k;
    EXPECT_LT(rotationDistance(reached, target), 1e-6) << k;
    EXPECT_TRUE(arm.withinLimits(r.q)) << k;
    // The camera variant: the left camera's pose through flange_T_left.
    const Eigen::Isometry3d camera_target = target * rig.flange_T_left;
    const trajectory::IkResult rc = trajectory::solveCameraIk(arm, rig.flange_T_left, camera_target, seed, near_seed);
    ASSERT_EQ(rc.status, trajectory::IkStatus::kConverged) << k << ": " << rc.message;
    EXPECT_LT(positionDistance(arm.forward(rc.q) * rig.flange_T_left, camera_target), 1e-6) << k;
    EXPECT_LT(rotationDistance(arm.forward(rc.q) * rig.flange_T_left, camera_target), 1e-6) << k;
  }
  EXPECT_LT(total_iterations / 200.0, 20.0);  // Gauss-Newton speed near the solution

  // From arbitrary seeds the restarts find a solution almost always (997/1000 with 64 restarts, 963/1000 with 16,
  // 282/1000 with none).
  trajectory::IkConfig restarts;
  restarts.restarts = 64;
  int converged = 0;
  for (int k = 0; k < 100; ++k) {
    const JointVector q = randomJoints(arm, rng, 0.05);
    const trajectory::IkResult r =
        trajectory::solveFlangeIk(arm, arm.forward(q), randomJoints(arm, rng, 0.0), restarts);
    if (r.status != trajectory::IkStatus::kConverged) continue;
    ++converged;
    EXPECT_LT(positionDistance(arm.forward(r.q), arm.forward(q)), 1e-6);
  }
  EXPECT_GE(converged, 97);
}

TEST(ServoArmIk, UnreachableAndOutOfLimitTargetsAreRefused) {
  const arm::ArmModel arm(arm::ArmModel::defaultConfig());
  const JointVector seed = sim::ArmRigConfig::defaultJointAngles();
  // 3 m away: beyond the reach bound, refused without iterating.
  Eigen::Isometry3d far = arm.forward(seed);
  far.translation() = Eigen::Vector3d(3.0, 0.5, 0.0);
  const trajectory::IkResult r = trajectory::solveFlangeIk(arm, far, seed);
  EXPECT_EQ(r.status, trajectory::IkStatus::kUnreachable);
  EXPECT_NE(r.message.find("beyond the arm's reach"), std::string::npos) << r.message;
  EXPECT_EQ(r.iterations, 0);
  EXPECT_GT(r.position_residual_m, 1.0);
  EXPECT_EQ(trajectory::toString(r.status), "unreachable");

  // Within the bound but out of the dexterous workspace: the wrist centre 1.13 m from the shoulder pitch axis (its
  // reach is 1.10 m).
  Eigen::Isometry3d stretched = Eigen::Isometry3d::Identity();
  stretched.linear() = Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitY()).toRotationMatrix();  // flange z = +x
  stretched.translation() = Eigen::Vector3d(0.1 + 1.13 + 0.12, 0.0, 0.25);
  ASSERT_LT((stretched.translation() - arm.shoulderPointM()).norm(), arm.reachBoundM());
  const trajectory::IkResult rs = trajectory::solveFlangeIk(arm, stretched, seed);
  EXPECT_EQ(rs.status, trajectory::IkStatus::kUnreachable) << rs.message;
  EXPECT_GT(rs.position_residual_m, 0.02);

  // A yaw that only exists beyond joint 1's limits: kJointLimits naming joint 1.
  arm::ArmModelConfig narrow = arm::ArmModel::defaultConfig();
  narrow.joints[0].min_rad = -0.5;
  narrow.joints[0].max_rad = 0.5;
  const arm::ArmModel narrow_arm(narrow);
  JointVector q = seed;
  q(0) = 1.0;
  const trajectory::IkResult rl = trajectory::solveFlangeIk(narrow_arm, arm.forward(q), seed);
  EXPECT_EQ(rl.status, trajectory::IkStatus::kJointLimits) << rl.message;
  EXPECT_NE(rl.message.find("joint 1 (shoulder yaw) on its upper limit"), std::string::npos) << rl.message;
  EXPECT_TRUE(narrow_arm.withinLimits(rl.q));
}

TEST(ServoArmResolvedRate, KeepsTheTwistDirectionAndRespectsVelocityLimits) {
  const arm::ArmModel arm(arm::ArmModel::defaultConfig());
  const JointVector q = sim::ArmRigConfig::defaultJointAngles();
  const arm::ArmJacobian j = arm.jacobianFlange(q);
  // A slow twist is executed exactly.
  Vector6 slow;
  slow << 0.01, -0.02, 0.015, 0.02, -0.01, 0.03;
  const arm::ResolvedRate rs = arm.resolvedRate(q, slow, 0.1);
  EXPECT_EQ(rs.status, arm::ArmStatus::kOk) << rs.message;
  EXPECT_LT((j * rs.joint_velocities_rad_s - slow).norm(), 1e-12);
  EXPECT_DOUBLE_EQ(rs.scale, 1.0);
  // A fast one is scaled uniformly: the same direction, every joint within its limit, one of them on it.
  std::mt19937 rng(3);
  for (int k = 0; k < 50; ++k) {
    Vector6 fast;
    for (int i = 0; i < 6; ++i) fast(i) = std::uniform_real_distribution<double>(-1.0, 1.0)(rng);
    const arm::ResolvedRate r = arm.resolvedRate(q, fast, 0.05);
    ASSERT_EQ(r.status, arm::ArmStatus::kVelocityScaled) << k << ": " << r.message;
    EXPECT_LT(r.scale, 1.0);
    const Vector6 achieved = j * r.joint_velocities_rad_s;
    EXPECT_LT((achieved - r.scale * fast).norm(), 1e-9 * fast.norm()) << k;
    EXPECT_GT(achieved.dot(fast), 0.0);
    const JointVector ratio = r.joint_velocities_rad_s.cwiseAbs().cwiseQuotient(arm.maxVelocities());
    EXPECT_LE(ratio.maxCoeff(), 1.0 + 1e-12) << k;
    EXPECT_NEAR(ratio.maxCoeff(), 1.0, 1e-12) << k;
    EXPECT_NEAR(ratio(r.limiting_joint), 1.0, 1e-12) << k;
  }
  // Near a singularity (wrist pitch 0: forearm and flange roll axes aligned) the solution is damped and says so.
  JointVector qs = q;
  qs(4) = 1e-4;
  const arm::ResolvedRate rsing = arm.resolvedRate(qs, slow, 0.1);
  EXPECT_EQ(rsing.status, arm::ArmStatus::kSingular) << rsing.message;
  EXPECT_LT(rsing.min_singular_value, arm.config().singular_threshold);
  EXPECT_TRUE(rsing.joint_velocities_rad_s.allFinite());
  EXPECT_LE(rsing.joint_velocities_rad_s.cwiseAbs().cwiseQuotient(arm.maxVelocities()).maxCoeff(), 1.0 + 1e-12);
  // Corrupt input: no motion.
  Vector6 bad = slow;
  bad(2) = std::nan("");
  const arm::ResolvedRate rb = arm.resolvedRate(q, bad, 0.1);
  EXPECT_EQ(rb.status, arm::ArmStatus::kInvalidInput);
  EXPECT_TRUE(rb.joint_velocities_rad_s.isZero());
}

TEST(ServoArmResolvedRate, AJointDrivenIntoItsLimitStopsTheMotionNamingIt) {
  const arm::ArmModel arm(arm::ArmModel::defaultConfig());
  JointVector q = sim::ArmRigConfig::defaultJointAngles();
  const double dt = 0.1;
  // The flange twist that turns the wrist pitch alone, towards its lower limit (-135 deg), re-evaluated each step.
  int steps = 0;
  arm::ResolvedRate r;
  for (; steps < 200; ++steps) {
    JointVector unit = JointVector::Zero();
    unit(4) = -0.8;
    r = arm.resolvedRate(q, arm.jacobianFlange(q) * unit, dt);
    if (r.status == arm::ArmStatus::kJointLimit) break;
    ASSERT_TRUE(r.status == arm::ArmStatus::kOk) << r.message;
    q += r.joint_velocities_rad_s * dt;
    ASSERT_GE(q(4), arm.minLimits()(4)) << "crossed the limit";
  }
  ASSERT_EQ(r.status, arm::ArmStatus::kJointLimit);
  EXPECT_EQ(r.limiting_joint, 4);
  EXPECT_TRUE(r.joint_velocities_rad_s.isZero());
  EXPECT_NE(r.message.find("joint 5 (wrist pitch) would cross its lower limit -2.3562 rad (-135.0 deg)"),
            std::string::npos)
      << r.message;
  // It stopped at the last step that still fitted: less than one step (0.08 rad) from the limit.
  EXPECT_LT(q(4) - arm.minLimits()(4), 0.08 + 1e-9);
  const double start = sim::ArmRigConfig::defaultJointAngles()(4);
  EXPECT_EQ(steps, static_cast<int>(std::floor((start - arm.minLimits()(4)) / 0.08 + 1e-9)));
  // Moving away from the limit is allowed again.
  JointVector away = JointVector::Zero();
  away(4) = 0.5;
  EXPECT_NE(arm.resolvedRate(q, arm.jacobianFlange(q) * away, dt).status, arm::ArmStatus::kJointLimit);
}

TEST(ServoArmRig, CommandsMoveTheLeftCameraAndBothCamerasSeeTheVent) {
  sim::ArmRigSimulator sim{sim::ArmRigConfig()};
  const sim::ArmRigConfig& c = sim.config();
  // Default start as documented: left camera at (0.7, 0, -0.05) looking along +x at the vent's axis.
  const Eigen::Isometry3d start = sim.worldFromLeft();
  EXPECT_LT(positionDistance(start, sim::lookAt({0.7, 0, -0.05}, {1.3, 0, -0.05})), 1e-8);
  EXPECT_LT(rotationDistance(start, sim::lookAt({0.7, 0, -0.05}, {1.3, 0, -0.05})), 1e-8);
  EXPECT_LT((sim.worldFromRight().matrix() - (start * c.rig.leftFromRight()).matrix()).norm(), 1e-12);
  // A small camera twist: the camera moves as the exponential map predicts, to first order in dt.
  Vector6 twist;
  twist << 0.02, -0.01, 0.03, 0.05, -0.04, 0.02;
  for (double dt : {0.02, 0.01}) {
    sim.setJointPositions(c.q_initial);
    const arm::ResolvedRate r = sim.command(twist, dt);
    EXPECT_EQ(r.status, arm::ArmStatus::kOk) << r.message;
    const Eigen::Isometry3d predicted = start * trajectory::expSe3(twist * dt);
    EXPECT_LT(positionDistance(sim.worldFromLeft(), predicted), 0.5 * dt * dt) << dt;
    EXPECT_LT(rotationDistance(sim.worldFromLeft(), predicted), 2.0 * dt * dt) << dt;
    EXPECT_GT(positionDistance(sim.worldFromLeft(), start), 0.5 * twist.head<3>().norm() * dt);
    EXPECT_LT((sim.jointVelocities() - r.joint_velocities_rad_s).norm(), 1e-15);
  }
  EXPECT_THROW(sim.setJointPositions(JointVector::Constant(4.0)), std::invalid_argument);
  sim.setJointPositions(c.q_initial);
  const sim::StereoViews views = sim.render();
  ASSERT_EQ(views.left.image.cols, c.left_camera.width_px);
  ASSERT_EQ(views.right.image.rows, c.right_camera.height_px);
  // The left camera sees the vent's axis at the image centre 0.5 m away (0.6 m to the axis minus the radius ~0.1).
  const float centre_depth = views.left.depth_m.at<float>(c.left_camera.height_px / 2, c.left_camera.width_px / 2);
  EXPECT_GT(centre_depth, 0.45);
  EXPECT_LT(centre_depth, 0.56);
  // The right camera sees the vent too (toe-in): the axis at mid-height projects inside its image onto the chimney.
  const sim::Projection axis = sim::project(c.right_camera, sim.worldFromRight(), {Eigen::Vector3d(1.3, 0.0, -0.05)});
  const Eigen::Vector2d px = axis.points_px[0];
  EXPECT_GT(px.x(), 0.0);
  EXPECT_LT(px.x(), c.right_camera.width_px);
  sim::SurfaceKind kind = sim::SurfaceKind::kNone;
  sim.renderer().depthAt(c.right_camera, sim.worldFromRight(), px, &kind);
  EXPECT_EQ(kind, sim::SurfaceKind::kChimney);
  // The two images differ in content (different poses and intrinsics), and neither is blank.
  cv::Scalar mean_l, std_l, mean_r, std_r;
  cv::meanStdDev(views.left.image, mean_l, std_l);
  cv::meanStdDev(views.right.image, mean_r, std_r);
  EXPECT_GT(std_l[0], 5.0);
  EXPECT_GT(std_r[0], 5.0);
}

TEST(ServoArmPlan, JointTargetsOfTheAcquisitionPlanExecutedOpenLoopReachEachPose) {
  sim::ArmRigSimulator sim{sim::ArmRigConfig()};
  const sim::ArmRigConfig& c = sim.config();
  // Three 60 deg legs centred on azimuth 180 deg (facing the arm) at 0.6 m over the vent's height, U-turns included.
  trajectory::AcquisitionPlanConfig pc;
  pc.object_base_m = c.scene.base_m;
  pc.object_height_m = c.scene.height_m;
  pc.object_radius_m = c.scene.base_radius_m;
  pc.distance_m = 0.6;
  pc.baseline_m = c.rig.baseline_m;
  pc.legs = 3;
  pc.leg_arc_rad = M_PI / 3;
  pc.start_azimuth_rad = M_PI - M_PI / 6;
  trajectory::AcquisitionPlan plan;
  ASSERT_EQ(trajectory::planAcquisition(pc, &plan), "");
  ASSERT_GE(plan.poses.size(), 6u);
  const std::vector<trajectory::IkResult> targets =
      trajectory::planJointTargets(sim.arm(), c.flange_T_left, plan.poses, c.q_initial);
  ASSERT_EQ(targets.size(), plan.poses.size());
  const double dt = 0.1;
  int total_steps = 0;
  for (size_t i = 0; i < targets.size(); ++i) {
    ASSERT_EQ(targets[i].status, trajectory::IkStatus::kConverged) << targets[i].message;
    // Open loop: straight joint-space motion at the velocity limits, no camera feedback.
    bool arrived = false;
    for (int step = 0; step < 1000 && !arrived; ++step, ++total_steps) {
      arm::ArmStatus status = arm::ArmStatus::kOk;
      std::string message;
      arrived = sim.stepTowards(targets[i].q, dt, &status, &message);
      ASSERT_TRUE(status == arm::ArmStatus::kOk || status == arm::ArmStatus::kVelocityScaled) << message;
      EXPECT_LE(sim.jointVelocities().cwiseAbs().cwiseQuotient(sim.arm().maxVelocities()).maxCoeff(), 1.0 + 1e-12);
      ASSERT_TRUE(sim.arm().withinLimits(sim.jointPositions(), 1e-12));
    }
    ASSERT_TRUE(arrived) << "pose " << i;
    EXPECT_LT(positionDistance(sim.worldFromLeft(), plan.poses[i]), 1e-6) << "pose " << i;
    EXPECT_LT(rotationDistance(sim.worldFromLeft(), plan.poses[i]), 1e-6) << "pose " << i;
    // The right camera then sits where the next servoing would take the left one (the rig transform of the plan).
    if (i + 1 < plan.poses.size() && plan.pose_leg[i + 1] == plan.pose_leg[i]) {
      EXPECT_LT(positionDistance(sim.worldFromRight(), plan.poses[i + 1]), 1e-6) << "pose " << i;
    }
  }
  EXPECT_GT(total_steps, static_cast<int>(targets.size()));  // the moves took time: the velocity limits acted
  // Legs of 90 deg at 0.7 m reach beyond the wrist's 1.10 m: their far ends are refused by name, the rest solved.
  pc.leg_arc_rad = M_PI / 2;
  pc.start_azimuth_rad = M_PI - M_PI / 4;
  pc.distance_m = 0.7;
  trajectory::AcquisitionPlan wide;
  ASSERT_EQ(trajectory::planAcquisition(pc, &wide), "");
  const std::vector<trajectory::IkResult> wide_targets =
      trajectory::planJointTargets(sim.arm(), c.flange_T_left, wide.poses, c.q_initial);
  int refused = 0;
  for (size_t i = 0; i < wide_targets.size(); ++i) {
    const trajectory::IkResult& r = wide_targets[i];
    if (r.status == trajectory::IkStatus::kConverged) {
      EXPECT_LT(positionDistance(sim.worldFromLeftAt(r.q), wide.poses[i]), 1e-6) << i;
      continue;
    }
    ++refused;
    EXPECT_EQ(r.message.rfind("pose " + std::to_string(i) + ": ", 0), 0u) << r.message;
    EXPECT_GT(r.position_residual_m, 1e-3) << r.message;
  }
  EXPECT_GE(refused, 1);
  EXPECT_LE(refused, static_cast<int>(wide_targets.size()) / 2);
  // A target outside the limits is refused without motion.
  const JointVector before = sim.jointPositions();
  JointVector outside = before;
  outside(1) = 3.0;
  arm::ArmStatus status = arm::ArmStatus::kOk;
  std::string message;
  EXPECT_FALSE(sim.stepTowards(outside, dt, &status, &message));
  EXPECT_EQ(status, arm::ArmStatus::kJointLimit);
  EXPECT_NE(message.find("joint 2 (shoulder pitch)"), std::string::npos) << message;
  EXPECT_EQ(sim.jointPositions(), before);
}

/// Vent points of the point-level loop, on the rendered scene's chimney.
std::vector<Eigen::Vector3d> ventPoints(const sim::ArmRigConfig& c) {
  sim::VentConfig v;
  v.base_m = c.scene.base_m;
  v.height_m = c.scene.height_m;
  v.base_radius_m = c.scene.base_radius_m;
  v.top_radius_m = c.scene.top_radius_m;
  v.points = 80;
  return sim::makeVentPoints(v);
}

/// Points of `projection` inside the image (the "tracked" ones).
int visiblePoints(const sim::PinholeCamera& camera, const sim::Projection& projection) {
  int n = 0;
  for (size_t i = 0; i < projection.points_px.size(); ++i) {
    const Eigen::Vector2d& p = projection.points_px[i];
    if (p.allFinite() && projection.depths_m[i] > 0.0 && p.x() >= 0.0 && p.y() >= 0.0 && p.x() < camera.width_px &&
        p.y() < camera.height_px) {
      ++n;
    }
  }
  return n;
}

TEST(ServoArmLoop, InvariantServoThroughTheArmReachesTheRightCameraPose) {
  sim::ArmRigSimulator sim{sim::ArmRigConfig()};
  const sim::ArmRigConfig& c = sim.config();
  const std::vector<Eigen::Vector3d> points = ventPoints(c);
  // Reference: the right camera's image at the start; the left camera must servo to that pose through the arm.
  const Eigen::Isometry3d goal = sim.worldFromRight();
  control::ServoConfig sc;
  sc.gain = control::AdaptiveGain::constant(1.0);  // 1/s; with dt = 0.1 s, 10 % of the error per iteration
  sc.max_iterations = 400;
  sc.image_width_px = c.left_camera.width_px;
  sc.image_height_px = c.left_camera.height_px;
  control::InvariantServo servo(sc);
  const sim::Projection ref = sim::project(c.right_camera, goal, points);
  ASSERT_EQ(visiblePoints(c.right_camera, ref), static_cast<int>(points.size()));
  ASSERT_EQ(servo.setReference(ref.points_px, c.right_camera.k, ref.depths_m), "");
  control::ServoSafetyConfig safety_config;
  safety_config.workspace_min_m = Eigen::Vector3d(0.2, -0.6, -0.15);  // above the seabed, in front of the arm
  safety_config.workspace_max_m = Eigen::Vector3d(1.1, 0.6, 0.6);
  control::ServoSafetyMonitor safety(safety_config);
  const double dt = 0.1;
  control::ServoStep step;
  int scaled = 0;
  for (int it = 0; it < 400; ++it) {
    const sim::Projection cur = sim::project(c.left_camera, sim.worldFromLeft(), points);
    step = servo.step(cur.points_px, c.left_camera.k, cur.depths_m);
    if (step.status != control::ServoStatus::kRunning) break;
    const arm::ResolvedRate r = sim.command(step.velocity, dt);
    scaled += r.status == arm::ArmStatus::kVelocityScaled;
    control::SafetyInput in;
    in.tracked_points = visiblePoints(c.left_camera, cur);
    in.error_norm = step.error_norm;
    in.camera_position_m = sim.worldFromLeft().translation();
    in.arm_status = r.status;
    in.arm_message = r.message;
    ASSERT_EQ(safety.update(in), control::SafetyStatus::kOk) << safety.message();
  }
  ASSERT_EQ(step.status, control::ServoStatus::kConverged) << step.message;
  const sim::PoseError e = sim::poseError(sim.worldFromLeft(), goal);
  EXPECT_LT(e.position_mm, 0.5);
  EXPECT_LT(e.rotation_deg, 0.05);
  EXPECT_TRUE(sim.arm().withinLimits(sim.jointPositions()));
  RecordProperty("iterations", step.iteration);
  RecordProperty("velocity_scaled_iterations", scaled);
  std::printf("arm loop: converged in %d iterations (%d velocity-scaled), final error %.3f mm / %.4f deg\n",
              step.iteration, scaled, e.position_mm, e.rotation_deg);
}

TEST(ServoArmLoop, TurningAwayFromTheVentStopsOnLostTracking) {
  sim::ArmRigSimulator sim{sim::ArmRigConfig()};
  const sim::ArmRigConfig& c = sim.config();
  const std::vector<Eigen::Vector3d> points = ventPoints(c);
  control::ServoSafetyConfig safety_config;
  safety_config.min_tracked_points = 20;
  control::ServoSafetyMonitor safety(safety_config);
  // A faulty command: pan the camera away (rotation about its y axis), the points leave the image.
  Vector6 twist = Vector6::Zero();
  twist(4) = 0.3;
  int iterations = 0;
  int last_visible = 0;
  for (; iterations < 100; ++iterations) {
    const sim::Projection cur = sim::project(c.left_camera, sim.worldFromLeft(), points);
    control::SafetyInput in;
    in.tracked_points = last_visible = visiblePoints(c.left_camera, cur);
    in.error_norm = 0.1;
    in.camera_position_m = sim.worldFromLeft().translation();
    if (safety.update(in) != control::SafetyStatus::kOk) break;
    const arm::ResolvedRate r = sim.command(twist, 0.1);
    ASSERT_NE(r.status, arm::ArmStatus::kJointLimit) << r.message;
  }
  EXPECT_EQ(safety.status(), control::SafetyStatus::kLostTracking) << safety.message();
  EXPECT_LT(last_visible, 20);
  EXPECT_GT(iterations, 1);  // the vent was in view at first
  EXPECT_NE(safety.message().find(std::to_string(last_visible) + " tracked points < 20"), std::string::npos)
      << safety.message();
  // The monitor latches: a later good iteration does not resume the motion.
  control::SafetyInput good;
  good.tracked_points = 80;
  good.error_norm = 0.1;
  good.camera_position_m = sim.worldFromLeft().translation();
  EXPECT_EQ(safety.update(good), control::SafetyStatus::kLostTracking);
}

}  // namespace
