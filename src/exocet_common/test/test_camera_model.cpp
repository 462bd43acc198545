// CameraModel: projection and distortion against OpenCV's, the Newton undistortion, validation messages, and the
// camera_calibration_parsers YAML read back as written (long and short forms).
#include <cmath>
#include <fstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>

#include "exocet_common/camera_model.h"
#include "exocet_common/testing/temp_dir.h"

using exocet_common::CameraModel;

namespace {

CameraModel distortedCamera() {
  CameraModel c = CameraModel::pal(70.0);
  c.cx += 3.5;
  c.cy -= 2.0;
  c.distortion = {{-0.21, 0.08, 0.0012, -0.0007, -0.015}};
  return c;
}

}  // namespace

TEST(CameraModel, ProjectsLikeOpenCvProjectPoints) {
  const CameraModel c = distortedCamera();
  std::vector<cv::Point3d> points;
  for (double x = -0.5; x <= 0.5; x += 0.25)
    for (double y = -0.4; y <= 0.4; y += 0.2) points.emplace_back(x, y, 1.3);
  std::vector<cv::Point2d> expected;
  cv::projectPoints(points, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), cv::Mat(c.K()), c.distortionCoeffs(), expected);
  for (size_t i = 0; i < points.size(); ++i) {
    Eigen::Vector2d pixel;
    ASSERT_TRUE(c.project(Eigen::Vector3d(points[i].x, points[i].y, points[i].z), &pixel));
    EXPECT_NEAR(pixel.x(), expected[i].x, 1e-9);
    EXPECT_NEAR(pixel.y(), expected[i].y, 1e-9);
  }
  Eigen::Vector2d pixel;
  EXPECT_FALSE(c.project(Eigen::Vector3d(0.1, 0.1, -1.0), &pixel)) << "a point behind the camera has no pixel";
}

TEST(CameraModel, UndistortionInvertsDistortionOverTheImage) {
  const CameraModel c = distortedCamera();
  for (double x = -0.6; x <= 0.6; x += 0.1)
    for (double y = -0.45; y <= 0.45; y += 0.09) {
      const Eigen::Vector2d xy(x, y);
      EXPECT_LT((c.undistortNormalized(c.distortNormalized(xy)) - xy).norm(), 1e-12) << x << ", " << y;
    }
  const cv::Mat rays = c.rayMap();
  ASSERT_EQ(rays.rows, c.height);
  ASSERT_EQ(rays.cols, c.width);
  // The ray of a pixel projects back onto that pixel.
  const cv::Vec2f ray = rays.at<cv::Vec2f>(100, 600);
  Eigen::Vector2d pixel;
  ASSERT_TRUE(c.project(Eigen::Vector3d(ray[0], ray[1], 1.0), &pixel));
  EXPECT_NEAR(pixel.x(), 600.0, 1e-3);
  EXPECT_NEAR(pixel.y(), 100.0, 1e-3);
}

TEST(CameraModel, ValidateNamesEveryBadField) {
  EXPECT_EQ(CameraModel::hd().validate(), "");
  const CameraModel uhd = CameraModel::uhd(60.0);
  EXPECT_EQ(uhd.validate(), "");
  EXPECT_EQ(uhd.width, 3840);
  EXPECT_EQ(uhd.height, 2160);
  EXPECT_NEAR(uhd.fx, 0.5 * 3840 / std::tan(30.0 * M_PI / 180.0), 1e-9);
  CameraModel c = CameraModel::pal();
  c.width = 8;
  c.fx = -1.0;
  c.cy = 900.0;
  c.distortion[0] = std::nan("");
  const std::string problem = c.validate();
  EXPECT_NE(problem.find("camera width 8 out of range [16, 16384]"), std::string::npos) << problem;
  EXPECT_NE(problem.find("focal lengths"), std::string::npos) << problem;
  EXPECT_NE(problem.find("principal point"), std::string::npos) << problem;
  EXPECT_NE(problem.find("distortion coefficients"), std::string::npos) << problem;
}

TEST(CameraModel, YamlRoundTripAndShortForm) {
  exocet_common::testing::TempDir dir("camera_model");
  const CameraModel c = distortedCamera();
  const std::string path = dir.path() + "/camera.yaml";
  exocet_common::saveCameraModelYaml(path, c, "left");
  const CameraModel back = exocet_common::loadCameraModelYaml(path);
  EXPECT_EQ(back.width, c.width);
  EXPECT_EQ(back.height, c.height);
  EXPECT_DOUBLE_EQ(back.fx, c.fx);
  EXPECT_DOUBLE_EQ(back.cy, c.cy);
  for (int i = 0; i < 5; ++i) EXPECT_DOUBLE_EQ(back.distortion[i], c.distortion[i]);

  const std::string short_path = dir.path() + "/short.yaml";
  std::ofstream(short_path) << "image_width: 968\nimage_height: 608\nK: [800, 0, 484, 0, 801, 304, 0, 0, 1]\n"
                               "D: [-0.1, 0.02, 0, 0]\n";
  const CameraModel s = exocet_common::loadCameraModelYaml(short_path);
  EXPECT_EQ(s.width, 968);
  EXPECT_DOUBLE_EQ(s.fy, 801.0);
  EXPECT_DOUBLE_EQ(s.distortion[0], -0.1);
  EXPECT_DOUBLE_EQ(s.distortion[4], 0.0);
}

TEST(CameraModel, LoadRefusesBadFilesNamingTheFileAndField) {
  exocet_common::testing::TempDir dir("camera_model_bad");
  const std::string path = dir.path() + "/bad.yaml";
  std::ofstream(path) << "image_width: 640\nimage_height: 480\nK: [500, 0, 320, 0, 500]\n";
  try {
    exocet_common::loadCameraModelYaml(path);
    FAIL() << "a 5-number camera matrix was accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("'camera_matrix' must hold 9 numbers"), std::string::npos) << e.what();
  }
  EXPECT_THROW(exocet_common::loadCameraModelYaml(dir.path() + "/missing.yaml"), std::runtime_error);
}
