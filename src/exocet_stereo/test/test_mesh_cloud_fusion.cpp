// Fusion of depth maps into one cloud and its surface, on exocet_servo's ray-cast vent (exact depth maps, known
// geometry): accuracy and coverage of the fused cloud, removal of injected outliers by the multi-view consistency
// check, and the accuracy and PLY export of the surface.
#include <stdlib.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "exocet_servo/sim/point_scene.h"
#include "exocet_servo/sim/vent_renderer.h"
#include "exocet_stereo/io/mesh_export.h"
#include "exocet_stereo/mesh/cloud_fusion.h"
#include "exocet_stereo/mesh/cloud_surface.h"

namespace {

namespace fs = std::filesystem;
namespace sim = exocet_servo::sim;
using exocet_stereo::mesh::CloudFusionConfig;
using exocet_stereo::mesh::CloudFusionStats;
using exocet_stereo::mesh::CloudSurfaceConfig;
using exocet_stereo::mesh::CloudSurfaceStats;
using exocet_stereo::mesh::DepthView;
using exocet_stereo::mesh::FusedCloud;
using exocet_stereo::mesh::TexturedMesh;

/// The default vent (0.3 m high, radius 0.1 m at the base, 0.05 m at the top) seen by a ring of cameras.
class VentRing : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    sim::VentSceneConfig scene;
    scene.supersampling = 1;  // the depth is exact per pixel centre anyway
    renderer_ = new sim::VentRenderer(scene);
    sim::PinholeCamera camera;
    camera.k = sim::intrinsics(400.0, 400.0, 159.5, 119.5);
    camera.width_px = 320;
    camera.height_px = 240;
    const int n = 6;
    for (int i = 0; i < n; ++i) {
      const double a = 2.0 * M_PI * i / n + 0.3;
      const Eigen::Isometry3d pose =
          sim::lookAt(Eigen::Vector3d(0.6 * std::cos(a), 0.6 * std::sin(a), 0.4), Eigen::Vector3d(0, 0, 0.15));
      const sim::RenderedView rendered = renderer_->render(camera, pose);
      DepthView view;
      view.K = camera.k;
      view.world_T_camera = pose;
      view.depth_m = rendered.depth_m;
      view.image = rendered.image;
      views_->push_back(view);
    }
  }
  static void TearDownTestSuite() {
    delete renderer_;
    renderer_ = nullptr;
    views_->clear();
  }

  static CloudFusionConfig exactConfig() {
    CloudFusionConfig config;
    config.voxel_m = 0.001;
    config.depth_tolerance = 0.005;
    config.min_confirmations = 1;
    return config;
  }
  /// Around the chimney (excludes the seabed far away).
  static FusedCloud crop(const FusedCloud& cloud) {
    return cloud.cropped(Eigen::Vector3d(-0.15, -0.15, -0.01), Eigen::Vector3d(0.15, 0.15, 0.32));
  }
  /// Exact distance to the vent, rims included.
  static double distance(const Eigen::Vector3d& p) { return renderer_->distanceToSurface(p); }
  static double maxDistance(const std::vector<Eigen::Vector3d>& points) {
    double worst = 0.0;
    for (const auto& p : points) worst = std::max(worst, distance(p));
    return worst;
  }
  static double rmsDistance(const std::vector<Eigen::Vector3d>& points) {
    double sum2 = 0.0;
    for (const auto& p : points) sum2 += std::pow(distance(p), 2);
    return std::sqrt(sum2 / std::max<size_t>(1, points.size()));
  }

  static sim::VentRenderer* renderer_;
  static std::vector<DepthView>* views_;
};
sim::VentRenderer* VentRing::renderer_ = nullptr;
std::vector<DepthView>* VentRing::views_ = new std::vector<DepthView>();

TEST(CloudFusionConfig, ValidateListsEveryBadField) {
  EXPECT_EQ(CloudFusionConfig().validate(), "");
  CloudFusionConfig bad;
  bad.min_confirmations = -1;
  bad.depth_tolerance = 0.0;
  bad.voxel_m = -1.0;
  bad.max_incidence_deg = 95.0;
  const std::string message = bad.validate();
  for (const char* field : {"min_confirmations", "depth_tolerance", "voxel_m", "max_incidence_deg"})
    EXPECT_NE(message.find(field), std::string::npos) << message;
  EXPECT_THROW(exocet_stereo::mesh::fuseDepthMaps({}, bad), std::invalid_argument);
  EXPECT_EQ(CloudSurfaceConfig().validate(), "");
  CloudSurfaceConfig bad_surface;
  bad_surface.cell_m = 0.01;
  bad_surface.radius_m = 0.001;  // below cell_m
  EXPECT_NE(bad_surface.validate().find("radius_m"), std::string::npos);
}

TEST(CloudFusion, RejectsMalformedViews) {
  DepthView view;
  view.depth_m = cv::Mat(10, 10, CV_64FC1, cv::Scalar(1.0));
  EXPECT_THROW(exocet_stereo::mesh::fuseDepthMaps({view}, CloudFusionConfig()), std::invalid_argument);
  view.depth_m = cv::Mat(10, 10, CV_32FC1, cv::Scalar(1.0));
  view.image = cv::Mat(5, 5, CV_8UC1);
  EXPECT_THROW(exocet_stereo::mesh::fuseDepthMaps({view}, CloudFusionConfig()), std::invalid_argument);
}

TEST_F(VentRing, ExactDepthMapsFuseOnTheSurfaceAllAroundTheChimney) {
  CloudFusionStats stats;
  const FusedCloud cloud = exocet_stereo::mesh::fuseDepthMaps(*views_, exactConfig(), &stats);
  ASSERT_GT(cloud.size(), 10000u);
  ASSERT_EQ(cloud.normals.size(), cloud.size());
  ASSERT_EQ(cloud.colors.size(), cloud.size());
  ASSERT_EQ(cloud.confirmations.size(), cloud.size());
  EXPECT_LT(maxDistance(cloud.points), 0.001);
  std::cout << cloud.size() << " fused points, max distance " << maxDistance(cloud.points) * 1e3 << " mm, "
            << stats.unconfirmed << " unconfirmed, " << stats.discontinuity << " on discontinuities\n";
  for (int c : cloud.confirmations) ASSERT_GE(c, 1);
  EXPECT_GT(stats.unconfirmed, 0);    // parts seen by one camera only
  EXPECT_GT(stats.discontinuity, 0);  // silhouettes

  // Points on every side of the chimney and on its top; normals point out of the cone.
  std::vector<int> per_sector(8, 0);
  int top = 0, outward = 0, side = 0;
  for (size_t i = 0; i < cloud.size(); ++i) {
    const Eigen::Vector3d& p = cloud.points[i];
    const double rho = std::hypot(p.x(), p.y());
    if (p.z() > 0.02 && p.z() < 0.28 && rho > 0.04) {
      ++per_sector[static_cast<int>(std::floor((std::atan2(p.y(), p.x()) + M_PI) / (2 * M_PI) * 8)) % 8];
      ++side;
      outward += cloud.normals[i].dot(Eigen::Vector3d(p.x(), p.y(), 0).normalized()) > 0.8 ? 1 : 0;
    }
    if (p.z() > 0.299 && rho < 0.05) ++top;
  }
  for (int s = 0; s < 8; ++s) EXPECT_GT(per_sector[s], 300) << "sector " << s;
  EXPECT_GT(top, 300);
  EXPECT_GT(outward, 0.95 * side);
}

TEST_F(VentRing, ViewsWithoutImagesGiveTheSameCloudWithoutColours) {
  std::vector<DepthView> bare = *views_;
  for (auto& view : bare) view.image = cv::Mat();
  const FusedCloud coloured = exocet_stereo::mesh::fuseDepthMaps(*views_, exactConfig());
  const FusedCloud cloud = exocet_stereo::mesh::fuseDepthMaps(bare, exactConfig());
  ASSERT_EQ(cloud.size(), coloured.size());
  EXPECT_TRUE(cloud.colors.empty());
  EXPECT_EQ(cloud.points.front(), coloured.points.front());
  EXPECT_EQ(cloud.points.back(), coloured.points.back());
}

TEST_F(VentRing, ConsistencyCheckRemovesGrossOutliers) {
  std::vector<DepthView> corrupted = *views_;
  corrupted[0].depth_m = (*views_)[0].depth_m.clone();
  cv::Mat& depth = corrupted[0].depth_m;
  // Smooth 12x12 patches pulled 10-25 % towards the camera: locally they look like surface (no discontinuity inside),
  // only another view can tell they float in the water.
  std::mt19937 rng(3);
  std::uniform_int_distribution<int> x_of(20, depth.cols - 32), y_of(20, depth.rows - 32);
  std::uniform_real_distribution<double> scale_of(0.75, 0.9);
  int patches = 0;
  for (int attempt = 0; attempt < 200 && patches < 25; ++attempt) {
    const cv::Rect patch(x_of(rng), y_of(rng), 12, 12);
    cv::Mat block = depth(patch);
    if (cv::checkRange(block, true, nullptr, 0.0, 10.0) == false) continue;  // only patches fully on nearby surface
    block *= scale_of(rng);
    ++patches;
  }
  ASSERT_EQ(patches, 25);

  CloudFusionConfig unchecked = exactConfig();
  unchecked.min_confirmations = 0;
  const FusedCloud polluted = exocet_stereo::mesh::fuseDepthMaps(corrupted, unchecked);
  int far = 0;
  for (const auto& p : polluted.points) far += distance(p) > 0.005 ? 1 : 0;
  EXPECT_GT(far, 25 * 20) << "the outliers must survive without the consistency check";
  std::cout << far << " points > 5 mm off without the check\n";

  CloudFusionStats stats;
  const FusedCloud cleaned = exocet_stereo::mesh::fuseDepthMaps(corrupted, exactConfig(), &stats);
  EXPECT_LT(maxDistance(cleaned.points), 0.001);
  std::cout << "with it: max distance " << maxDistance(cleaned.points) * 1e3 << " mm, " << stats.unconfirmed
            << " unconfirmed\n";
  EXPECT_GT(stats.unconfirmed, 25 * 50);
  EXPECT_GT(cleaned.size(), 10000u);
}

TEST_F(VentRing, SurfaceOfTheExactCloudIsAccurateAndExportsToPly) {
  const FusedCloud cloud = crop(exocet_stereo::mesh::fuseDepthMaps(*views_, exactConfig()));
  CloudSurfaceConfig config;
  config.cell_m = 0.002;
  config.radius_m = 0.005;
  CloudSurfaceStats stats;
  const TexturedMesh mesh = exocet_stereo::mesh::surfaceFromCloud(cloud, config, &stats);
  ASSERT_FALSE(mesh.empty());
  EXPECT_EQ(mesh.validate(), "");
  EXPECT_EQ(mesh.colors.size(), mesh.vertices.size());
  EXPECT_EQ(stats.triangles, static_cast<long>(mesh.triangles.size()));
  const double rms = rmsDistance(mesh.vertices);
  EXPECT_LT(rms, 0.00025) << "object 0.3 m high";
  std::cout << cloud.size() << " points -> " << mesh.vertices.size() << " vertices, " << mesh.triangles.size()
            << " triangles, vertex RMS " << rms * 1e3 << " mm, max " << maxDistance(mesh.vertices) * 1e3 << " mm, "
            << stats.removed_triangles << " triangles in small pieces\n";
  // Triangles face the cameras: on the chimney's side their normal points away from the axis.
  int outward = 0, side = 0;
  for (const auto& t : mesh.triangles) {
    const Eigen::Vector3d a = mesh.vertices[t[0]], b = mesh.vertices[t[1]], c = mesh.vertices[t[2]];
    const Eigen::Vector3d centre = (a + b + c) / 3.0;
    if (centre.z() < 0.03 || centre.z() > 0.27) continue;
    ++side;
    outward += (b - a).cross(c - a).dot(Eigen::Vector3d(centre.x(), centre.y(), 0)) > 0.0 ? 1 : 0;
  }
  EXPECT_GT(side, 1000);
  EXPECT_GT(outward, 0.98 * side);

  // PLY round trip through a minimal ASCII reader.
  std::string pattern = (fs::temp_directory_path() / "exocet_cloud_XXXXXX").string();
  const fs::path dir = mkdtemp(pattern.data());
  const std::string path = (dir / "vent.ply").string();
  exocet_stereo::io::writePly(path, mesh);
  std::ifstream in(path);
  std::string line;
  size_t vertex_count = 0, face_count = 0;
  while (std::getline(in, line) && line != "end_header") {
    std::istringstream s(line);
    std::string word, element;
    s >> word >> element;
    if (word == "element" && element == "vertex") s >> vertex_count;
    if (word == "element" && element == "face") s >> face_count;
  }
  ASSERT_EQ(vertex_count, mesh.vertices.size());
  ASSERT_EQ(face_count, mesh.triangles.size());
  double worst = 0.0;
  for (size_t i = 0; i < vertex_count; ++i) {
    ASSERT_TRUE(static_cast<bool>(std::getline(in, line)));
    std::istringstream s(line);
    Eigen::Vector3d v;
    s >> v.x() >> v.y() >> v.z();
    worst = std::max(worst, (v - mesh.vertices[i]).norm());
  }
  EXPECT_LT(worst, 1e-6);
  for (size_t i = 0; i < face_count; ++i) {
    ASSERT_TRUE(static_cast<bool>(std::getline(in, line)));
    std::istringstream s(line);
    int n, a, b, c;
    s >> n >> a >> b >> c;
    ASSERT_EQ(n, 3);
    ASSERT_EQ(Eigen::Vector3i(a, b, c), mesh.triangles[i]);
  }
  fs::remove_all(dir);
}

}  // namespace
