// Multi-view texture mapping of a fused surface, on exocet_servo's ray-cast vent (exact depth maps, known geometry,
// view-independent radiance when the water does not attenuate): the atlas colour at points of the textured triangles
// against the colour a separate ground-truth camera sees there, coverage, occlusion by the chimney, the per-view
// gains, the OBJ/MTL/PNG export, and the wiring into reconstructPairs().
#include <stdlib.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "exocet_common/testing/temp_dir.h"
#include "exocet_servo/sim/point_scene.h"
#include "exocet_servo/sim/vent_renderer.h"
#include "exocet_stereo/io/mesh_export.h"
#include "exocet_stereo/mesh/acquisition_reconstruction.h"
#include "exocet_stereo/mesh/cloud_fusion.h"
#include "exocet_stereo/mesh/cloud_surface.h"
#include "exocet_stereo/mesh/surface_texturing.h"

namespace {

namespace fs = std::filesystem;
namespace sim = exocet_servo::sim;
namespace mesh = exocet_stereo::mesh;
using mesh::SurfaceTexturingConfig;
using mesh::SurfaceTexturingStats;
using mesh::TexturedMesh;
using mesh::TextureView;

double secondsSince(const std::chrono::steady_clock::time_point& start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

/// Fresh empty folder under the temp dir, removed at the end of the test.
using TempDir = exocet_common::testing::TempDir;

/// The vent without attenuation (its radiance is the same from every camera) seen by a ring of six 640x480 cameras;
/// its surface from their exact depth maps; a seventh camera, between two of the ring and higher, is the ground truth.
class VentTexturing : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    sim::VentSceneConfig scene;
    scene.attenuation_per_m = 0.0;
    renderer_ = new sim::VentRenderer(scene);
    camera_.k = sim::intrinsics(800.0, 800.0, 319.5, 239.5);
    camera_.width_px = 640;
    camera_.height_px = 480;
    const Eigen::Vector3d target(0, 0, 0.15);
    std::vector<mesh::DepthView> depth_views;
    for (int i = 0; i < 6; ++i) {
      const double a = 2.0 * M_PI * i / 6 + 0.3;
      const Eigen::Isometry3d pose = sim::lookAt(Eigen::Vector3d(0.6 * std::cos(a), 0.6 * std::sin(a), 0.4), target);
      const sim::RenderedView rendered = renderer_->render(camera_, pose);
      mesh::DepthView depth;
      depth.K = camera_.k;
      depth.world_T_camera = pose;
      depth.depth_m = rendered.depth_m;
      depth_views.push_back(depth);
      TextureView view;
      view.image = rendered.image;
      view.K = camera_.k;
      view.world_T_camera = pose;
      views_->push_back(view);
    }
    const double a = 2.0 * M_PI * 0.5 / 6 + 0.3;
    truth_pose_ = new Eigen::Isometry3d(
        sim::lookAt(Eigen::Vector3d(0.5 * std::cos(a), 0.5 * std::sin(a), 0.55), Eigen::Vector3d(0, 0, 0.1)));
    truth_ = new sim::RenderedView(renderer_->render(camera_, *truth_pose_));

    mesh::CloudFusionConfig fusion;
    fusion.voxel_m = 0.001;
    fusion.depth_tolerance = 0.005;
    fusion.step_px = 2;
    const mesh::FusedCloud cloud = mesh::fuseDepthMaps(depth_views, fusion)
                                       .cropped(Eigen::Vector3d(-0.2, -0.2, -0.01), Eigen::Vector3d(0.2, 0.2, 0.32));
    mesh::CloudSurfaceConfig surface;
    surface.cell_m = 0.003;  // fewer triangles (~0.3 M): a faster test, the same mapping
    surface.radius_m = 0.0075;
    *surface_ = mesh::surfaceFromCloud(cloud, surface);
    surface_->colors.clear();  // untextured triangles must show the configured grey
  }
  static void TearDownTestSuite() {
    delete renderer_;
    delete truth_;
    delete truth_pose_;
    renderer_ = nullptr;
    truth_ = nullptr;
    truth_pose_ = nullptr;
    views_->clear();
    *surface_ = TexturedMesh();
  }

  /// Depth (Z, m) of a world point in a camera, and its pixel.
  static double project(const Eigen::Isometry3d& world_T_camera, const Eigen::Vector3d& p_w, Eigen::Vector2d* px) {
    const Eigen::Vector3d c = world_T_camera.inverse() * p_w;
    const Eigen::Vector3d h = camera_.k * c;
    *px = h.head<2>() / h.z();
    return c.z();
  }
  /// True when the scene hides the world point in the camera (something nearer by more than 2 % along its ray).
  static bool hiddenIn(const Eigen::Isometry3d& world_T_camera, const Eigen::Vector3d& p_w) {
    Eigen::Vector2d px;
    const double z = project(world_T_camera, p_w, &px);
    if (z <= 0.0 || px.x() < 0 || px.y() < 0 || px.x() > camera_.width_px - 1 || px.y() > camera_.height_px - 1)
      return false;
    return renderer_->depthAt(camera_, world_T_camera, px) < 0.98 * z;
  }

  static double bilinear(const cv::Mat& image, double x, double y) {
    cv::Mat patch;
    cv::getRectSubPix(image, cv::Size(1, 1), cv::Point2f(static_cast<float>(x), static_cast<float>(y)), patch, CV_32F);
    const cv::Scalar mean = cv::mean(patch);
    return patch.channels() == 1 ? mean[0] : (mean[0] + mean[1] + mean[2]) / 3.0;
  }

  /// Texture coordinates to atlas pixel (pixel-centre convention of TexturedMesh).
  using UvMap = std::function<Eigen::Vector2d(const Eigen::Vector2d& uv, int triangle)>;

  /// Median |atlas - truth| (grey levels) at the centroids of the textured triangles that the ground-truth camera
  /// sees away from silhouettes; the atlas is read at the centroid's texture coordinates through uv_map.
  static double medianError(const TexturedMesh& textured, const std::vector<int>& labels, const UvMap& uv_map,
                            int* samples = nullptr) {
    std::vector<double> errors;
    for (size_t t = 0; t < textured.triangles.size(); ++t) {
      if (labels[t] < 0) continue;
      const Eigen::Vector3i& tri = textured.triangles[t];
      const Eigen::Vector3d p = (textured.vertices[tri[0]] + textured.vertices[tri[1]] + textured.vertices[tri[2]]) / 3;
      Eigen::Vector2d px;
      const double z = project(*truth_pose_, p, &px);
      double depth = 0.0;
      if (z <= 0.0 || !truth_->smoothDepthAt(px, 2, 0.01, &depth) || std::abs(depth - z) > 0.002) continue;
      const Eigen::Vector2d uv =
          (textured.tex_coords[tri[0]] + textured.tex_coords[tri[1]] + textured.tex_coords[tri[2]]) / 3;
      const Eigen::Vector2d a = uv_map(uv, static_cast<int>(t));
      errors.push_back(std::abs(bilinear(textured.texture, a.x(), a.y()) - bilinear(truth_->image, px.x(), px.y())));
    }
    if (samples) *samples = static_cast<int>(errors.size());
    if (errors.empty()) return 1e9;
    std::nth_element(errors.begin(), errors.begin() + errors.size() / 2, errors.end());
    return errors[errors.size() / 2];
  }
  static UvMap exactMap(const cv::Mat& atlas) {
    return [&atlas](const Eigen::Vector2d& uv, int) {
      return Eigen::Vector2d(uv.x() * atlas.cols - 0.5, uv.y() * atlas.rows - 0.5);
    };
  }

  static sim::VentRenderer* renderer_;
  static sim::PinholeCamera camera_;
  static std::vector<TextureView>* views_;
  static TexturedMesh* surface_;
  static Eigen::Isometry3d* truth_pose_;
  static sim::RenderedView* truth_;
};
sim::VentRenderer* VentTexturing::renderer_ = nullptr;
sim::PinholeCamera VentTexturing::camera_;
std::vector<TextureView>* VentTexturing::views_ = new std::vector<TextureView>();
TexturedMesh* VentTexturing::surface_ = new TexturedMesh();
Eigen::Isometry3d* VentTexturing::truth_pose_ = nullptr;
sim::RenderedView* VentTexturing::truth_ = nullptr;

// Measured 0.26 grey levels (the views and the truth render the same radiance); wrong mappings give 25-50 (measured
// below on purpose).
constexpr double kMedianErrorBound = 3.0;

TEST(SurfaceTexturingConfig, ValidateListsEveryBadField) {
  EXPECT_EQ(SurfaceTexturingConfig().validate(), "");
  SurfaceTexturingConfig bad;
  bad.max_angle_deg = 90.0;
  bad.margin_px = -1.0;
  bad.occlusion_tolerance = 0.0;
  bad.smoothing_lambda = -0.1;
  bad.icm_passes = 101;
  bad.atlas_scale = 1.5;
  bad.max_atlas_side_px = 100;
  const std::string message = bad.validate();
  for (const char* field : {"max_angle_deg", "margin_px", "occlusion_tolerance", "smoothing_lambda", "icm_passes",
                            "atlas_scale", "max_atlas_side_px"})
    EXPECT_NE(message.find(field), std::string::npos) << message;
}

TEST(SurfaceTexturing, RejectsMalformedInputs) {
  TexturedMesh triangle;
  triangle.vertices = {Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(0.1, 0, 1), Eigen::Vector3d(0, 0.1, 1)};
  triangle.triangles = {Eigen::Vector3i(0, 2, 1)};
  TextureView view;
  view.image = cv::Mat(100, 100, CV_8UC3, cv::Scalar(10, 20, 30));
  view.K << 100, 0, 49.5, 0, 100, 49.5, 0, 0, 1;
  EXPECT_NO_THROW(mesh::textureSurface(triangle, {view}, SurfaceTexturingConfig()));
  EXPECT_THROW(mesh::textureSurface(TexturedMesh(), {view}, SurfaceTexturingConfig()), std::invalid_argument);
  EXPECT_THROW(mesh::textureSurface(triangle, {}, SurfaceTexturingConfig()), std::invalid_argument);
  TextureView bad = view;
  bad.image = cv::Mat(100, 100, CV_32FC1);
  EXPECT_THROW(mesh::textureSurface(triangle, {bad}, SurfaceTexturingConfig()), std::invalid_argument);
  bad = view;
  bad.K.setZero();
  EXPECT_THROW(mesh::textureSurface(triangle, {bad}, SurfaceTexturingConfig()), std::invalid_argument);
  SurfaceTexturingConfig config;
  config.atlas_scale = 0.0;
  EXPECT_THROW(mesh::textureSurface(triangle, {view}, config), std::invalid_argument);
}

TEST(SurfaceTexturing, OneTriangleTakesItsColourFromTheViewThatFacesIt) {
  // A triangle whose normal points at the camera (towards -z).
  TexturedMesh triangle;
  triangle.vertices = {Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(0.1, 0, 1), Eigen::Vector3d(0, 0.1, 1)};
  triangle.triangles = {Eigen::Vector3i(0, 2, 1)};
  TextureView view;
  view.image = cv::Mat(100, 100, CV_8UC3, cv::Scalar(10, 20, 30));  // BGR
  view.K << 100, 0, 49.5, 0, 100, 49.5, 0, 0, 1;
  SurfaceTexturingStats stats;
  std::vector<int> labels;
  const TexturedMesh textured = mesh::textureSurface(triangle, {view}, SurfaceTexturingConfig(), &stats, &labels);
  const Eigen::Vector3d n =
      (triangle.vertices[2] - triangle.vertices[0]).cross(triangle.vertices[1] - triangle.vertices[0]);
  ASSERT_LT(n.z(), 0.0) << "the test triangle must face the camera (-z)";
  EXPECT_EQ(textured.validate(), "");
  ASSERT_EQ(labels, std::vector<int>{0});
  EXPECT_EQ(stats.textured_triangles, 1);
  EXPECT_EQ(textured.vertices.size(), 3u);
  EXPECT_EQ(textured.colors[0], cv::Vec3b(30, 20, 10));  // RGB
  // Seen from behind: untextured, flat grey.
  TexturedMesh flipped = triangle;
  flipped.triangles = {Eigen::Vector3i(0, 1, 2)};
  const TexturedMesh grey = mesh::textureSurface(flipped, {view}, SurfaceTexturingConfig(), &stats, &labels);
  EXPECT_EQ(labels, std::vector<int>{-1});
  EXPECT_EQ(stats.untextured_triangles, 1);
  EXPECT_EQ(stats.views_used, 0);
  const Eigen::Vector2d uv = grey.tex_coords[0];
  const cv::Vec3b texel = grey.texture.channels() == 3
                              ? grey.texture.at<cv::Vec3b>(static_cast<int>(uv.y() * grey.texture.rows),
                                                           static_cast<int>(uv.x() * grey.texture.cols))
                              : cv::Vec3b::all(grey.texture.at<uchar>(static_cast<int>(uv.y() * grey.texture.rows),
                                                                      static_cast<int>(uv.x() * grey.texture.cols)));
  EXPECT_EQ(texel[0], 128);
}

TEST_F(VentTexturing, AtlasColourMatchesTheTrueColourOfTheVent) {
  ASSERT_GT(surface_->triangles.size(), 20000u);
  const auto start = std::chrono::steady_clock::now();
  SurfaceTexturingStats stats;
  std::vector<int> labels;
  const TexturedMesh textured = mesh::textureSurface(*surface_, *views_, SurfaceTexturingConfig(), &stats, &labels);
  const double seconds = secondsSince(start);
  ASSERT_EQ(textured.validate(), "");
  ASSERT_TRUE(textured.hasTexture());
  ASSERT_EQ(textured.triangles.size(), surface_->triangles.size());
  ASSERT_EQ(textured.vertices.size(), 3 * surface_->triangles.size());
  ASSERT_EQ(labels.size(), surface_->triangles.size());
  // Same triangles, same winding.
  for (size_t t = 0; t < surface_->triangles.size(); t += 97)
    for (int k = 0; k < 3; ++k)
      ASSERT_EQ(textured.vertices[textured.triangles[t][k]], surface_->vertices[surface_->triangles[t][k]]);

  const double textured_fraction = static_cast<double>(stats.textured_triangles) / surface_->triangles.size();
  int samples = 0;
  const double error = medianError(textured, labels, exactMap(textured.texture), &samples);
  std::cout << surface_->triangles.size() << " triangles, " << 100.0 * textured_fraction << " % textured from "
            << stats.views_used << " views, atlas " << stats.atlas_width_px << "x" << stats.atlas_height_px << ", "
            << stats.seam_edges << " seam edges (" << stats.icm_changes << " ICM changes), " << seconds
            << " s; median |atlas - truth| " << error << " grey levels over " << samples << " points\n";
  EXPECT_GT(textured_fraction, 0.9);
  EXPECT_EQ(stats.views_used, 6);
  EXPECT_GT(samples, 5000);
  EXPECT_LT(error, kMedianErrorBound);

  // The bound tells a right mapping from wrong ones: v flipped, the neighbouring tile, one pixel row per 8 off.
  const cv::Mat& atlas = textured.texture;
  const double tile_w = 640.0, tile_h = 480.0;
  const double flipped = medianError(textured, labels, [&](const Eigen::Vector2d& uv, int) {
    const double y = uv.y() * atlas.rows - 0.5, row = std::floor(y / tile_h) * tile_h;
    return Eigen::Vector2d(uv.x() * atlas.cols - 0.5, row + (tile_h - 1.0) - (y - row));
  });
  const double next_tile = medianError(textured, labels, [&](const Eigen::Vector2d& uv, int) {
    const double x = uv.x() * atlas.cols - 0.5;
    return Eigen::Vector2d(x < 2 * tile_w ? x + tile_w : x - 2 * tile_w, uv.y() * atlas.rows - 0.5);
  });
  const double shifted = medianError(textured, labels, [&](const Eigen::Vector2d& uv, int) {
    return Eigen::Vector2d(uv.x() * atlas.cols - 0.5, uv.y() * atlas.rows - 0.5 + 8.0);
  });
  std::cout << "wrong mappings: v flipped " << flipped << ", next tile " << next_tile << ", 8 rows off " << shifted
            << " grey levels\n";
  EXPECT_GT(flipped, 3.0 * kMedianErrorBound);
  EXPECT_GT(next_tile, 3.0 * kMedianErrorBound);
  EXPECT_GT(shifted, 3.0 * kMedianErrorBound);
}

TEST_F(VentTexturing, TrianglesHiddenByTheChimneyAreNotTexturedFromThatView) {
  // Triangles textured from a view in which the true scene hides them (the seabed behind the chimney, mostly).
  const auto hidden_in_own_view = [](const TexturedMesh& textured, const std::vector<int>& labels) {
    int hidden = 0;
    for (size_t t = 0; t < labels.size(); ++t) {
      if (labels[t] < 0) continue;
      const Eigen::Vector3i& tri = textured.triangles[t];
      const Eigen::Vector3d p = (textured.vertices[tri[0]] + textured.vertices[tri[1]] + textured.vertices[tri[2]]) / 3;
      hidden += hiddenIn((*views_)[labels[t]].world_T_camera, p) ? 1 : 0;
    }
    return hidden;
  };
  SurfaceTexturingConfig unchecked;
  unchecked.check_occlusion = false;
  std::vector<int> labels;
  const TexturedMesh careless = mesh::textureSurface(*surface_, *views_, unchecked, nullptr, &labels);
  const int careless_hidden = hidden_in_own_view(careless, labels);
  SurfaceTexturingStats stats;
  const TexturedMesh textured = mesh::textureSurface(*surface_, *views_, SurfaceTexturingConfig(), &stats, &labels);
  const int hidden = hidden_in_own_view(textured, labels);
  std::cout << "triangles textured from a view that does not see them: " << careless_hidden << " without the z-buffer, "
            << hidden << " with it\n";
  EXPECT_GT(careless_hidden, 25) << "the scene must test the occlusion";
  EXPECT_LE(hidden, 10);  // a few at the chimney's silhouette, where the mesh and the true cone differ

  // And the seabed right behind the chimney in view 0 is still textured, from the other side.
  int behind = 0, textured_behind = 0;
  for (size_t t = 0; t < labels.size(); ++t) {
    const Eigen::Vector3i& tri = textured.triangles[t];
    const Eigen::Vector3d p = (textured.vertices[tri[0]] + textured.vertices[tri[1]] + textured.vertices[tri[2]]) / 3;
    if (p.z() > 0.003 || !hiddenIn((*views_)[0].world_T_camera, p)) continue;
    ++behind;
    if (labels[t] >= 0) {
      ++textured_behind;
      EXPECT_NE(labels[t], 0);
    }
  }
  EXPECT_GT(behind, 500);
  EXPECT_GT(textured_behind, 0.8 * behind);
}

TEST_F(VentTexturing, GainsEvenOutADarkerView) {
  std::vector<TextureView> views = *views_;
  views[2].image = views[2].image * 0.7;  // lighting differs: this view is darker
  // Error over the triangles textured from view 2.
  const auto view2Error = [](const TexturedMesh& textured, std::vector<int> labels) {
    for (int& l : labels) l = l == 2 ? 2 : -1;
    int samples = 0;
    const double error = medianError(textured, labels, exactMap(textured.texture), &samples);
    EXPECT_GT(samples, 1000);
    return error;
  };
  SurfaceTexturingConfig plain;
  plain.adjust_gains = false;
  std::vector<int> labels;
  SurfaceTexturingStats stats;
  const TexturedMesh uneven = mesh::textureSurface(*surface_, views, plain, &stats, &labels);
  const double uneven_error = view2Error(uneven, labels);
  const TexturedMesh even = mesh::textureSurface(*surface_, views, SurfaceTexturingConfig(), &stats, &labels);
  const double even_error = view2Error(even, labels);
  double others = 0.0;
  for (int v : {0, 1, 3, 4, 5}) others += stats.gains[v] / 5.0;
  std::cout << "view 2 darkened x0.7: gain ratio " << stats.gains[2] / others << " (ideal " << 1 / 0.7
            << "), median error on its triangles " << uneven_error << " -> " << even_error << " grey levels\n";
  EXPECT_NEAR(stats.gains[2] / others, 1.0 / 0.7, 0.07);
  EXPECT_NEAR(others, 1.0, 0.02);
  EXPECT_GT(uneven_error, 3.0 * kMedianErrorBound);
  EXPECT_LT(even_error, kMedianErrorBound);
}

TEST_F(VentTexturing, ObjExportReferencesTheAtlasWithCoordinatesInTheUnitSquare) {
  // A part of the surface (ASCII export of the whole takes long).
  TexturedMesh part = *surface_;
  part.triangles.resize(std::min<size_t>(part.triangles.size(), 20000));
  SurfaceTexturingConfig config;
  config.atlas_scale = 0.5;
  SurfaceTexturingStats stats;
  const TexturedMesh textured = mesh::textureSurface(part, *views_, config, &stats);
  EXPECT_NEAR(stats.atlas_scale, 0.5, 1e-12);
  const TempDir dir;
  const std::string obj = dir.file("surface.obj");
  const std::string png = exocet_stereo::io::writeObj(obj, textured);
  ASSERT_EQ(fs::path(png).filename(), "surface.png");
  const cv::Mat atlas = cv::imread(png, cv::IMREAD_UNCHANGED);
  ASSERT_FALSE(atlas.empty());
  EXPECT_EQ(atlas.cols, stats.atlas_width_px);
  EXPECT_EQ(atlas.rows, stats.atlas_height_px);
  EXPECT_LE(std::max(atlas.cols, atlas.rows), 2 * 640);

  std::ifstream mtl(dir.file("surface.mtl"));
  std::string text((std::istreambuf_iterator<char>(mtl)), std::istreambuf_iterator<char>());
  EXPECT_NE(text.find("map_Kd surface.png"), std::string::npos) << text;
  std::ifstream in(obj);
  std::string line;
  size_t vt = 0, faces = 0, v = 0;
  bool mtllib = false, in_unit_square = true;
  while (std::getline(in, line)) {
    std::istringstream s(line);
    std::string tag;
    s >> tag;
    if (tag == "mtllib") mtllib = line.find("surface.mtl") != std::string::npos;
    if (tag == "v") ++v;
    if (tag == "vt") {
      double a, b;
      s >> a >> b;
      in_unit_square = in_unit_square && a >= 0 && a <= 1 && b >= 0 && b <= 1;
      ++vt;
    }
    if (tag == "f") ++faces;
  }
  EXPECT_TRUE(mtllib);
  EXPECT_TRUE(in_unit_square);
  EXPECT_EQ(v, textured.vertices.size());
  EXPECT_EQ(vt, textured.vertices.size());
  EXPECT_EQ(faces, part.triangles.size());
}

TEST_F(VentTexturing, ReconstructPairsTexturesItsSurfaceAndWritesTheAtlas) {
  // Three parallel stereo pairs (0.1 m baseline, 320x240) around the vent; SGM, fusion, surface, texture.
  sim::PinholeCamera camera;
  camera.k = sim::intrinsics(400.0, 400.0, 159.5, 119.5);
  camera.width_px = 320;
  camera.height_px = 240;
  std::vector<mesh::CalibratedPair> pairs;
  for (int i = 0; i < 3; ++i) {
    const double a = 2.0 * M_PI * i / 3 + 0.3;
    mesh::CalibratedPair pair;
    pair.world_T_left =
        sim::lookAt(Eigen::Vector3d(0.6 * std::cos(a), 0.6 * std::sin(a), 0.4), Eigen::Vector3d(0, 0, 0.15));
    pair.world_T_right = pair.world_T_left * Eigen::Translation3d(0.1, 0.0, 0.0);
    pair.left = renderer_->render(camera, pair.world_T_left).image;
    pair.right = renderer_->render(camera, pair.world_T_right).image;
    pair.K_left = pair.K_right = camera.k;
    pairs.push_back(pair);
  }
  mesh::AcquisitionReconstructionConfig config;
  ASSERT_TRUE(config.texture) << "texturing is on by default";
  config.fusion.voxel_m = 0.005;  // a coarse surface: the files are written in ASCII
  const auto start = std::chrono::steady_clock::now();
  const mesh::AcquisitionReconstruction result = mesh::reconstructPairs(pairs, config);
  std::cout << "reconstructPairs: " << result.surface.triangles.size() << " triangles, "
            << result.texturing.textured_triangles << " textured, atlas " << result.texturing.atlas_width_px << "x"
            << result.texturing.atlas_height_px << ", " << secondsSince(start) << " s\n";
  for (const std::string& w : result.warnings) std::cout << "warning: " << w << "\n";
  ASSERT_FALSE(result.surface.empty());
  ASSERT_TRUE(result.surface.hasTexture());
  EXPECT_EQ(result.surface.validate(), "");
  EXPECT_GT(result.texturing.textured_triangles, 0.8 * result.surface.triangles.size());
  EXPECT_EQ(result.texturing.views_used, 3);
  // The colour through the whole pipeline (SGM geometry, 320x240 images) against the 640x480 ground truth.
  const std::vector<int> all(result.surface.triangles.size(), 0);
  int samples = 0;
  const double error = medianError(result.surface, all, exactMap(result.surface.texture), &samples);
  std::cout << "reconstructPairs: median |atlas - truth| " << error << " grey levels over " << samples << " points\n";
  EXPECT_GT(samples, 5000);
  EXPECT_LT(error, 4.0 * kMedianErrorBound);  // measured 5.6: lower resolution, SGM geometry

  const TempDir dir;
  const std::vector<std::string> files = mesh::writeReconstruction(result, dir.path());
  EXPECT_NE(std::find(files.begin(), files.end(), dir.file("surface.png")), files.end());
  EXPECT_FALSE(cv::imread(dir.file("surface.png")).empty());
  std::ifstream ply(dir.file("surface.ply"));
  std::string text((std::istreambuf_iterator<char>(ply)), std::istreambuf_iterator<char>());
  EXPECT_NE(text.find("comment TextureFile surface.png"), std::string::npos);
  std::ifstream wrl(dir.file("surface.wrl"));
  std::string vrml((std::istreambuf_iterator<char>(wrl)), std::istreambuf_iterator<char>());
  EXPECT_NE(vrml.find("ImageTexture { url \"surface.png\" }"), std::string::npos);

  config.texture = false;
  const mesh::AcquisitionReconstruction bare = mesh::reconstructPairs(pairs, config);
  EXPECT_FALSE(bare.surface.hasTexture());
}

}  // namespace
