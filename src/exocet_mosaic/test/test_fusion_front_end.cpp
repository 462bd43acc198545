// The fusion front-end's policy: which input starts the filter, lever arms, the views of the images (attitude and
// height, fitted over a window or interpolated), the metric conversion, the operator's heading, and bad inputs.
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <memory>
#include <random>
#include <stdexcept>
#include <string>

#include "exocet_mosaic/fusion/fusion_front_end.h"

namespace exocet_mosaic {
namespace fusion {
namespace {

/// A camera looking straight down from 0.5 m ahead of base_link (camera x = base x, camera z = -base z), an
/// altimeter at base_link and a USBL transponder 1 m above it.
std::map<std::string, Eigen::Isometry3d> rigMounts() {
  Eigen::Isometry3d camera = Eigen::Isometry3d::Identity();
  camera.linear() = Eigen::Vector3d(1.0, -1.0, -1.0).asDiagonal();
  camera.translation() = Eigen::Vector3d(0.5, 0.0, 0.0);
  Eigen::Isometry3d transponder = Eigen::Isometry3d::Identity();
  transponder.translation() = Eigen::Vector3d(0.0, 0.0, 1.0);
  return {{"camera", camera}, {"altimeter", Eigen::Isometry3d::Identity()}, {"usbl", transponder}};
}

FusionFrontEnd makeFrontEnd(FusionFrontEndConfig config = {}) {
  const std::map<std::string, Eigen::Isometry3d> mounts = rigMounts();
  return FusionFrontEnd(config, [mounts](const std::string& frame) -> std::optional<Eigen::Isometry3d> {
    const auto it = mounts.find(frame);
    if (it == mounts.end()) return std::nullopt;
    return it->second;
  });
}

Eigen::Quaterniond yaw(double rad) { return Eigen::Quaterniond(Eigen::AngleAxisd(rad, Eigen::Vector3d::UnitZ())); }

Eigen::Matrix3d camera() {
  Eigen::Matrix3d k;
  k << 500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0;
  return k;
}

/// The registration's estimate of a pure image translation (tx, ty) px between two stamps.
ImageMotionInput translation(double t0, double t1, double tx_px, double ty_px) {
  ImageMotionInput m;
  m.previous_stamp_s = t0;
  m.stamp_s = t1;
  m.model = "translation";
  m.parameters = Eigen::Vector2d(tx_px, ty_px);
  m.covariance = Eigen::Matrix2d::Identity() * 0.01;
  m.centre_px = Eigen::Vector2d(320.0, 240.0);
  m.pixel_matrix = Eigen::Matrix3d::Identity();
  m.pixel_matrix(0, 2) = tx_px;
  m.pixel_matrix(1, 2) = ty_px;
  m.camera_matrix = camera();
  return m;
}

/// Level attitude and a 2 m altimeter range every 0.1 s over [from, to].
void feedLevelSensors(FusionFrontEnd* front, double from_s, double to_s, double enu_yaw_rad = 0.0) {
  for (double t = from_s; t <= to_s + 1e-9; t += 0.1) {
    front->addImuAttitude(t, yaw(enu_yaw_rad));
    front->addAltimeterRange(t, 2.0, "altimeter");
  }
}

TEST(FusionFrontEnd, TheFirstDeadReckoningStartsTheFilterAtTheCameraAndTheNextIsApplied) {
  FusionFrontEnd front = makeFrontEnd();
  feedLevelSensors(&front, 10.0, 12.0, M_PI / 2.0);  // facing north
  const InputOutcome first =
      front.addDeadReckoning(10.0, Eigen::Vector3d(100.0, 200.0, -50.0), Eigen::Matrix2d::Identity() * 0.04);
  EXPECT_EQ(first.started_from, "the dead reckoning");
  EXPECT_FALSE(first.update.has_value());
  ASSERT_TRUE(first.camera_en_m.has_value());
  // The camera is 0.5 m ahead of base_link: facing north, that is 0.5 m north.
  EXPECT_NEAR(first.camera_en_m->x(), 100.0, 1e-9);
  EXPECT_NEAR(first.camera_en_m->y(), 200.5, 1e-9);
  EXPECT_TRUE(front.filter().initialized());
  EXPECT_NEAR(front.filter().current().position_covariance_m2(0, 0), 0.04, 1e-9);
  const InputOutcome second =
      front.addDeadReckoning(11.0, Eigen::Vector3d(100.0, 201.0, -50.0), Eigen::Matrix2d::Identity() * 0.04);
  ASSERT_TRUE(second.update.has_value());
  EXPECT_EQ(second.update->status, UpdateStatus::kApplied) << second.update->detail;
  EXPECT_TRUE(second.started_from.empty());
}

TEST(FusionFrontEnd, TheFilterWaitsForTheCameraMountAndTheAttitudeBeforeStartingFromTheNavigation) {
  // /tf_static late (a loaded machine, a node restarted): started at base_link, the filter would carry the 0.5 m
  // lever arm as an error until the fixes removed it.
  auto mounts = std::make_shared<std::map<std::string, Eigen::Isometry3d>>();
  FusionFrontEnd front(FusionFrontEndConfig(), [mounts](const std::string& frame) -> std::optional<Eigen::Isometry3d> {
    const auto it = mounts->find(frame);
    if (it == mounts->end()) return std::nullopt;
    return it->second;
  });
  const Eigen::Matrix2d covariance = Eigen::Matrix2d::Identity() * 0.04;
  const InputOutcome no_attitude = front.addDeadReckoning(9.5, Eigen::Vector3d(100.0, 200.0, -50.0), covariance);
  EXPECT_FALSE(front.filter().initialized());
  EXPECT_NE(no_attitude.problem.find("waits"), std::string::npos) << no_attitude.problem;
  feedLevelSensors(&front, 10.0, 12.0, M_PI / 2.0);  // facing north
  const InputOutcome no_mount = front.addDeadReckoning(10.0, Eigen::Vector3d(100.0, 200.0, -50.0), covariance);
  EXPECT_FALSE(front.filter().initialized());
  EXPECT_NE(no_mount.problem.find("camera"), std::string::npos) << no_mount.problem;
  const InputOutcome fix = front.addFix(10.1, Eigen::Vector2d(100.0, 200.0), covariance, "", true);
  EXPECT_FALSE(front.filter().initialized());  // a fix may not start it either
  EXPECT_FALSE(fix.problem.empty());
  *mounts = rigMounts();
  const InputOutcome started = front.addDeadReckoning(10.5, Eigen::Vector3d(100.0, 200.0, -50.0), covariance);
  EXPECT_EQ(started.started_from, "the dead reckoning");
  EXPECT_NEAR(front.filter().current().position_en_m.y(), 200.5, 1e-9);  // at the camera, 0.5 m ahead
  // A vehicle that never gives an attitude starts anyway, 2 s after its first navigation sample, and says so.
  FusionFrontEnd blind = makeFrontEnd();
  EXPECT_FALSE(blind.addDeadReckoning(20.0, Eigen::Vector3d(1, 2, 0), covariance).problem.empty());
  EXPECT_FALSE(blind.filter().initialized());
  const InputOutcome late = blind.addDeadReckoning(22.5, Eigen::Vector3d(1, 2, 0), covariance);
  EXPECT_TRUE(blind.filter().initialized());
  EXPECT_NE(late.problem.find("without the lever arm"), std::string::npos) << late.problem;
}

TEST(FusionFrontEnd, AFixIsMovedFromTheTransponderToTheCameraAndStartsTheFilterOnlyWhenAllowed) {
  FusionFrontEnd front = makeFrontEnd();
  feedLevelSensors(&front, 0.0, 3.0, 0.0);  // facing east
  const InputOutcome refused =
      front.addFix(1.0, Eigen::Vector2d(10.0, 20.0), Eigen::Matrix2d::Identity(), "usbl", false);
  EXPECT_FALSE(front.filter().initialized());
  EXPECT_FALSE(refused.update.has_value());
  const InputOutcome started =
      front.addFix(2.0, Eigen::Vector2d(10.0, 20.0), Eigen::Matrix2d::Identity(), "usbl", true);
  EXPECT_EQ(started.started_from, "the first fix");
  ASSERT_TRUE(started.camera_en_m.has_value());
  EXPECT_NEAR(started.camera_en_m->x(), 10.5, 1e-9);  // the camera is 0.5 m ahead (east); the transponder's height
  EXPECT_NEAR(started.camera_en_m->y(), 20.0, 1e-9);  // above base_link does not move it horizontally when level
}

TEST(FusionFrontEnd, AnImageTranslationBecomesTheCameraDisplacementInMetres) {
  FusionFrontEnd front = makeFrontEnd();
  feedLevelSensors(&front, 0.0, 2.0);
  front.initialize(0.5, Eigen::Vector2d(0.0, 0.0), Eigen::Matrix2d::Identity() * 0.01);
  // 10 px at 500 px focal length from 2 m: 4 cm.
  const InputOutcome out = front.addImageMotion(translation(1.0, 1.04, 10.0, 0.0));
  ASSERT_TRUE(out.metric.has_value()) << out.rejected << out.problem;
  ASSERT_TRUE(out.update.has_value());
  EXPECT_EQ(out.update->status, UpdateStatus::kApplied) << out.update->detail;
  EXPECT_NEAR(out.metric->camera_displacement_en_m.norm(), 0.04, 1e-6);
  EXPECT_NEAR(std::abs(out.metric->camera_displacement_en_m.x()), 0.04, 1e-6);  // along the camera's x: east
  ASSERT_TRUE(out.camera_en_m.has_value());  // the image-only track moved by the same
  EXPECT_TRUE(out.camera_en_m->isApprox(out.metric->camera_displacement_en_m));
}

TEST(FusionFrontEnd, AnImagePairWithoutAttitudeOrHeightReachesTheFilterAsAFailure) {
  FusionFrontEnd front = makeFrontEnd();
  front.initialize(0.5, Eigen::Vector2d(0.0, 0.0), Eigen::Matrix2d::Identity() * 0.01);
  const InputOutcome no_attitude = front.addImageMotion(translation(1.0, 1.04, 10.0, 0.0));
  EXPECT_FALSE(no_attitude.metric.has_value());
  EXPECT_NE(no_attitude.problem.find("no attitude"), std::string::npos) << no_attitude.problem;
  ASSERT_TRUE(no_attitude.update.has_value());  // the time passes in the filter
  for (double t = 0.9; t <= 1.3; t += 0.1) front.addImuAttitude(t, yaw(0.0));
  const InputOutcome no_height = front.addImageMotion(translation(1.04, 1.08, 10.0, 0.0));
  EXPECT_NE(no_height.problem.find("no camera height"), std::string::npos) << no_height.problem;
  front.setOperatorHeight(2.0);
  const InputOutcome with_operator_height = front.addImageMotion(translation(1.08, 1.12, 10.0, 0.0));
  ASSERT_TRUE(with_operator_height.metric.has_value()) << with_operator_height.problem;
  EXPECT_NEAR(with_operator_height.metric->camera_displacement_en_m.norm(), 0.04, 1e-6);
}

TEST(FusionFrontEnd, WithoutAnAltimeterTheHeightComesFromTheDepthAndTheSeabedDepth) {
  FusionFrontEndConfig config;
  config.seabed_depth_m = 20.0;
  FusionFrontEnd front = makeFrontEnd(config);
  front.initialize(0.5, Eigen::Vector2d(0.0, 0.0), Eigen::Matrix2d::Identity() * 0.01);
  for (double t = 0.9; t <= 1.3; t += 0.1) front.addImuAttitude(t, yaw(0.0));
  const InputOutcome no_depth = front.addImageMotion(translation(1.0, 1.04, 10.0, 0.0));
  EXPECT_NE(no_depth.problem.find("~seabed_depth_m"), std::string::npos) << no_depth.problem;
  // base_link at 18 m, the camera level with it (its lever arm is horizontal): 2 m above a 20 m seabed.
  for (double t = 0.9; t <= 1.3; t += 0.1) front.addDepth(t, 18.0);
  const auto height = front.cameraHeightAt(1.1, yaw(0.0), rigMounts().at("camera"));
  ASSERT_TRUE(height.has_value());
  EXPECT_NEAR(*height, 2.0, 1e-9);
  const InputOutcome out = front.addImageMotion(translation(1.04, 1.08, 10.0, 0.0));
  ASSERT_TRUE(out.metric.has_value()) << out.problem;
  EXPECT_NEAR(out.metric->camera_displacement_en_m.norm(), 0.04, 1e-6);  // 10 px at 500 px from 2 m
  // A camera 0.3 m below base_link is 0.3 m nearer the seabed; an altimeter, when it speaks, wins.
  Eigen::Isometry3d low_camera = rigMounts().at("camera");
  low_camera.translation().z() = -0.3;
  EXPECT_NEAR(*front.cameraHeightAt(1.1, yaw(0.0), low_camera), 1.7, 1e-9);
  for (double t = 0.9; t <= 1.3; t += 0.1) front.addAltimeterRange(t, 3.0, "altimeter");
  EXPECT_NEAR(*front.cameraHeightAt(1.1, yaw(0.0), rigMounts().at("camera")), 3.0, 1e-9);
  // Deeper than the seabed: no height from the depth.
  FusionFrontEnd shallow = makeFrontEnd(config);
  shallow.addDepth(1.0, 25.0);
  EXPECT_FALSE(shallow.cameraHeightAt(1.0, yaw(0.0), rigMounts().at("camera")).has_value());
  config.seabed_depth_m = -1.0;
  EXPECT_THROW(makeFrontEnd(config), std::invalid_argument);
}

TEST(FusionFrontEnd, BadImageMotionsAreRejectedNamingTheFault) {
  FusionFrontEnd front = makeFrontEnd();
  feedLevelSensors(&front, 0.0, 2.0);
  front.initialize(0.5, Eigen::Vector2d(0.0, 0.0), Eigen::Matrix2d::Identity() * 0.01);
  ImageMotionInput bad_model = translation(1.0, 1.04, 1.0, 0.0);
  bad_model.model = "spline";
  EXPECT_FALSE(front.addImageMotion(bad_model).rejected.empty());
  ImageMotionInput bad_size = translation(1.04, 1.08, 1.0, 0.0);
  bad_size.model = "similarity";
  EXPECT_NE(front.addImageMotion(bad_size).rejected.find("sizes do not match"), std::string::npos);
  ImageMotionInput nan = translation(1.08, 1.12, std::nan(""), 0.0);
  EXPECT_NE(front.addImageMotion(nan).rejected.find("non-finite"), std::string::npos);
  ImageMotionInput no_k = translation(1.12, 1.16, 1.0, 0.0);
  no_k.camera_matrix.reset();
  EXPECT_NE(front.addImageMotion(no_k).rejected.find("no camera matrix"), std::string::npos);
  front.setCameraMatrix(camera());  // the camera_info's K stands in
  EXPECT_TRUE(front.addImageMotion(no_k).metric.has_value());
  ImageMotionInput backwards = translation(2.0, 1.9, 1.0, 0.0);
  const InputOutcome refused = front.addImageMotion(backwards);
  EXPECT_NE(refused.rejected.find("previous_stamp"), std::string::npos);
  EXPECT_FALSE(refused.update.has_value());
}

TEST(FusionFrontEnd, WithoutNavigationTheOperatorsPointStartsTheImagesAndTheirRotationCarriesTheHeading) {
  FusionFrontEnd front = makeFrontEnd();
  const InputOutcome waiting = front.addImageMotion(translation(1.0, 1.04, 10.0, 0.0));
  ASSERT_TRUE(waiting.update.has_value());
  EXPECT_EQ(waiting.update->status, UpdateStatus::kNotInitialized);
  front.setOperatorStart(Eigen::Vector2d(500.0, 600.0), 2.0);
  front.setOperatorHeading(0.0);
  front.setOperatorHeight(2.0);
  const InputOutcome first = front.addImageMotion(translation(1.04, 1.08, 10.0, 0.0));
  EXPECT_EQ(first.started_from, "the operator's first point");
  ASSERT_TRUE(first.metric.has_value()) << first.problem << first.rejected;
  const Eigen::Vector2d east_step = first.metric->camera_displacement_en_m;
  // The image turns by 90 degrees about its centre: the vehicle yawed by 90 degrees; the next translation goes
  // along the new heading.
  ImageMotionInput turn = translation(1.08, 1.12, 0.0, 0.0);
  turn.model = "similarity";
  turn.parameters = Eigen::Vector4d(0.0, 0.0, -1.0, 1.0);  // (1+a) = 0, b = 1: a rotation by +90 degrees
  turn.covariance = Eigen::Matrix4d::Identity() * 1e-4;
  const Eigen::Matrix3d rotation = (Eigen::Matrix3d() << 0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0).finished();
  Eigen::Matrix3d to_centre = Eigen::Matrix3d::Identity(), from_centre = Eigen::Matrix3d::Identity();
  to_centre.col(2).head<2>() = -turn.centre_px;
  from_centre.col(2).head<2>() = turn.centre_px;
  turn.pixel_matrix = from_centre * rotation * to_centre;
  ASSERT_TRUE(front.addImageMotion(turn).metric.has_value());
  const InputOutcome after = front.addImageMotion(translation(1.12, 1.16, 10.0, 0.0));
  ASSERT_TRUE(after.metric.has_value());
  const Eigen::Vector2d turned_step = after.metric->camera_displacement_en_m;
  EXPECT_NEAR(turned_step.norm(), east_step.norm(), 1e-6);
  EXPECT_NEAR(std::abs(turned_step.dot(east_step)) / (east_step.squaredNorm()), 0.0, 1e-6);  // perpendicular
}

TEST(FusionFrontEnd, AViewWindowAveragesTheAttitudeAndAltimeterNoise) {
  FusionFrontEndConfig config;
  config.view_half_window_s = 1.0;
  config.altimeter_sigma_m = 0.02;
  FusionFrontEnd smoothed = makeFrontEnd(config);
  FusionFrontEnd raw = makeFrontEnd();
  std::mt19937 rng(7);
  std::normal_distribution<double> roll_noise(0.0, 0.01), range_noise(0.0, 0.02);
  for (double t = 0.0; t <= 4.0 + 1e-9; t += 0.02) {
    const double roll = 0.05 + roll_noise(rng);
    const Eigen::Quaterniond q(Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()));
    const double range = 2.0 + 0.1 * t + range_noise(rng);  // a slope: the quadratic keeps it
    for (FusionFrontEnd* f : {&smoothed, &raw}) {
      f->addImuAttitude(t, q);
      f->addAltimeterRange(t, range, "altimeter");
    }
  }
  const Eigen::Isometry3d camera_mount = rigMounts().at("camera");
  double smoothed_roll_sq = 0.0, raw_roll_sq = 0.0, smoothed_h_sq = 0.0, raw_h_sq = 0.0;
  int n = 0;
  for (double t = 1.2; t <= 2.8; t += 0.1, ++n) {
    const auto vs = smoothed.viewAt(t, camera_mount), vr = raw.viewAt(t, camera_mount);
    ASSERT_TRUE(vs && vr);
    const auto roll_of = [](const Eigen::Quaterniond& q) {
      const Eigen::Matrix3d r = q.toRotationMatrix();
      return std::atan2(r(2, 1), r(2, 2));
    };
    smoothed_roll_sq += std::pow(roll_of(vs->world_from_base) - 0.05, 2);
    raw_roll_sq += std::pow(roll_of(vr->world_from_base) - 0.05, 2);
    const double true_height = (2.0 + 0.1 * t) * std::cos(0.05);  // roughly; both are compared to the same value
    smoothed_h_sq += std::pow(vs->camera_height_m - true_height, 2);
    raw_h_sq += std::pow(vr->camera_height_m - true_height, 2);
    EXPECT_GT(vs->camera_height_sigma_m, 0.0);
    EXPECT_LT(vs->camera_height_sigma_m, 0.02 / 2.0);  // 100 samples: the fit's sigma is well below one sample's
    EXPECT_DOUBLE_EQ(vr->camera_height_sigma_m, 0.0);  // no sigma configured
  }
  EXPECT_LT(std::sqrt(smoothed_roll_sq / n), 0.5 * std::sqrt(raw_roll_sq / n));
  EXPECT_LT(std::sqrt(smoothed_h_sq / n), std::sqrt(raw_h_sq / n));
}

TEST(FusionFrontEnd, ResetForgetsTheFilterAndTheHistoriesButNotTheOperator) {
  FusionFrontEnd front = makeFrontEnd();
  feedLevelSensors(&front, 0.0, 1.0);
  front.setOperatorHeight(3.0);
  front.addDeadReckoning(0.5, Eigen::Vector3d(1.0, 2.0, 0.0), Eigen::Matrix2d::Identity());
  ASSERT_TRUE(front.filter().initialized());
  front.reset();
  EXPECT_FALSE(front.filter().initialized());
  EXPECT_FALSE(front.attitudeAt(0.5).has_value());
  EXPECT_FALSE(front.imageOnlyPosition().has_value());
  EXPECT_DOUBLE_EQ(*front.cameraHeightAt(0.5, yaw(0.0), rigMounts().at("camera")), 3.0);
}

TEST(FusionFrontEnd, BadSettingsAreNamed) {
  FusionFrontEndConfig config;
  config.view_half_window_s = 20.0;
  EXPECT_NE(config.validate().find("view_half_window_s"), std::string::npos);
  try {
    makeFrontEnd(config);
    FAIL() << "a 20 s view window was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("view_half_window_s = 20"), std::string::npos) << e.what();
  }
  config = FusionFrontEndConfig();
  config.altimeter_sigma_m = -1.0;
  EXPECT_NE(config.validate().find("altimeter_sigma_m"), std::string::npos);
  EXPECT_THROW(FusionFrontEnd(FusionFrontEndConfig(), MountLookup()), std::invalid_argument);
}

}  // namespace
}  // namespace fusion
}  // namespace exocet_mosaic
