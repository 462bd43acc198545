// Image-level closed loop through the arm: the servo node's computation without ROS. The right camera's rendered
// image is the reference (the report's step: the left camera, with other intrinsics, goes where the right one was,
// 0.3 m and 18 degrees away); each left image (rendered at the arm's current joint angles) gives one controller step
// whose velocity the arm executes by resolved rate for one period (4 Hz), clamped as the node does.
#include <cstdio>
#include <limits>
#include <vector>

#include <gtest/gtest.h>

#include "exocet_servo/control/image_servo_controller.h"
#include "exocet_servo/control/twist_limit.h"
#include "exocet_servo/sim/arm_rig_simulator.h"
#include "exocet_servo/sim/image_servo_loop.h"
#include "exocet_servo/sim/pose_bound.h"
#include "exocet_servo/sim/servo_simulation.h"

namespace exocet_servo {
namespace {

control::DepthLookup lookupIn(const sim::RenderedView& view, const control::ImageServoConfig& config) {
  return [&view, &config](const Eigen::Vector2d& px) {
    double d = 0.0;
    return view.smoothDepthAt(px, config.depth_check_radius_px, config.depth_max_relative_step, &d)
               ? d
               : std::numeric_limits<double>::quiet_NaN();
  };
}

TEST(ServoArmImageLoop, LeftCameraReachesTheRightCamerasPoseThroughTheArm) {
  sim::ArmRigConfig rig;
  rig.scene.supersampling = 2;
  sim::ArmRigSimulator sim(rig);
  const Eigen::Isometry3d goal = sim.worldFromRight();
  const sim::StereoViews first = sim.render();
  control::ImageServoConfig config;
  config.servo.gain = control::AdaptiveGain{2.0, 1.0, 4.0};  // per second, as the node
  config.matcher.ratio = 0.6;  // as the node: fewer, surer pairs across the rig's baseline
  const double dt = 0.25;
  control::ImageServoController controller(config, rig.right_camera.k, rig.left_camera.k, rig.left_camera.width_px,
                                           rig.left_camera.height_px);
  ASSERT_EQ(controller.setReference(first.right.image, lookupIn(first.right, config)), "");
  control::ImageStep step;
  int it = 0;
  for (; it < 300; ++it) {
    const sim::StereoViews views = sim.render();
    step = controller.step(views.left.image, lookupIn(views.left, config));
    const sim::PoseError e = sim::poseError(sim.worldFromLeft(), goal);
    if (it % 10 == 0)
      std::printf("it %d: %s |e| %.5f points %d, pose error %.2f mm %.3f deg\n", it,
                  control::toString(step.status).c_str(), step.error_norm, step.points, e.position_mm, e.rotation_deg);
    if (step.status != control::ImageStepStatus::kRunning) break;
    const arm::ResolvedRate r = sim.command(control::limitTwist(step.velocity, 0.3, 1.0), dt);
    ASSERT_NE(r.status, arm::ArmStatus::kJointLimit) << r.message;
  }
  ASSERT_EQ(step.status, control::ImageStepStatus::kConverged) << step.message;
  const sim::PoseError e = sim::poseError(sim.worldFromLeft(), goal);
  std::printf("arm image loop: converged in %d images, %.3f mm, %.4f deg\n", it + 1, e.position_mm, e.rotation_deg);
  EXPECT_LT(e.position_mm, 2.0);
  EXPECT_LT(e.rotation_deg, 0.2);
}

// A law that makes no progress (here the arm does not move: the same left image every time) gets a fresh point set by
// a whole-image SIFT matching every stall_rematch_images images, within the re-matching budget, and no more.
TEST(ServoArmImageLoop, AStalledLawIsGivenAFreshPointSetWithinTheBudget) {
  sim::ArmRigConfig rig;
  sim::ArmRigSimulator sim(rig);
  const sim::StereoViews views = sim.render();
  control::ImageServoConfig config;
  config.matcher.ratio = 0.6;
  config.stall_rematch_images = 6;
  config.max_rematches = 3;
  control::ImageServoController controller(config, rig.right_camera.k, rig.left_camera.k, rig.left_camera.width_px,
                                           rig.left_camera.height_px);
  ASSERT_EQ(controller.setReference(views.right.image, lookupIn(views.right, config)), "");
  std::vector<int> rematched_at;
  for (int it = 0; it < 40; ++it) {
    const control::ImageStep step = controller.step(views.left.image, lookupIn(views.left, config));
    ASSERT_EQ(step.status, control::ImageStepStatus::kRunning) << it << ": " << step.message;
    ASSERT_GT(step.error_norm, config.rematch_below_error);  // far from the goal: the stall rule applies
    if (step.rematched && it > 0) rematched_at.push_back(it);
  }
  // The stall is seen on the 6th image without progress after a matching; the matching is done on the next image.
  EXPECT_EQ(rematched_at, (std::vector<int>{7, 14, 21}));
  EXPECT_EQ(controller.stallRematches(), 3);
  EXPECT_EQ(controller.rematches(), 3);

  config.stall_rematch_images = 0;  // off
  control::ImageServoController off(config, rig.right_camera.k, rig.left_camera.k, rig.left_camera.width_px,
                                    rig.left_camera.height_px);
  ASSERT_EQ(off.setReference(views.right.image, lookupIn(views.right, config)), "");
  for (int it = 0; it < 40; ++it) off.step(views.left.image, lookupIn(views.left, config));
  EXPECT_EQ(off.rematches(), 0);
}

}  // namespace
}  // namespace exocet_servo
