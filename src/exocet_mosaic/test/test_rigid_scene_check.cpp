// The rigid-scene check of KLT's acceptance: tracks of a seabed with strong relief (rubble 0.05-0.6 m tall at 2 m) seen
// by a camera that moves sideways are one rigid scene, though no homography explains them; tracks that drift on
// their own (particles, fish) are not; the tracking noise is recovered from forward-backward distances.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "exocet_mosaic/registration/rigid_scene_check.h"
#include "exocet_mosaic/registration/robust_motion_fitter.h"

namespace exocet_mosaic {
namespace registration {
namespace {

constexpr int kWidth = 968, kHeight = 608;
constexpr double kFocal = 800.0;

/// Tracks of seabed points at 2 m (z down the optical axis), half of them on rubble 0.05-0.6 m tall, seen before
/// and after the camera moves `sideways_m` sideways, a fifth of it forward, and turns 2 degrees; `noise_px` on the
/// track ends.
struct Tracks {
  std::vector<cv::Point2f> from, to;
  std::vector<bool> on_relief;
};

Tracks reliefTracks(int count, double noise_px, uint32_t seed, double sideways_m = 0.25) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::normal_distribution<double> noise(0.0, noise_px);
  const Eigen::Matrix3d r = Eigen::AngleAxisd(2.0 * M_PI / 180.0, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  const Eigen::Vector3d t(-sideways_m, -0.2 * sideways_m, 0.0);  // second camera = r * first + t
  auto project = [](const Eigen::Vector3d& p) {
    return cv::Point2f(static_cast<float>(kFocal * p.x() / p.z() + 0.5 * kWidth),
                       static_cast<float>(kFocal * p.y() / p.z() + 0.5 * kHeight));
  };
  Tracks tracks;
  while (static_cast<int>(tracks.from.size()) < count) {
    const double x = (u(rng) - 0.5) * kWidth, y = (u(rng) - 0.5) * kHeight;
    const bool relief = u(rng) < 0.5;
    const double depth = 2.0 - (relief ? 0.05 + 0.55 * u(rng) : 0.0);
    const Eigen::Vector3d p(x / kFocal * depth, y / kFocal * depth, depth);
    const cv::Point2f a = project(p), b = project(r * p + t);
    if (b.x < 0 || b.y < 0 || b.x >= kWidth || b.y >= kHeight) continue;
    tracks.from.push_back(a);
    tracks.to.push_back(b + cv::Point2f(static_cast<float>(noise(rng)), static_cast<float>(noise(rng))));
    tracks.on_relief.push_back(relief);
  }
  return tracks;
}

TEST(RigidSceneCheck, TrackingNoiseFromForwardBackwardDistances) {
  std::mt19937 rng(5);
  for (const double sigma : {0.03, 0.1, 0.4}) {
    std::normal_distribution<double> n(0.0, sigma);
    std::vector<float> fb;
    for (int i = 0; i < 2000; ++i) fb.push_back(static_cast<float>(std::hypot(n(rng) + n(rng), n(rng) + n(rng))));
    EXPECT_NEAR(trackingNoiseFromForwardBackward_px(fb, 0.001), sigma, 0.05 * sigma);
  }
  EXPECT_DOUBLE_EQ(trackingNoiseFromForwardBackward_px({}, 0.03), 0.03);
  EXPECT_DOUBLE_EQ(trackingNoiseFromForwardBackward_px({0.001f, 0.002f}, 0.03), 0.03);  // the floor
}

TEST(RigidSceneCheck, ReliefIsOneRigidSceneThoughNoHomographyHoldsIt) {
  const double sigma = 0.08;
  // Consecutive images of a 20 frames/s video at 0.4 m/s: 2 cm apart. The rubble's parallax (0-3 px) is too small
  // for a homography's robust fit to strike it off, and neighbouring tracks at different heights disagree.
  const Tracks tracks = reliefTracks(200, sigma, 11, 0.02);
  RobustFitConfig fc;
  fc.model = MotionModel::kHomography;
  const RobustFit fit =
      RobustMotionFitter(fc).fit(tracks.from, tracks.to, Eigen::Vector2d(kWidth / 2.0, kHeight / 2.0));
  EXPECT_TRUE(!fit.ok || fit.local_scale_px > 0.3 || fit.residual_scale_px > 1.0)
      << "the relief must be strong enough to fail a one-plane test: local " << fit.local_scale_px << " px";
  const RigidSceneCheck check = checkRigidScene(tracks.from, tracks.to, sigma);
  ASSERT_TRUE(check.estimated) << check.detail;
  EXPECT_GE(check.consistent_count, 0.98 * tracks.from.size()) << check.detail;
  std::printf("[ info ] relief: homography local scale %.2f px, residual %.2f px; %s\n", fit.local_scale_px,
              fit.residual_scale_px, check.detail.c_str());
}

TEST(RigidSceneCheck, TracksThatMoveOnTheirOwnLeaveTheEpipolarGeometry) {
  const double sigma = 0.08;
  Tracks tracks = reliefTracks(150, sigma, 12);
  // 60 drifting particles: each moves with the scene plus a drift of 1-4 px in its own direction.
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const size_t scene = tracks.from.size();
  const Tracks more = reliefTracks(60, sigma, 13);
  for (size_t i = 0; i < more.from.size(); ++i) {
    const double a = 2.0 * M_PI * u(rng), d = 1.0 + 3.0 * u(rng);
    tracks.from.push_back(more.from[i]);
    tracks.to.push_back(more.to[i] +
                        cv::Point2f(static_cast<float>(d * std::cos(a)), static_cast<float>(d * std::sin(a))));
  }
  const RigidSceneCheck check = checkRigidScene(tracks.from, tracks.to, sigma);
  ASSERT_TRUE(check.estimated) << check.detail;
  int scene_kept = 0, drift_kept = 0;
  for (size_t i = 0; i < tracks.from.size(); ++i) (i < scene ? scene_kept : drift_kept) += check.consistent[i];
  EXPECT_GE(scene_kept, 0.97 * scene) << check.detail;
  // A drift nearly along its own epipolar line cannot be told from relief: a drift of d px stays within 3 sigma of
  // the line for directions within asin(0.24 / d) of it, 2 asin(0.24 / d) / pi of them (about 10 % for d uniform
  // in 1-4 px), and the fitted geometry bends towards a few more; a fifth is the bound.
  EXPECT_LE(drift_kept, 12) << check.detail;
  std::printf("[ info ] relief + 60 drifting tracks: %d of %zu scene tracks and %d of 60 drifting ones kept\n",
              scene_kept, scene, drift_kept);

  // Only drifting tracks: no epipolar geometry holds most of them.
  Tracks snow;
  for (size_t i = 0; i < more.from.size(); ++i) {
    snow.from.push_back(more.from[i]);
    snow.to.push_back(tracks.to[scene + i]);
  }
  const RigidSceneCheck none = checkRigidScene(snow.from, snow.to, sigma);
  EXPECT_LT(none.consistent_count, 0.5 * snow.from.size()) << none.detail;
}

TEST(RigidSceneCheck, BadInputIsNamed) {
  const std::vector<cv::Point2f> a(10), b(9);
  EXPECT_THROW(checkRigidScene(a, b, 0.1), std::invalid_argument);
  EXPECT_THROW(checkRigidScene(a, a, 0.0), std::invalid_argument);
  RigidSceneConfig bad;
  bad.k_sigma = 0.5;
  EXPECT_NE(bad.validate().find("k_sigma"), std::string::npos);
  const RigidSceneCheck few = checkRigidScene(std::vector<cv::Point2f>(5), std::vector<cv::Point2f>(5), 0.1);
  EXPECT_FALSE(few.estimated);
}

}  // namespace
}  // namespace registration
}  // namespace exocet_mosaic
