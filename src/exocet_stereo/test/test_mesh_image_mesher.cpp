// Image mesher and depth maps on analytic scenes seen by a known camera: a tilted plane, a sphere cap and a depth step.
#include <cmath>
#include <limits>
#include <random>

#include <gtest/gtest.h>
#include <Eigen/Geometry>
#include <Eigen/LU>
#include <opencv2/imgproc.hpp>

#include "exocet_stereo/mesh/depth_map.h"
#include "exocet_stereo/mesh/image_mesher.h"

using exocet_stereo::geometry::PinholeView;
namespace mesh = exocet_stereo::mesh;

namespace {

constexpr int kWidth = 320;
constexpr int kHeight = 240;
constexpr double kFocal = 400.0;
const double kNan = std::numeric_limits<double>::quiet_NaN();

/// Camera with a non-trivial pose, so the world frame differs from the camera frame.
PinholeView makeView() {
  PinholeView view;
  view.K << kFocal, 0, 160.0, 0, kFocal, 120.0, 0, 0, 1;
  view.R = (Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized())).toRotationMatrix();
  view.t = Eigen::Vector3d(0.5, -0.2, 1.0);
  return view;
}

Eigen::Vector3d toCamera(const PinholeView& view, const Eigen::Vector3d& X) { return view.R * X + view.t; }

/// Normalised ray (x', y', 1) of pixel (x, y).
Eigen::Vector3d ray(const PinholeView& view, double x, double y) { return view.K.inverse() * Eigen::Vector3d(x, y, 1); }

// Plane Z = 2 + 0.3 X - 0.1 Y in the camera frame.
double planeDepth(const Eigen::Vector3d& r) { return 2.0 / (1.0 - 0.3 * r.x() + 0.1 * r.y()); }
double planeDistance(const Eigen::Vector3d& Xc) {
  return std::abs(Xc.z() - 2.0 - 0.3 * Xc.x() + 0.1 * Xc.y()) / std::sqrt(1.0 + 0.09 + 0.01);
}

// Sphere of centre kCentre, radius kRadius in the camera frame; depth of the nearest hit or NaN.
const Eigen::Vector3d kCentre(0.1, -0.05, 3.0);
constexpr double kRadius = 1.0;
double sphereDepth(const Eigen::Vector3d& r) {
  // |s r - c|^2 = R^2: s^2 |r|^2 - 2 s r.c + |c|^2 - R^2 = 0, nearest root; Z = s since r.z() = 1.
  const double a = r.squaredNorm(), b = -2.0 * r.dot(kCentre), c = kCentre.squaredNorm() - kRadius * kRadius;
  const double disc = b * b - 4 * a * c;
  if (disc < 0) return kNan;
  return (-b - std::sqrt(disc)) / (2 * a);
}

template <typename F>
cv::Mat renderDepth(const PinholeView& view, F depth_of_ray) {
  cv::Mat depth(kHeight, kWidth, CV_64F);
  for (int y = 0; y < kHeight; ++y)
    for (int x = 0; x < kWidth; ++x) depth.at<double>(y, x) = depth_of_ray(ray(view, x, y));
  return depth;
}

cv::Mat randomImage() {
  cv::Mat image(kHeight, kWidth, CV_8UC3);
  cv::randu(image, 0, 255);
  return image;
}

/// Every triangle's normal must face the reference camera.
void expectFacingCamera(const mesh::TexturedMesh& m, const PinholeView& view) {
  int wrong = 0;
  for (const Eigen::Vector3i& t : m.triangles) {
    const Eigen::Vector3d &a = m.vertices[t[0]], &b = m.vertices[t[1]], &c = m.vertices[t[2]];
    if ((b - a).cross(c - a).dot(view.centre() - a) <= 0) ++wrong;
  }
  EXPECT_EQ(wrong, 0);
}

}  // namespace

TEST(MeshImageMesher, ConfigValidateListsEveryBadField) {
  mesh::ImageMesherConfig config;
  EXPECT_EQ(config.validate(), "");
  config.grid_step_px = 0;
  config.max_edge_depth_ratio = -1;
  config.max_edge_length_ratio = 0.5;
  config.min_area_px2 = -2;
  const std::string bad = config.validate();
  EXPECT_NE(bad.find("grid_step_px"), std::string::npos);
  EXPECT_NE(bad.find("max_edge_depth_ratio"), std::string::npos);
  EXPECT_NE(bad.find("max_edge_length_ratio"), std::string::npos);
  EXPECT_NE(bad.find("min_area_px2"), std::string::npos);
  EXPECT_THROW(mesh::meshFromDepth(cv::Mat::ones(10, 10, CV_32F), makeView(), cv::Mat(), config),
               std::invalid_argument);
}

TEST(MeshDepthMap, DisparityToDepthAndBackProjection) {
  mesh::RectifiedPairGeometry pair;
  pair.focal_px = kFocal;
  pair.baseline_m = 0.12;
  pair.doffs_px = 3.0;
  EXPECT_EQ(pair.validate(), "");
  cv::Mat disparity(2, 3, CV_32F);
  disparity.at<float>(0, 0) = 21.0f;  // Z = 400 * 0.12 / 24 = 2
  disparity.at<float>(0, 1) = 45.0f;  // Z = 1
  disparity.at<float>(0, 2) = std::numeric_limits<float>::quiet_NaN();
  disparity.at<float>(1, 0) = std::numeric_limits<float>::infinity();
  disparity.at<float>(1, 1) = -3.0f;  // d + doffs = 0: at infinity
  disparity.at<float>(1, 2) = -10.0f;
  const cv::Mat depth = mesh::depthFromDisparity(disparity, pair);
  EXPECT_NEAR(depth.at<float>(0, 0), 2.0, 1e-6);
  EXPECT_NEAR(depth.at<float>(0, 1), 1.0, 1e-6);
  EXPECT_TRUE(std::isnan(depth.at<float>(0, 2)));
  EXPECT_TRUE(std::isnan(depth.at<float>(1, 0)));
  EXPECT_TRUE(std::isnan(depth.at<float>(1, 1)));
  EXPECT_TRUE(std::isnan(depth.at<float>(1, 2)));
  pair.baseline_m = 0;
  EXPECT_THROW(mesh::depthFromDisparity(disparity, pair), std::invalid_argument);

  // Back-projection: each point re-projects onto its pixel at its depth, and carries the pixel's RGB.
  const PinholeView view = makeView();
  const cv::Mat plane = renderDepth(view, planeDepth);
  const cv::Mat image = randomImage();
  const mesh::PointCloud cloud = mesh::backProjectDepth(plane, view, image, 3);
  ASSERT_EQ(cloud.points.size(), static_cast<size_t>(((kWidth + 2) / 3) * ((kHeight + 2) / 3)));
  ASSERT_EQ(cloud.colors.size(), cloud.points.size());
  double max_px = 0, max_plane = 0;
  for (size_t i = 0; i < cloud.points.size(); ++i) {
    max_px = std::max(max_px, (view.project(cloud.points[i]) - cloud.pixels[i]).norm());
    max_plane = std::max(max_plane, planeDistance(toCamera(view, cloud.points[i])));
    const cv::Vec3b bgr =
        image.at<cv::Vec3b>(static_cast<int>(cloud.pixels[i].y()), static_cast<int>(cloud.pixels[i].x()));
    ASSERT_EQ(cloud.colors[i], cv::Vec3b(bgr[2], bgr[1], bgr[0]));
  }
  EXPECT_LT(max_px, 1e-9);
  EXPECT_LT(max_plane, 1e-9);
  EXPECT_THROW(mesh::backProjectDepth(plane, view, image, 0), std::invalid_argument);
  EXPECT_THROW(mesh::backProjectDepth(plane, view, cv::Mat(5, 5, CV_8UC3)), std::invalid_argument);
}

TEST(MeshImageMesher, TiltedPlaneGridIsFullyMeshedOnTheSurface) {
  const PinholeView view = makeView();
  mesh::ImageMesherConfig config;  // grid step 4
  mesh::MeshingStats stats;
  const mesh::TexturedMesh m = mesh::meshFromDepth(renderDepth(view, planeDepth), view, randomImage(), config, &stats);
  const int nx = kWidth / 4, ny = kHeight / 4;  // 80 x 60 grid points
  EXPECT_EQ(stats.used_points, nx * ny);
  // A full rectangular grid triangulates into exactly two triangles per cell.
  EXPECT_EQ(stats.triangles, 2 * (nx - 1) * (ny - 1));
  EXPECT_EQ(stats.removed_discontinuity + stats.removed_degenerate, 0);
  EXPECT_EQ(m.validate(), "");
  ASSERT_TRUE(m.hasTexture());
  EXPECT_EQ(m.colors.size(), m.vertices.size());
  double max_distance = 0, max_uv = 0;
  for (size_t i = 0; i < m.vertices.size(); ++i) {
    max_distance = std::max(max_distance, planeDistance(toCamera(view, m.vertices[i])));
    const Eigen::Vector2d px = view.project(m.vertices[i]);
    max_uv = std::max(
        max_uv,
        (Eigen::Vector2d((px.x() + 0.5) / kWidth, (px.y() + 0.5) / kHeight) - m.tex_coords[i]).cwiseAbs().maxCoeff());
  }
  EXPECT_LT(max_distance, 1e-9);
  EXPECT_LT(max_uv, 1e-9);  // texture coordinate = pixel / image size
  expectFacingCamera(m, view);
}

TEST(MeshImageMesher, SphereCapVerticesOnSurfaceAndTrianglesCoverTheDisc) {
  const PinholeView view = makeView();
  mesh::ImageMesherConfig config;
  config.grid_step_px = 4;
  mesh::MeshingStats stats;
  const cv::Mat depth = renderDepth(view, sphereDepth);
  const mesh::TexturedMesh m = mesh::meshFromDepth(depth, view, cv::Mat(), config, &stats);
  ASSERT_FALSE(m.empty());
  EXPECT_EQ(m.validate(), "");
  EXPECT_TRUE(m.colors.empty());
  double max_vertex = 0, max_sag = 0, min_sag = 1;
  for (const Eigen::Vector3d& X : m.vertices) {
    max_vertex = std::max(max_vertex, std::abs((toCamera(view, X) - kCentre).norm() - kRadius));
  }
  double area_px2 = 0;
  for (const Eigen::Vector3i& t : m.triangles) {
    const Eigen::Vector3d centroid = (m.vertices[t[0]] + m.vertices[t[1]] + m.vertices[t[2]]) / 3.0;
    const double sag = kRadius - (toCamera(view, centroid) - kCentre).norm();  // chord below the surface
    max_sag = std::max(max_sag, sag);
    min_sag = std::min(min_sag, sag);
    const Eigen::Vector2d a = view.project(m.vertices[t[0]]), b = view.project(m.vertices[t[1]]),
                          c = view.project(m.vertices[t[2]]);
    area_px2 += 0.5 * std::abs((b - a).x() * (c - a).y() - (b - a).y() * (c - a).x());
  }
  EXPECT_LT(max_vertex, 1e-9);
  EXPECT_GE(min_sag, -1e-12);  // a triangle inscribed in a sphere lies inside it
  EXPECT_LT(max_sag, 2e-3);    // and close to it: 4 px facets on a 1 m sphere at 3 m
  // Nearly two triangles per grid point (2n - 2 - hull), a few grazing ones at the silhouette removed.
  const int n = stats.used_points;
  EXPECT_GT(stats.triangles, 1.85 * n);
  EXPECT_LE(stats.triangles, 2 * n);
  // The mesh covers the visible disc: grid-sampled pixel count times the cell area.
  const double disc_px2 = cv::countNonZero(depth == depth);  // non-NaN pixels
  EXPECT_NEAR(area_px2 / disc_px2, 1.0, 0.05);
  expectFacingCamera(m, view);
  std::printf("sphere cap: %d points, %d triangles (%d discontinuity, %d degenerate removed), max sag %.2e m\n", n,
              stats.triangles, stats.removed_discontinuity, stats.removed_degenerate, max_sag);
}

TEST(MeshImageMesher, TrianglesAcrossDepthStepAreRemoved) {
  const PinholeView view = makeView();
  cv::Mat depth(kHeight, kWidth, CV_64F);
  depth.colRange(0, kWidth / 2).setTo(2.0);
  depth.colRange(kWidth / 2, kWidth).setTo(3.0);
  mesh::ImageMesherConfig config;
  mesh::MeshingStats stats;
  const mesh::TexturedMesh m = mesh::meshFromDepth(depth, view, cv::Mat(), config, &stats);
  const int nx_half = kWidth / 4 / 2, ny = kHeight / 4;
  EXPECT_EQ(stats.triangles, 2 * 2 * (nx_half - 1) * (ny - 1));  // both halves fully meshed
  EXPECT_EQ(stats.removed_discontinuity, 2 * (ny - 1));          // the strip of cells across the step
  int spanning = 0;
  for (const Eigen::Vector3i& t : m.triangles) {
    double z_min = 1e9, z_max = 0;
    for (int k = 0; k < 3; ++k) {
      z_min = std::min(z_min, view.depth(m.vertices[t[k]]));
      z_max = std::max(z_max, view.depth(m.vertices[t[k]]));
    }
    if (z_max - z_min > 0.5) ++spanning;
  }
  EXPECT_EQ(spanning, 0);

  // With the criterion relaxed the step is bridged: the test above can fail.
  config.max_edge_depth_ratio = 100;
  config.max_edge_length_ratio = 0;
  const mesh::TexturedMesh bridged = mesh::meshFromDepth(depth, view, cv::Mat(), config, &stats);
  EXPECT_EQ(stats.removed_discontinuity, 0);
  EXPECT_EQ(stats.triangles, 2 * (2 * nx_half - 1) * (ny - 1));
}

TEST(MeshImageMesher, SparsePointsGiveTheDelaunayTriangleCount) {
  const PinholeView view = makeView();
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> ux(0, kWidth - 1), uy(0, kHeight - 1);
  std::vector<Eigen::Vector2d> pixels;
  std::vector<Eigen::Vector3d> points;
  for (int i = 0; i < 300; ++i) {
    const Eigen::Vector2d px(ux(rng), uy(rng));
    const Eigen::Vector3d r = ray(view, px.x(), px.y());
    pixels.push_back(px);
    points.push_back(view.R.transpose() * (planeDepth(r) * r - view.t));
  }
  std::vector<cv::Point2f> hull_input;
  for (const Eigen::Vector2d& p : pixels) hull_input.emplace_back(static_cast<float>(p.x()), static_cast<float>(p.y()));
  // Outliers the mesher must drop: a repeated pixel, a NaN point, a point behind the camera.
  pixels.push_back(pixels[0]);
  points.push_back(points[5]);
  pixels.emplace_back(10, 10);
  points.push_back(Eigen::Vector3d(kNan, 0, 0));
  pixels.emplace_back(20, 20);
  points.push_back(view.R.transpose() * (Eigen::Vector3d(0, 0, -1) - view.t));

  mesh::ImageMesherConfig config;
  config.max_edge_depth_ratio = 100;  // random points make slivers: keep every Delaunay triangle here
  config.max_edge_length_ratio = 0;
  mesh::MeshingStats stats;
  const mesh::TexturedMesh m = mesh::meshFromPoints(pixels, points, view, cv::Size(kWidth, kHeight), config, &stats);
  EXPECT_EQ(stats.input_points, 303);
  EXPECT_EQ(stats.used_points, 300);
  std::vector<int> hull;
  cv::convexHull(hull_input, hull);
  EXPECT_EQ(stats.delaunay_triangles, 2 * 300 - 2 - static_cast<int>(hull.size()));  // Euler on a triangulated hull
  EXPECT_EQ(stats.triangles + stats.removed_degenerate, stats.delaunay_triangles);
  EXPECT_EQ(m.vertices.size(), 300u);
  EXPECT_EQ(m.validate(), "");
  EXPECT_FALSE(m.hasTexture());  // sparse meshing leaves the texture to the caller
  double max_distance = 0;
  for (const Eigen::Vector3d& X : m.vertices) max_distance = std::max(max_distance, planeDistance(toCamera(view, X)));
  EXPECT_LT(max_distance, 1e-9);
  EXPECT_DOUBLE_EQ(m.vertices[0].x(), points[0].x());  // input order, first point of a repeated pixel kept
  expectFacingCamera(m, view);

  EXPECT_THROW(mesh::meshFromPoints(pixels, {}, view, cv::Size(kWidth, kHeight), config), std::invalid_argument);
  EXPECT_TRUE(
      mesh::meshFromPoints({pixels[0], pixels[1]}, {points[0], points[1]}, view, cv::Size(kWidth, kHeight), config)
          .empty());
}

TEST(MeshImageMesher, DisparityMapOfAPlaneMeshesOnThePlane) {
  // Left rectified view at the world origin; disparity d = f B / Z of a fronto-parallel-ish plane.
  PinholeView view;
  view.K << kFocal, 0, 160.0, 0, kFocal, 120.0, 0, 0, 1;
  mesh::RectifiedPairGeometry pair;
  pair.focal_px = kFocal;
  pair.baseline_m = 0.1;
  const cv::Mat depth = renderDepth(view, planeDepth);
  cv::Mat disparity(depth.size(), CV_32F);
  for (int y = 0; y < kHeight; ++y)
    for (int x = 0; x < kWidth; ++x)
      disparity.at<float>(y, x) = static_cast<float>(kFocal * 0.1 / depth.at<double>(y, x));
  disparity.colRange(0, 40).setTo(std::numeric_limits<float>::quiet_NaN());  // left band unknown (occlusion)
  mesh::ImageMesherConfig config;
  mesh::MeshingStats stats;
  const mesh::TexturedMesh m =
      mesh::meshFromDisparity(disparity, pair, view, cv::Mat(kHeight, kWidth, CV_8UC1, cv::Scalar(90)), config, &stats);
  EXPECT_EQ(stats.used_points, (kWidth - 40) / 4 * (kHeight / 4));
  EXPECT_EQ(stats.triangles, 2 * ((kWidth - 40) / 4 - 1) * (kHeight / 4 - 1));
  double max_distance = 0;
  for (const Eigen::Vector3d& X : m.vertices) max_distance = std::max(max_distance, planeDistance(X));
  EXPECT_LT(max_distance, 2e-6);  // float disparities
  ASSERT_FALSE(m.colors.empty());
  EXPECT_EQ(m.colors[0], cv::Vec3b(90, 90, 90));
}
