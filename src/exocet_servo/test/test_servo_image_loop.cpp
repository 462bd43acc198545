// Tests of the image-level servo (2D4 report 2.3-2.4): the rendered depth agrees with the scene geometry, SIFT
// matches between the two cameras agree with the projection of the known geometry, the closed loop (SIFT + KLT +
// invariant law) brings the left camera to the right camera's reference pose despite other intrinsics, and losing the
// object gives the "lost tracking" status.
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>

#include <gtest/gtest.h>

#include "exocet_servo/sim/image_servo_loop.h"
#include "exocet_servo/sim/point_scene.h"
#include "exocet_servo/sim/vent_renderer.h"
#include "exocet_servo/trajectory/se3.h"
#include "exocet_servo/vision/point_matcher.h"
#include "exocet_servo/vision/point_tracker.h"

namespace {

using namespace exocet_servo;

const sim::VentRenderer& renderer() {
  static const sim::VentRenderer r{sim::VentSceneConfig()};
  return r;
}

// The report's rig: the right camera (longer focal length, other aspect, principal point, skew) takes the reference
// 1.1 m from the chimney, looking down at it; the left camera is servoed.
sim::ImageServoSetup rigSetup() {
  sim::ImageServoSetup s;
  s.controlled_camera.k = sim::intrinsics(800.0, 812.0, 322.0, 236.0);
  s.reference_camera.k = sim::intrinsics(905.0, 880.0, 301.0, 257.0, 1.5);
  s.world_T_reference = sim::lookAt(Eigen::Vector3d(1.0, 0.0, 0.55), Eigen::Vector3d(0.0, 0.0, 0.12));
  s.k_estimate_reference = s.reference_camera.k;
  s.k_estimate_controlled = s.controlled_camera.k;
  s.world_T_start = s.world_T_reference;
  return s;
}

Eigen::Isometry3d offset(const Eigen::Isometry3d& pose, const Eigen::Vector3d& t_m, const Eigen::Vector3d& r_rad) {
  trajectory::Twist d;
  d << t_m, r_rad;
  return pose * trajectory::expSe3(d);
}

// Where a pixel of camera a (at pa) appears in camera b (at pb), through the exact rendered depth.
Eigen::Vector2d transfer(const sim::PinholeCamera& a, const Eigen::Isometry3d& pa, const sim::PinholeCamera& b,
                         const Eigen::Isometry3d& pb, const Eigen::Vector2d& px) {
  const double z = renderer().depthAt(a, pa, px);
  const Eigen::Vector3d point_w = pa * (z * (a.k.inverse() * Eigen::Vector3d(px.x(), px.y(), 1.0)));
  const Eigen::Vector3d q = b.k * (pb.inverse() * point_w);
  return q.head<2>() / q.z();
}

TEST(ServoImageRenderer, DepthBackProjectsOntoTheSurface) {
  sim::PinholeCamera cam;
  cam.k = sim::intrinsics(400.0, 410.0, 161.0, 118.0, 0.7);  // 320x240: enough for the geometry
  cam.width_px = 320;
  cam.height_px = 240;
  const Eigen::Isometry3d pose =
      offset(rigSetup().world_T_reference, Eigen::Vector3d(0.05, -0.02, 0.03), Eigen::Vector3d(0.02, -0.05, 0.1));
  const sim::RenderedView view = renderer().render(cam, pose);
  ASSERT_EQ(view.image.type(), CV_8UC1);
  ASSERT_EQ(view.image.size(), cv::Size(320, 240));
  int chimney = 0, seabed = 0, checked = 0;
  double worst = 0.0, worst_wrong_pose = std::numeric_limits<double>::infinity();
  const Eigen::Isometry3d wrong = offset(pose, Eigen::Vector3d(0.0, 0.0, 0.01), Eigen::Vector3d::Zero());
  for (int y = 2; y < cam.height_px; y += 7) {
    for (int x = 3; x < cam.width_px; x += 7) {
      const float z = view.depth_m.at<float>(y, x);
      if (!std::isfinite(z)) continue;
      sim::SurfaceKind kind;
      const double exact = renderer().depthAt(cam, pose, Eigen::Vector2d(x, y), &kind);
      EXPECT_NEAR(z, exact, 1e-5 * exact);
      chimney += kind == sim::SurfaceKind::kChimney;
      seabed += kind == sim::SurfaceKind::kSeabed;
      const Eigen::Vector3d ray = cam.k.inverse() * Eigen::Vector3d(x, y, 1.0);
      worst = std::max(worst, renderer().distanceToSurface(pose * (z * ray)));
      // The same depth from a pose 1 cm further along the optical axis lands off the surface.
      if (kind == sim::SurfaceKind::kChimney)
        worst_wrong_pose = std::min(worst_wrong_pose, renderer().distanceToSurface(wrong * (z * ray)));
      ++checked;
    }
  }
  EXPECT_GT(chimney, 50);
  EXPECT_GT(seabed, 200);
  EXPECT_LT(worst, 1e-5) << "rendered depth does not put the pixel on the surface";
  EXPECT_GT(worst_wrong_pose, 1e-3);
  // The image is textured (the matcher needs it): gray levels spread.
  cv::Scalar mean, stddev;
  cv::meanStdDev(view.image, mean, stddev);
  EXPECT_GT(stddev[0], 25.0);
  printf("%d pixels checked (%d chimney, %d seabed), largest distance to the surface %.2g m\n", checked, chimney,
         seabed, worst);
}

TEST(ServoImageRenderer, DistanceToTheSceneIsExactAtTheRims) {
  sim::VentSceneConfig scene;  // chimney 0.3 m high, radius 0.1 m at the base and 0.05 m at the top
  scene.base_m = Eigen::Vector3d(1.0, -2.0, -0.5);
  const auto at = [&](double x, double y, double z) { return sim::distanceToScene(scene, scene.base_m + Eigen::Vector3d(x, y, z)); };
  // On each surface: the seabed, the side (half way up: radius 0.075 m), the top cap, both rims.
  EXPECT_NEAR(at(0.5, 0.3, 0.0), 0.0, 1e-12);
  EXPECT_NEAR(at(0.0, 0.075, 0.15), 0.0, 1e-12);
  EXPECT_NEAR(at(0.02, 0.0, 0.3), 0.0, 1e-12);
  EXPECT_NEAR(at(0.05, 0.0, 0.3), 0.0, 1e-12);
  EXPECT_NEAR(at(0.0, -0.1, 0.0), 0.0, 1e-12);
  // Just above and outside the top rim: the rim, 1.4 cm away (the seabed is 0.31 m away); level with the cap, the
  // side, which slopes outwards below the rim, is nearer than the rim.
  EXPECT_NEAR(at(0.06, 0.0, 0.31), std::hypot(0.01, 0.01), 1e-12);
  EXPECT_NEAR(at(0.06, 0.0, 0.3), 0.003 / std::hypot(0.05, 0.3), 1e-12);
  // Diagonally above the top rim: the distance to the rim point.
  EXPECT_NEAR(at(0.08, 0.0, 0.34), 0.05, 1e-12);
  // Above the cap: straight down to it; inside the chimney: to the nearest wall or the cap.
  EXPECT_NEAR(at(0.0, 0.0, 0.5), 0.2, 1e-12);
  EXPECT_NEAR(at(0.0, 0.0, 0.29), 0.01, 1e-12);
  // Below the chimney's foot (under the seabed): the base rim, not the seabed plane.
  EXPECT_NEAR(at(0.0, 0.0, -0.1), std::hypot(0.1, 0.1), 1e-12);
  // Beyond the seabed's textured square (half side 3 m) the plane goes on.
  EXPECT_NEAR(at(3.4, 0.0, 0.3), 0.3, 1e-12);
  // Without the seabed, a point on the seabed plane is only as close as the chimney.
  scene.draw_seabed = false;
  EXPECT_NEAR(at(0.5, 0.0, 0.0), 0.4, 1e-12);
  // The renderer's member is the same function.
  scene.draw_seabed = true;
  scene.supersampling = 1;
  const sim::VentRenderer renderer(scene);
  EXPECT_NEAR(renderer.distanceToSurface(scene.base_m + Eigen::Vector3d(0.06, 0.0, 0.31)), std::hypot(0.01, 0.01),
              1e-12);
}

TEST(ServoImageRenderer, SmoothDepthRejectsTheSilhouette) {
  const sim::ImageServoSetup s = rigSetup();
  const sim::RenderedView view = renderer().render(s.controlled_camera, s.world_T_reference);
  // The chimney's axis projects near the image centre column; walk a row from the chimney outwards until the depth
  // jumps to the seabed behind: around the jump no depth is given, on either side it is.
  const Eigen::Vector2d centre = transfer(s.controlled_camera, s.world_T_reference, s.controlled_camera,
                                          s.world_T_reference, Eigen::Vector2d(320, 240));
  const int row = static_cast<int>(centre.y());
  int jump = -1;
  for (int x = 320; x < 630 && jump < 0; ++x)
    if (view.depth_m.at<float>(row, x + 1) > 1.05f * view.depth_m.at<float>(row, x)) jump = x;
  ASSERT_GT(jump, 0);
  double d = 0.0;
  EXPECT_FALSE(view.smoothDepthAt(Eigen::Vector2d(jump + 0.5, row), 3, 0.03, &d));
  EXPECT_TRUE(view.smoothDepthAt(Eigen::Vector2d(jump - 10.0, row), 3, 0.03, &d));
  EXPECT_NEAR(d, view.depth_m.at<float>(row, jump - 10), 0.01);
  EXPECT_TRUE(view.smoothDepthAt(Eigen::Vector2d(jump + 10.0, row), 3, 0.03, &d));
}

TEST(ServoImageMatcher, FindsCorrectMatchesBetweenTheTwoCameras) {
  const sim::ImageServoSetup s = rigSetup();
  const sim::RenderedView ref = renderer().render(s.reference_camera, s.world_T_reference);
  vision::PointMatcher matcher;
  ASSERT_EQ(matcher.setReference(ref.image), "");
  // Both cameras at the reference pose (only K differs), then the left camera 7 cm and 8 deg away.
  const Eigen::Isometry3d poses[] = {
      s.world_T_reference,
      offset(s.world_T_reference, Eigen::Vector3d(0.04, -0.03, 0.05), Eigen::Vector3d(0.06, 0.1, -0.07))};
  for (const Eigen::Isometry3d& pose : poses) {
    const sim::RenderedView cur = renderer().render(s.controlled_camera, pose);
    const vision::PointMatches m = matcher.match(cur.image);
    ASSERT_TRUE(m.ok()) << m.error;
    int correct = 0;
    double sum = 0.0;
    for (size_t i = 0; i < m.reference_px.size(); ++i) {
      const Eigen::Vector2d predicted = transfer(s.reference_camera, s.world_T_reference, s.controlled_camera, pose,
                                                 Eigen::Vector2d(m.reference_px[i].x, m.reference_px[i].y));
      const double e = (predicted - Eigen::Vector2d(m.current_px[i].x, m.current_px[i].y)).norm();
      if (e < 1.0) {
        ++correct;
        sum += e;
      }
    }
    printf("%d SIFT keypoints, %d ratio matches, %zu after RANSAC, %d within 1 px of the projection (mean %.3f px)\n",
           m.current_keypoints, m.ratio_matches, m.reference_px.size(), correct, sum / std::max(1, correct));
    EXPECT_GE(correct, 50);
    EXPECT_GE(correct, 0.9 * m.reference_px.size());
  }
  // A blank image has nothing to match.
  const vision::PointMatches none = matcher.match(cv::Mat(480, 640, CV_8UC1, cv::Scalar(40)));
  EXPECT_FALSE(none.ok());
  EXPECT_TRUE(none.reference_px.empty());
}

TEST(ServoImageTracker, FollowsTheMotionAndDropsWhatItCannotSee) {
  const sim::ImageServoSetup s = rigSetup();
  const Eigen::Isometry3d a = s.world_T_reference;
  const Eigen::Isometry3d b = offset(a, Eigen::Vector3d(0.01, 0.005, -0.01), Eigen::Vector3d(0.01, -0.02, 0.01));
  const sim::RenderedView va = renderer().render(s.controlled_camera, a),
                          vb = renderer().render(s.controlled_camera, b);
  std::vector<cv::Point2f> pts;
  std::vector<int> ids;
  for (int y = 60; y < 440; y += 20)
    for (int x = 60; x < 600; x += 20) {
      double z = 0.0;
      if (!va.smoothDepthAt(Eigen::Vector2d(x, y), 3, 0.03, &z)) continue;
      ids.push_back(static_cast<int>(pts.size()));
      pts.emplace_back(x, y);
    }
  vision::PointTracker tracker;
  tracker.reset(va.image, pts, ids);
  const int kept = tracker.track(vb.image);
  EXPECT_GT(kept, 0.8 * pts.size());
  double sum = 0.0;
  for (size_t i = 0; i < tracker.points().size(); ++i) {
    const Eigen::Vector2d p(pts[tracker.ids()[i]].x, pts[tracker.ids()[i]].y);
    sum += (transfer(s.controlled_camera, a, s.controlled_camera, b, p) -
            Eigen::Vector2d(tracker.points()[i].x, tracker.points()[i].y))
               .norm();
  }
  EXPECT_LT(sum / kept, 0.3) << "mean tracking error (px)";
  EXPECT_EQ(tracker.track(cv::Mat(480, 640, CV_8UC1, cv::Scalar(40))), 0);
  EXPECT_TRUE(tracker.needsRematch());
}

TEST(ServoImageLoop, ConvergesToTheReferencePoseWithDifferentIntrinsics) {
  const sim::ImageServoConfig config;
  // 7 cm / 8 deg and 10 cm / 6 deg away; the second with intrinsics estimates 10-15 % off (only L_hat uses them).
  struct Case {
    Eigen::Vector3d t_m, r_rad;
    bool rough_k;
  };
  const Case cases[] = {{Eigen::Vector3d(0.04, -0.03, 0.05), Eigen::Vector3d(0.06, 0.1, -0.07), false},
                        {Eigen::Vector3d(-0.06, 0.05, -0.06), Eigen::Vector3d(-0.05, 0.06, 0.06), true}};
  for (const Case& c : cases) {
    sim::ImageServoSetup s = rigSetup();
    s.world_T_start = offset(s.world_T_reference, c.t_m, c.r_rad);
    if (c.rough_k) {
      s.k_estimate_reference = sim::intrinsics(1000, 1000, 320, 240);
      s.k_estimate_controlled = sim::intrinsics(700, 700, 320, 240);
    }
    const sim::ImageServoResult r = sim::runImageServo(renderer(), s, config);
    printf(
        "start %.1f mm %.2f deg -> %s in %d iterations (%d points, %d re-matches), final %.3f mm %.4f deg, "
        "control %.1f ms CPU\n",
        r.initial_error.position_mm, r.initial_error.rotation_deg, sim::toString(r.status).c_str(), r.iterations,
        r.initial_matches, r.rematches, r.final_error.position_mm, r.final_error.rotation_deg,
        1e3 * r.mean_control_cpu_time_s);
    EXPECT_EQ(r.status, sim::ImageServoStatus::kConverged) << r.message;
    EXPECT_GT(r.initial_error.position_mm, 50.0);
    EXPECT_LT(r.final_error.position_mm, 2.0);
    EXPECT_LT(r.final_error.rotation_deg, 0.2);
    EXPECT_LE(r.iterations, 40);
    ASSERT_FALSE(r.history.empty());
    EXPECT_TRUE(r.history.front().rematched);
    EXPECT_GT(r.history.front().points, 100);
  }
}

TEST(ServoImageLoop, LosingTheObjectGivesLostTracking) {
  sim::ImageServoSetup s = rigSetup();
  s.world_T_start = offset(s.world_T_reference, Eigen::Vector3d(0.04, -0.03, 0.05), Eigen::Vector3d(0.06, 0.1, -0.07));
  // After two images the object (and the seabed) leave the view: only water.
  auto render = [&s](const Eigen::Isometry3d& pose, int iteration) {
    sim::RenderedView v = renderer().render(s.controlled_camera, pose);
    if (iteration >= 2) {
      v.image.setTo(cv::Scalar(40));
      v.depth_m.setTo(cv::Scalar(std::numeric_limits<float>::infinity()));
    }
    return v;
  };
  const sim::ImageServoResult r = sim::runImageServo(renderer(), s, sim::ImageServoConfig(), render);
  EXPECT_EQ(r.status, sim::ImageServoStatus::kLostTracking) << r.message;
  EXPECT_EQ(r.iterations, 2);
  EXPECT_NE(r.message.find("lost tracking"), std::string::npos) << r.message;
  printf("%s\n", r.message.c_str());
}

TEST(ServoImageLoop, ReMatchesAfterAnOcclusionAndStillConverges) {
  sim::ImageServoSetup s = rigSetup();
  s.world_T_start = offset(s.world_T_reference, Eigen::Vector3d(0.04, -0.03, 0.05), Eigen::Vector3d(0.06, 0.1, -0.07));
  // On the third image something (a fish) hides the left 75 % of the view: fewer tracks than tracker.min_points
  // survive and SIFT re-matches on what is left: the seabed only, a plane, which the law refuses as degenerate; the
  // next (clear) image is matched again and the servo goes on.
  auto render = [&s](const Eigen::Isometry3d& pose, int iteration) {
    sim::RenderedView v = renderer().render(s.controlled_camera, pose);
    if (iteration == 2) v.image(cv::Rect(0, 0, 480, 480)).setTo(cv::Scalar(40));
    return v;
  };
  sim::ImageServoConfig config;
  config.tracker.min_points = 100;
  const sim::ImageServoResult r = sim::runImageServo(renderer(), s, config, render);
  ASSERT_GE(r.history.size(), 3u) << r.message;
  EXPECT_TRUE(r.history[2].rematched);
  EXPECT_LT(r.history[2].points, r.history[1].points);  // matched in the visible quarter only
  EXPECT_GE(r.rematches, 1);
  EXPECT_EQ(r.status, sim::ImageServoStatus::kConverged) << r.message;
  EXPECT_LT(r.final_error.position_mm, 2.0);
  EXPECT_LT(r.final_error.rotation_deg, 0.2);
  for (const auto& h : r.history)  // points per iteration, (m) when SIFT matched, law status
    printf("%d%s%s ", h.points, h.rematched ? "(m)" : "",
           h.servo_status == control::ServoStatus::kRunning ? "" : control::toString(h.servo_status).c_str());
  printf("\n");
  printf("occlusion: %d -> %d -> %d points, %d re-matches, %s in %d iterations, final %.3f mm %.4f deg\n",
         r.history[1].points, r.history[2].points, r.history[3].points, r.rematches, sim::toString(r.status).c_str(),
         r.iterations, r.final_error.position_mm, r.final_error.rotation_deg);
}

TEST(ServoImageLoop, ConfigValidationListsEveryBadField) {
  sim::ImageServoConfig c;
  EXPECT_EQ(c.validate(), "");
  c.dt_s = 0.0;
  c.max_points = 2;
  c.tracker.window_px = 20;
  c.matcher.ratio = 1.5;
  const std::string e = c.validate();
  for (const char* field : {"dt_s", "max_points", "tracker: window_px", "matcher: ratio"})
    EXPECT_NE(e.find(field), std::string::npos) << field << " missing from: " << e;
  EXPECT_THROW(sim::runImageServo(renderer(), rigSetup(), c), std::invalid_argument);
  sim::VentSceneConfig scene;
  scene.supersampling = 0;
  scene.height_m = -1.0;
  EXPECT_NE(scene.validate().find("supersampling"), std::string::npos);
  EXPECT_NE(scene.validate().find("height_m"), std::string::npos);
}

}  // namespace
