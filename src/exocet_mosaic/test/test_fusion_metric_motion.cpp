// Metric conversion (2D3 section 3.3): image motion in pixels -> camera displacement on the seabed in metres,
// checked against the simulator's exact seabed-plane homography between two known camera poses.
#include <cmath>
#include <limits>
#include <random>

#include <Eigen/Dense>
#include <gtest/gtest.h>

#include "exocet_mosaic/fusion/metric_motion.h"
#include "exocet_mosaic/registration/motion_model.h"
#include "exocet_common/camera_model.h"
#include "exocet_mosaic/sim/dive_synthesizer.h"
#include "exocet_mosaic/sim/image_motion_truth.h"
#include "exocet_mosaic/sim/vehicle_trajectory.h"

namespace {

using namespace exocet_mosaic;
using fusion::CameraMount;
using fusion::MetricMotion;
using fusion::ViewGeometry;
using registration::MotionModel;

constexpr double kDeg = M_PI / 180.0;

Eigen::Matrix3d cameraMatrix(const exocet_common::CameraModel& c) {
  Eigen::Matrix3d k;
  k << c.fx, 0.0, c.cx, 0.0, c.fy, c.cy, 0.0, 0.0, 1.0;
  return k;
}

struct Pose {
  Eigen::Vector3d base_position;  ///< local frame, seabed plane z = 0
  Eigen::Matrix3d world_from_base;
};

Eigen::Isometry3d cameraPose(const Pose& p, const sim::CameraRig& rig) {
  Eigen::Isometry3d world_from_base = Eigen::Isometry3d::Identity();
  world_from_base.linear() = p.world_from_base;
  world_from_base.translation() = p.base_position;
  return world_from_base * rig.baseFromCamera();
}

ViewGeometry view(const Pose& p, const sim::CameraRig& rig) {
  ViewGeometry v;
  v.world_from_base = Eigen::Quaterniond(p.world_from_base);
  v.camera_height_m = cameraPose(p, rig).translation().z();
  return v;
}

/// Exact homography parameters between two poses, with a KLT-like parameter covariance.
struct TruePair {
  Eigen::VectorXd parameters;
  Eigen::MatrixXd covariance;
  Eigen::Vector2d centre;
  Eigen::Vector3d true_displacement;
};

TruePair truePair(const sim::CameraRig& rig, const Pose& a, const Pose& b, MotionModel model) {
  const exocet_common::CameraModel& cam = rig.camera;
  TruePair t;
  t.centre = Eigen::Vector2d(0.5 * (cam.width - 1), 0.5 * (cam.height - 1));
  const Eigen::Matrix3d h = sim::seabedPlaneHomography(cam, cameraPose(a, rig), cameraPose(b, rig));
  t.parameters = registration::parametersFromPixelMatrix(model, h, t.centre, cam.width, cam.height);
  const int n = registration::parameterCount(model);
  t.covariance = Eigen::MatrixXd::Zero(n, n);
  t.covariance(0, 0) = t.covariance(1, 1) = 0.01;  // 0.1 px on the translation
  for (int i = 2; i < n; ++i) t.covariance(i, i) = i < 6 ? 1e-8 : 1e-12;
  t.true_displacement = cameraPose(b, rig).translation() - cameraPose(a, rig).translation();
  return t;
}

sim::CameraRig tiltedRig() {
  sim::CameraRig rig;
  rig.camera = exocet_common::CameraModel::pal(60.0);
  rig.lever_arm_m = Eigen::Vector3d(0.4, 0.1, -0.3);
  rig.mounting_rpy_deg = Eigen::Vector3d(2.0, -1.5, 3.0);
  return rig;
}

}  // namespace

TEST(MetricMotion, RecoversTheTrueDisplacementWithAttitudeLeverArmAndAltitudeChange) {
  const sim::CameraRig rig = tiltedRig();
  CameraMount mount;
  mount.camera_matrix = cameraMatrix(rig.camera);
  mount.base_from_camera = rig.baseFromCamera();
  const Pose a{Eigen::Vector3d(1.0, 2.0, 2.5), sim::rotationFromRpy(3.0 * kDeg, -4.0 * kDeg, 30.0 * kDeg)};
  const Pose b{Eigen::Vector3d(1.12, 2.07, 2.8), sim::rotationFromRpy(-2.0 * kDeg, 2.5 * kDeg, 35.0 * kDeg)};
  const TruePair t = truePair(rig, a, b, MotionModel::kHomography);
  const MetricMotion m = fusion::toMetricMotion(MotionModel::kHomography, t.parameters, t.covariance, t.centre, mount,
                                                view(a, rig), view(b, rig));
  ASSERT_TRUE(m.valid) << m.error;
  EXPECT_LT((m.camera_displacement_en_m - t.true_displacement.head<2>()).norm(), 1e-3);
  EXPECT_LT((m.camera_displacement_en_m - t.true_displacement.head<2>()).norm(), 1e-8);  // exact, in fact
  EXPECT_NEAR(m.height_change_m, t.true_displacement.z(), 1e-8);
  EXPECT_NEAR(m.ground_sample_distance_m, view(a, rig).camera_height_m / rig.camera.fx, 1e-12);
  // The covariance is a proper 2x2 covariance of about 0.1 px times the pixel size.
  const double pixel = view(a, rig).camera_height_m / rig.camera.fx;
  EXPECT_GT(m.covariance_m2.determinant(), 0.0);
  EXPECT_NEAR(std::sqrt(m.covariance_m2.trace() / 2.0), 0.1 * pixel, 0.03 * pixel);

  // A large motion (40 cm, a tenth of the footprint) with a 20 deg turn: still exact.
  const Pose c{Eigen::Vector3d(1.3, 2.35, 2.2), sim::rotationFromRpy(1.0 * kDeg, 3.0 * kDeg, 50.0 * kDeg)};
  const TruePair t2 = truePair(rig, a, c, MotionModel::kHomography);
  const MetricMotion m2 = fusion::toMetricMotion(MotionModel::kHomography, t2.parameters, t2.covariance, t2.centre,
                                                 mount, view(a, rig), view(c, rig));
  ASSERT_TRUE(m2.valid) << m2.error;
  EXPECT_LT((m2.camera_displacement_en_m - t2.true_displacement.head<2>()).norm(), 1e-3);
}

TEST(MetricMotion, CovarianceMatchesTheSpreadOfPerturbedParameters) {
  // Monte Carlo: parameters drawn from their covariance give displacements whose spread is the propagated covariance.
  const sim::CameraRig rig = tiltedRig();
  CameraMount mount;
  mount.camera_matrix = cameraMatrix(rig.camera);
  mount.base_from_camera = rig.baseFromCamera();
  const Pose a{Eigen::Vector3d(0.0, 0.0, 2.5), sim::rotationFromRpy(2.0 * kDeg, 1.0 * kDeg, 80.0 * kDeg)};
  const Pose b{Eigen::Vector3d(0.05, 0.09, 2.55), sim::rotationFromRpy(1.0 * kDeg, 2.0 * kDeg, 82.0 * kDeg)};
  TruePair t = truePair(rig, a, b, MotionModel::kHomography);
  Eigen::MatrixXd cov = t.covariance;
  cov(0, 2) = cov(2, 0) = 0.5 * std::sqrt(cov(0, 0) * cov(2, 2));  // some correlation
  const MetricMotion m =
      fusion::toMetricMotion(MotionModel::kHomography, t.parameters, cov, t.centre, mount, view(a, rig), view(b, rig));
  ASSERT_TRUE(m.valid) << m.error;
  const Eigen::MatrixXd L = cov.llt().matrixL();
  std::mt19937 rng(5);
  std::normal_distribution<double> n01;
  Eigen::Matrix2d sample_cov = Eigen::Matrix2d::Zero();
  const int draws = 4000;
  for (int i = 0; i < draws; ++i) {
    Eigen::VectorXd z(8);
    for (int k = 0; k < 8; ++k) z[k] = n01(rng);
    const MetricMotion d = fusion::toMetricMotion(MotionModel::kHomography, t.parameters + L * z,
                                                  Eigen::MatrixXd::Zero(8, 8), t.centre, mount, view(a, rig),
                                                  view(b, rig));
    ASSERT_TRUE(d.valid);
    const Eigen::Vector2d e = d.camera_displacement_en_m - m.camera_displacement_en_m;
    sample_cov += e * e.transpose() / draws;
  }
  EXPECT_NEAR(sample_cov(0, 0), m.covariance_m2(0, 0), 0.1 * m.covariance_m2(0, 0));
  EXPECT_NEAR(sample_cov(1, 1), m.covariance_m2(1, 1), 0.1 * m.covariance_m2(1, 1));
  EXPECT_NEAR(sample_cov(0, 1), m.covariance_m2(0, 1), 0.1 * std::sqrt(m.covariance_m2(0, 0) * m.covariance_m2(1, 1)));
}

TEST(MetricMotion, PixelSizeIsHeightOverAlphaOnANadirCamera) {
  EXPECT_NEAR(fusion::pixelSize_m(2.5, 623.5), 2.5 / 623.5, 1e-15);
  EXPECT_THROW(fusion::pixelSize_m(0.0, 600.0), std::invalid_argument);
  EXPECT_THROW(fusion::pixelSize_m(2.0, -1.0), std::invalid_argument);
  EXPECT_THROW(fusion::pixelSize_m(std::nan(""), 600.0), std::invalid_argument);

  // Nadir camera, level vehicle heading east: an image translation of t pixels is t * h / alpha metres.
  sim::CameraRig rig;
  rig.camera = exocet_common::CameraModel::pal(60.0);
  rig.lever_arm_m.setZero();
  CameraMount mount;
  mount.camera_matrix = cameraMatrix(rig.camera);
  mount.base_from_camera = rig.baseFromCamera();
  ViewGeometry level;
  level.camera_height_m = 2.5;
  const Eigen::Vector2d centre(359.5, 287.5);
  Eigen::VectorXd translation(2);
  translation << 10.0, -4.0;  // the scene moves right and up in the image
  const MetricMotion m = fusion::toMetricMotion(MotionModel::kTranslation, translation,
                                                0.01 * Eigen::MatrixXd::Identity(2, 2), centre, mount, level, level);
  ASSERT_TRUE(m.valid) << m.error;
  const double l = fusion::pixelSize_m(2.5, rig.camera.fx);
  EXPECT_NEAR(m.ground_sample_distance_m, l, 1e-15);
  // Image x is starboard (south when heading east), image y is aft (west): the scene moving right (+x) means the
  // camera moved to port (north); the scene moving up (-y, forward) means the camera moved aft (west).
  EXPECT_NEAR(m.camera_displacement_en_m.x(), -4.0 * l, 1e-12);
  EXPECT_NEAR(m.camera_displacement_en_m.y(), 10.0 * l, 1e-12);
  EXPECT_NEAR(m.covariance_m2(0, 0), 0.01 * l * l, 1e-6 * l * l);  // numerical Jacobian
  EXPECT_NEAR(m.covariance_m2(1, 1), 0.01 * l * l, 1e-6 * l * l);
  EXPECT_NEAR(m.covariance_m2(0, 1), 0.0, 1e-6 * l * l);

  // The height's sigma adds a scale uncertainty along the displacement.
  ViewGeometry noisy = level;
  noisy.camera_height_sigma_m = 0.02;
  const MetricMotion s = fusion::toMetricMotion(MotionModel::kTranslation, translation,
                                                0.01 * Eigen::MatrixXd::Identity(2, 2), centre, mount, noisy, level);
  ASSERT_TRUE(s.valid);
  const Eigen::Vector2d d = m.camera_displacement_en_m;
  const Eigen::Matrix2d expected = m.covariance_m2 + std::pow(0.02 / 2.5, 2) * d * d.transpose();
  EXPECT_LT((s.covariance_m2 - expected).norm(), 1e-6 * expected.norm());
}

TEST(MetricMotion, InvalidInputsGiveErrors) {
  const sim::CameraRig rig = tiltedRig();
  CameraMount mount;
  mount.camera_matrix = cameraMatrix(rig.camera);
  mount.base_from_camera = rig.baseFromCamera();
  const Pose a{Eigen::Vector3d(0.0, 0.0, 2.5), Eigen::Matrix3d::Identity()};
  const Pose b{Eigen::Vector3d(0.05, 0.0, 2.5), Eigen::Matrix3d::Identity()};
  const TruePair t = truePair(rig, a, b, MotionModel::kHomography);
  const auto run = [&](const Eigen::VectorXd& p, const Eigen::MatrixXd& c, const ViewGeometry& va,
                       const ViewGeometry& vb, const CameraMount& mo) {
    return fusion::toMetricMotion(MotionModel::kHomography, p, c, t.centre, mo, va, vb);
  };
  const ViewGeometry va = view(a, rig), vb = view(b, rig);
  ASSERT_TRUE(run(t.parameters, t.covariance, va, vb, mount).valid);

  ViewGeometry bad = va;
  bad.camera_height_m = 0.0;
  MetricMotion m = run(t.parameters, t.covariance, bad, vb, mount);
  EXPECT_FALSE(m.valid);
  EXPECT_NE(m.error.find("previous.camera_height_m"), std::string::npos) << m.error;
  bad.camera_height_m = -1.0;
  EXPECT_FALSE(run(t.parameters, t.covariance, va, bad, mount).valid);
  bad = va;
  bad.camera_height_m = std::numeric_limits<double>::infinity();
  EXPECT_FALSE(run(t.parameters, t.covariance, bad, vb, mount).valid);

  Eigen::VectorXd nan_params = t.parameters;
  nan_params[3] = std::nan("");
  m = run(nan_params, t.covariance, va, vb, mount);
  EXPECT_FALSE(m.valid);
  EXPECT_NE(m.error.find("parameters"), std::string::npos) << m.error;
  m = run(t.parameters.head(4), t.covariance, va, vb, mount);
  EXPECT_FALSE(m.valid);
  EXPECT_NE(m.error.find("needs 8"), std::string::npos) << m.error;
  Eigen::MatrixXd nan_cov = t.covariance;
  nan_cov(1, 1) = std::nan("");
  m = run(t.parameters, nan_cov, va, vb, mount);
  EXPECT_FALSE(m.valid);
  EXPECT_NE(m.error.find("parameter_covariance"), std::string::npos) << m.error;

  bad = va;
  bad.world_from_base.coeffs() << std::nan(""), 0, 0, 1;
  m = run(t.parameters, t.covariance, bad, vb, mount);
  EXPECT_FALSE(m.valid);
  EXPECT_NE(m.error.find("world_from_base"), std::string::npos) << m.error;

  // Upside down: the camera looks at the sky.
  bad = va;
  bad.world_from_base = Eigen::Quaterniond(Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()));
  m = run(t.parameters, t.covariance, bad, vb, mount);
  EXPECT_FALSE(m.valid);
  EXPECT_NE(m.error.find("misses the seabed"), std::string::npos) << m.error;

  // A singular motion.
  Eigen::VectorXd singular = Eigen::VectorXd::Zero(8);
  singular[2] = singular[5] = -1.0;
  m = run(singular, t.covariance, va, vb, mount);
  EXPECT_FALSE(m.valid);
  EXPECT_NE(m.error.find("singular"), std::string::npos) << m.error;

  CameraMount bad_mount = mount;
  bad_mount.camera_matrix(0, 0) = 0.0;
  m = run(t.parameters, t.covariance, va, vb, bad_mount);
  EXPECT_FALSE(m.valid);
  EXPECT_NE(m.error.find("camera_matrix"), std::string::npos) << m.error;
}

TEST(MetricMotion, CameraHeightFromAltimeterAndCameraPosition) {
  const Eigen::Vector3d altimeter(-0.2, 0.05, -0.15), camera(0.4, 0.0, -0.3);
  for (const Eigen::Vector3d& rpy_deg : {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(4, -6, 120)}) {
    const Eigen::Matrix3d r = sim::rotationFromRpy(rpy_deg.x() * kDeg, rpy_deg.y() * kDeg, rpy_deg.z() * kDeg);
    const double base_height = 3.0;  // base_link above the flat seabed z = 0
    // True range along the body's -z from the altimeter to the plane, and the camera's true height.
    const Eigen::Vector3d altimeter_world = Eigen::Vector3d(0, 0, base_height) + r * altimeter;
    const Eigen::Vector3d beam = -r.col(2);
    const double range = altimeter_world.z() / -beam.z();
    const double camera_height = base_height + (r * camera).z();
    EXPECT_NEAR(fusion::cameraHeightFromAltimeter_m(range, Eigen::Quaterniond(r), altimeter, camera), camera_height,
                1e-12);
  }
  const Eigen::Quaterniond level = Eigen::Quaterniond::Identity();
  EXPECT_NEAR(fusion::cameraHeightFromAltimeter_m(2.2, level, Eigen::Vector3d(0, 0, -0.1), camera), 2.0, 1e-12);
  EXPECT_THROW(fusion::cameraHeightFromAltimeter_m(std::nan(""), level, altimeter, camera), std::invalid_argument);
  EXPECT_THROW(fusion::cameraHeightFromAltimeter_m(-1.0, level, altimeter, camera), std::invalid_argument);
  EXPECT_THROW(fusion::cameraHeightFromAltimeter_m(0.05, level, altimeter, camera), std::invalid_argument);
  EXPECT_THROW(fusion::cameraHeightFromAltimeter_m(
                   2.0, Eigen::Quaterniond(Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX())), altimeter, camera),
               std::invalid_argument);

  Eigen::Isometry3d base_from_camera = Eigen::Isometry3d::Identity();
  base_from_camera.translation() = camera;
  const Eigen::Quaterniond yaw90(Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()));
  const Eigen::Vector3d c = fusion::cameraPosition(Eigen::Vector3d(100, 200, -40), yaw90, base_from_camera);
  EXPECT_NEAR(c.x(), 100.0, 1e-12);  // forward lever arm points north when heading north
  EXPECT_NEAR(c.y(), 200.4, 1e-12);
  EXPECT_NEAR(c.z(), -40.3, 1e-12);
}
