// Ground projection, GSD rounding, feather weights and configuration checks of the composer.
#include <gtest/gtest.h>

#include <Eigen/Dense>

#include "compose_fixtures.h"
#include "exocet_mosaic/compose/composer_config.h"
#include "exocet_mosaic/compose/feather_weights.h"
#include "exocet_mosaic/compose/ground_projection.h"

namespace ec = exocet_mosaic::compose;

namespace {

// Direct ray intersection with the plane z = camera_z - h.
Eigen::Vector2d rayIntersection(const ec::CameraGroundPose& p, const Eigen::Vector2d& px) {
  Eigen::Matrix3d k;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) k(r, c) = p.camera_matrix(r, c);
  const Eigen::Vector3d d = p.world_from_camera.toRotationMatrix() * k.inverse() * Eigen::Vector3d(px.x(), px.y(), 1);
  const double t = p.camera_height_m / -d.z();
  return p.camera_en_m + t * d.head<2>();
}

}  // namespace

TEST(ComposeGroundProjection, RoundTripAndRayIntersection) {
  compose_test::Flight flight;
  const Eigen::Vector2d origin(500000.0, 4800000.0);
  for (int i = 0; i < 200; i += 17) {
    const ec::CameraGroundPose pose = flight.pose(i);
    cv::Matx33d g, p;
    ASSERT_TRUE(ec::groundFromPixel(pose, flight.image_size, origin, &g));
    ASSERT_TRUE(ec::pixelFromGround(pose, flight.image_size, origin, &p));
    for (const Eigen::Vector2d& px :
         {Eigen::Vector2d(0, 0), Eigen::Vector2d(319, 0), Eigen::Vector2d(160.3, 120.7), Eigen::Vector2d(5, 239)}) {
      const Eigen::Vector2d ground = ec::applyHomography(g, px);
      EXPECT_LT((ec::applyHomography(p, ground) - px).norm(), 1e-8);
      EXPECT_LT((origin + ground - rayIntersection(pose, px)).norm(), 1e-9);
    }
  }
}

TEST(ComposeGroundProjection, NadirGeometryAndHorizon) {
  ec::CameraGroundPose pose;  // nadir, image top north
  pose.camera_en_m = Eigen::Vector2d(10, 20);
  pose.camera_height_m = 2.0;
  pose.camera_matrix = cv::Matx33d(500, 0, 100, 0, 500, 50, 0, 0, 1);
  cv::Matx33d g;
  ASSERT_TRUE(ec::groundFromPixel(pose, cv::Size(200, 100), Eigen::Vector2d::Zero(), &g));
  // Principal point straight below, +u east, +v south, gsd = h / f.
  EXPECT_LT((ec::applyHomography(g, Eigen::Vector2d(100, 50)) - Eigen::Vector2d(10, 20)).norm(), 1e-12);
  EXPECT_LT((ec::applyHomography(g, Eigen::Vector2d(110, 50)) - Eigen::Vector2d(10.04, 20)).norm(), 1e-12);
  EXPECT_LT((ec::applyHomography(g, Eigen::Vector2d(100, 60)) - Eigen::Vector2d(10, 19.96)).norm(), 1e-12);
  EXPECT_DOUBLE_EQ(ec::nativeGsd(pose), 0.004);
  // Tilted 89 degrees: the horizon is in the image.
  ec::CameraGroundPose tilted = pose;
  tilted.world_from_camera = Eigen::AngleAxisd(1.55, Eigen::Vector3d::UnitX()) * pose.world_from_camera;
  EXPECT_FALSE(ec::groundFromPixel(tilted, cv::Size(200, 100), Eigen::Vector2d::Zero(), &g));
  tilted.world_from_camera = Eigen::AngleAxisd(1.4, Eigen::Vector3d::UnitX()) * pose.world_from_camera;
  EXPECT_TRUE(ec::groundFromPixel(tilted, cv::Size(200, 100), Eigen::Vector2d::Zero(), &g));  // 80: still sees it
  ec::CameraGroundPose no_height = pose;
  no_height.camera_height_m = 0;
  EXPECT_FALSE(ec::groundFromPixel(no_height, cv::Size(200, 100), Eigen::Vector2d::Zero(), &g));
}

TEST(ComposeGroundProjection, GsdRoundsDownToOneTwoFive) {
  EXPECT_NEAR(ec::roundGsdDown(0.0047), 0.004, 1e-15);
  EXPECT_NEAR(ec::roundGsdDown(0.0036), 0.0032, 1e-15);  // a PAL camera 2.5 m above the seabed
  EXPECT_NEAR(ec::roundGsdDown(0.0055), 0.005, 1e-15);
  EXPECT_DOUBLE_EQ(ec::roundGsdDown(0.001), 0.001);
  EXPECT_NEAR(ec::roundGsdDown(0.0199), 0.016, 1e-15);
  EXPECT_NEAR(ec::roundGsdDown(0.25), 0.25, 1e-15);
  EXPECT_NEAR(ec::roundGsdDown(0.0999), 0.08, 1e-15);
  EXPECT_NEAR(ec::roundGsdDown(7.0), 6.3, 1e-12);
  for (double g = 1e-3; g < 10.0; g *= 1.01) {  // never up, never more than one R'10 step (< 28 %) down
    EXPECT_LE(ec::roundGsdDown(g), g * (1 + 1e-12));
    EXPECT_GT(ec::roundGsdDown(g), g / 1.28);
  }
  EXPECT_EQ(ec::roundGsdDown(0.0), 0.0);
}

TEST(ComposeFeatherWeights, DistanceToBorderNormalised) {
  const cv::Mat w = ec::FeatherWeights::compute(cv::Size(40, 20), 1.0);
  EXPECT_NEAR(w.at<float>(10, 20), 0.95f, 1e-6);  // 9.5 px of 10 from the border
  EXPECT_NEAR(w.at<float>(9, 20), 0.95f, 1e-6);
  EXPECT_NEAR(w.at<float>(0, 20), 0.05f, 1e-6);  // half a pixel of 10
  EXPECT_NEAR(w.at<float>(10, 0), 0.05f, 1e-6);
  EXPECT_LT(w.at<float>(2, 20), w.at<float>(5, 20));
  const cv::Mat w2 = ec::FeatherWeights::compute(cv::Size(40, 20), 2.0);
  EXPECT_NEAR(w2.at<float>(0, 20), 0.0025f, 1e-6);
  ec::FeatherWeights cache;
  const cv::Mat& a = cache.get(cv::Size(40, 20), 1.0);
  const uchar* data = a.data;
  EXPECT_EQ(cache.get(cv::Size(40, 20), 1.0).data, data);  // cached
}

TEST(ComposeConfig, ValidateNamesEveryBadField) {
  ec::ComposerConfig c;
  EXPECT_EQ(c.validate(), "");
  c.frames_per_mosaic = 1;
  c.blend = "average";
  c.anchor = "affine";
  c.gsd_m = -1;
  c.lighting.max_gain = 0.5;
  c.navigation_samples_per_mosaic = 0.5;
  const std::string e = c.validate();
  for (const char* field : {"frames_per_mosaic", "[2, 100000]", "blend", "anchor", "gsd_m", "lighting.max_gain",
                            "navigation_samples_per_mosaic"})
    EXPECT_NE(e.find(field), std::string::npos) << field << " missing in: " << e;
  EXPECT_THROW(ec::MosaicComposer composer(c), std::invalid_argument);
  ec::MosaicComposer ok{ec::ComposerConfig()};
  EXPECT_THROW(ok.setConfig(c), std::invalid_argument);
}
