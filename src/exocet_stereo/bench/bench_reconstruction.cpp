// Benchmark of the sparse geometry (2D4 report sections 3.1.1 and 3.2): the chessboard rig calibration against
// OpenCV's stored result, and the temple ring (16 real views) reconstructed from poses perturbed by 5 % of the
// camera-to-object distance and 3 degrees, beside COLMAP (SIFT on CPU, exhaustive matching, incremental mapper with
// the exact intrinsics held) on the same 16 images. Prints a side-by-side table and writes reconstruction.json.
// Then the "vent" section (issue 7): dense reconstruction of exocet_servo's simulated vent from a ring of stereo pairs,
// fused, surfaced and scored against the known geometry; "--only vent" runs it alone and keeps the file's other
// figures of an earlier run.
//   bench_reconstruction --output-dir out/bench --shared-data /abs/path/shared/data [--only all|vent]
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "exocet_common/json_file.h"
#include "exocet_common/command_line.h"
#include "exocet_common/testing/paths.h"
#include "exocet_servo/sim/point_scene.h"
#include "exocet_servo/sim/vent_renderer.h"
#include "exocet_stereo/dense/dense_stereo.h"
#include "exocet_stereo/geometry/epipolar.h"
#include "exocet_stereo/geometry/pose_perturbation.h"
#include "exocet_stereo/geometry/rig_calibration.h"
#include "exocet_stereo/geometry/sparse_reconstruction.h"
#include "exocet_stereo/geometry/stereo_rectification.h"
#include "exocet_stereo/io/mesh_export.h"
#include "exocet_stereo/mesh/cloud_fusion.h"
#include "exocet_stereo/mesh/cloud_surface.h"
#include "exocet_stereo/mesh/depth_map.h"
#include "exocet_stereo/mesh/pair_depth.h"

namespace {

namespace fs = std::filesystem;
using namespace exocet_stereo::geometry;
using Clock = std::chrono::steady_clock;

// Centre of the tight bounding box given in the temple data set's README.txt.
const Eigen::Vector3d kTempleCentre(0.5 * (-0.073568 + 0.028855), 0.5 * (0.021728 + 0.181892),
                                    0.5 * (-0.012445 + 0.062736));

double secondsSince(Clock::time_point start) { return std::chrono::duration<double>(Clock::now() - start).count(); }

/// What COLMAP produced.
struct ColmapOutcome {
  bool ok = false;
  std::string status;
  double seconds = 0.0;
  int views_registered = 0;
  int points = 0;
  double reproj_rms_px = NAN;
  double centre_err_max_pct = NAN;
  double centre_err_rms_pct = NAN;
};

bool run(const std::string& command, const fs::path& log) {
  return std::system((command + " > " + log.string() + " 2>&1").c_str()) == 0;
}

/// Reads a COLMAP text model (cameras.txt, images.txt, points3D.txt) into views and point observations, and scores
/// it: reprojection RMS over every observation, centre errors against the truth after a similarity.
void scoreColmapModel(const fs::path& txt, const std::vector<PinholeView>& truth, ColmapOutcome& out) {
  std::map<int, Eigen::Matrix3d> cameras;
  {
    std::ifstream in(txt / "cameras.txt");
    std::string line;
    while (std::getline(in, line)) {
      if (line.empty() || line[0] == '#') continue;
      std::istringstream s(line);
      int id, w, h;
      std::string model;
      double fx, fy, cx, cy;
      s >> id >> model >> w >> h >> fx >> fy >> cx >> cy;
      Eigen::Matrix3d K;
      K << fx, 0, cx, 0, fy, cy, 0, 0, 1;
      cameras[id] = K;
    }
  }
  std::map<long, Eigen::Vector3d> points;
  {
    std::ifstream in(txt / "points3D.txt");
    std::string line;
    while (std::getline(in, line)) {
      if (line.empty() || line[0] == '#') continue;
      std::istringstream s(line);
      long id;
      Eigen::Vector3d X;
      s >> id >> X.x() >> X.y() >> X.z();
      points[id] = X;
    }
  }
  std::vector<PinholeView> estimated, matched_truth;
  double sum2 = 0.0;
  long n_obs = 0;
  std::ifstream in(txt / "images.txt");
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream s(line);
    int id, camera_id;
    double qw, qx, qy, qz;
    PinholeView view;
    s >> id >> qw >> qx >> qy >> qz >> view.t.x() >> view.t.y() >> view.t.z() >> camera_id >> view.name;
    view.R = Eigen::Quaterniond(qw, qx, qy, qz).normalized().toRotationMatrix();
    view.K = cameras[camera_id];
    std::string observations;
    std::getline(in, observations);
    std::istringstream o(observations);
    double x, y;
    long point_id;
    while (o >> x >> y >> point_id) {
      if (point_id < 0 || !points.count(point_id)) continue;
      sum2 += (view.project(points[point_id]) - Eigen::Vector2d(x, y)).squaredNorm();
      ++n_obs;
    }
    for (const auto& t : truth)
      if (t.name == view.name) {
        estimated.push_back(view);
        matched_truth.push_back(t);
      }
  }
  out.views_registered = static_cast<int>(estimated.size());
  out.points = static_cast<int>(points.size());
  if (n_obs > 0) out.reproj_rms_px = std::sqrt(sum2 / n_obs);
  if (estimated.size() >= 3) {
    const CentreErrors e = centreErrorsAfterSimilarity(estimated, matched_truth, kTempleCentre);
    out.centre_err_max_pct = e.max_pct;
    out.centre_err_rms_pct = e.rms_pct;
  }
}

ColmapOutcome runColmap(const fs::path& temple_dir, const std::vector<PinholeView>& truth) {
  ColmapOutcome out;
  if (std::system("command -v colmap > /dev/null 2>&1") != 0) {
    out.status = "colmap not installed (apt-get install colmap)";
    return out;
  }
  setenv("QT_QPA_PLATFORM", "offscreen", 1);
  const fs::path work = fs::temp_directory_path() / ("exocet_bench_colmap_" + std::to_string(getpid()));
  fs::remove_all(work);
  fs::create_directories(work / "images");
  fs::create_directories(work / "sparse");
  fs::create_directories(work / "txt");
  // Links, not copies: COLMAP reads the 16 images and nothing else of the data folder.
  for (const auto& v : truth) fs::create_symlink(temple_dir / v.name, work / "images" / v.name);
  const Eigen::Matrix3d& K = truth[0].K;
  std::ostringstream params;
  params << std::setprecision(10) << K(0, 0) << "," << K(1, 1) << "," << K(0, 2) << "," << K(1, 2);
  const std::string db = (work / "database.db").string(), images = (work / "images").string();
  const auto start = Clock::now();
  bool ok = run("colmap feature_extractor --database_path " + db + " --image_path " + images +
                    " --ImageReader.camera_model PINHOLE --ImageReader.single_camera 1 --ImageReader.camera_params " +
                    params.str() + " --SiftExtraction.use_gpu 0",
                work / "feature_extractor.log");
  ok = ok && run("colmap exhaustive_matcher --database_path " + db + " --SiftMatching.use_gpu 0",
                 work / "exhaustive_matcher.log");
  ok = ok && run("colmap mapper --database_path " + db + " --image_path " + images + " --output_path " +
                     (work / "sparse").string() +
                     " --Mapper.ba_refine_focal_length 0 --Mapper.ba_refine_principal_point 0"
                     " --Mapper.ba_refine_extra_params 0",
                 work / "mapper.log");
  out.seconds = secondsSince(start);
  if (!ok) {
    out.status = "a colmap step failed (logs in " + work.string() + ")";
    return out;
  }
  // The mapper may split the views into several models: score the largest.
  ColmapOutcome best;
  int models = 0;
  for (const auto& entry : fs::directory_iterator(work / "sparse")) {
    if (!entry.is_directory()) continue;
    ++models;
    const fs::path txt = work / "txt" / entry.path().filename();
    fs::create_directories(txt);
    if (!run("colmap model_converter --input_path " + entry.path().string() + " --output_path " + txt.string() +
                 " --output_type TXT",
             work / "model_converter.log"))
      continue;
    ColmapOutcome candidate;
    scoreColmapModel(txt, truth, candidate);
    if (candidate.views_registered > best.views_registered) best = candidate;
  }
  if (best.views_registered == 0) {
    out.status = "colmap mapper produced no model";
    return out;
  }
  best.seconds = out.seconds;
  best.ok = true;
  best.status = "ok (" + std::to_string(models) + " model(s); the largest is scored)";
  fs::remove_all(work);
  return best;
}

// ================= Vent: dense reconstruction of exocet_servo's simulated vent (issue 7) =================
// A ring of stereo pairs around the ray-cast vent (known geometry), each rectified by our rectification, matched by our
// dense stereo, turned into a depth map of the rectified left camera; all depth maps fused (multi-view consistency,
// voxel merge), the fused cloud cropped to a box around the vent (the seabed far away is excluded) and surfaced. The
// figure is the RMS of the true surface distance over the chimney (points above the seabed) divided by the vent's
// height (the object's size).

struct VentSettings {
  int pairs = 10;
  double ring_radius_m = 0.6;    ///< horizontal distance of the left cameras from the vent's axis
  double camera_height_m = 0.4;  ///< above the seabed; the cameras look at mid-height of the vent
  double baseline_m = 0.15;      ///< converged rig: both cameras look at the same point
  std::string method = "sgm";
  double seabed_margin_m = 0.005;  ///< points below this height belong to the seabed, not the chimney
};

/// RMS (m) of the true surface distance over the points whose height is at least min_z_m, and their count.
std::pair<double, long> rmsDistance(const exocet_servo::sim::VentSceneConfig& scene,
                                    const std::vector<Eigen::Vector3d>& points, double min_z_m) {
  double sum2 = 0.0;
  long n = 0;
  for (const auto& p : points) {
    if (p.z() < min_z_m) continue;
    sum2 += std::pow(exocet_servo::sim::distanceToScene(scene, p), 2);
    ++n;
  }
  return {n > 0 ? std::sqrt(sum2 / n) : NAN, n};
}

/// Completeness: the fraction of points sampled every ~spacing_m on the chimney's side and top that have a surface
/// vertex within reach_m.
double completeness(const exocet_servo::sim::VentSceneConfig& scene, const std::vector<Eigen::Vector3d>& vertices,
                    double spacing_m, double reach_m) {
  auto cellKey = [reach_m](const Eigen::Vector3d& p) {
    const Eigen::Vector3d c = (p / reach_m).array().floor();
    return (static_cast<int64_t>(c.x()) + 100000) * 40000000000LL + (static_cast<int64_t>(c.y()) + 100000) * 200000LL +
           (static_cast<int64_t>(c.z()) + 100000);
  };
  std::map<int64_t, std::vector<int>> cells;
  for (size_t i = 0; i < vertices.size(); ++i) cells[cellKey(vertices[i])].push_back(static_cast<int>(i));
  auto covered = [&](const Eigen::Vector3d& p) {
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const auto it = cells.find(cellKey(p + reach_m * Eigen::Vector3d(dx, dy, dz)));
          if (it == cells.end()) continue;
          for (int i : it->second)
            if ((vertices[i] - p).norm() <= reach_m) return true;
        }
    return false;
  };
  long samples = 0, hits = 0;
  const int rings = static_cast<int>(std::ceil(scene.height_m / spacing_m));
  for (int k = 0; k <= rings; ++k) {  // side
    const double h = scene.height_m * k / rings;
    const double r = scene.base_radius_m + (scene.top_radius_m - scene.base_radius_m) * h / scene.height_m;
    const int n = static_cast<int>(std::ceil(2 * M_PI * r / spacing_m));
    for (int j = 0; j < n; ++j) {
      const double a = 2 * M_PI * j / n;
      ++samples;
      hits += covered(scene.base_m + Eigen::Vector3d(r * std::cos(a), r * std::sin(a), h)) ? 1 : 0;
    }
  }
  for (double x = -scene.top_radius_m; x <= scene.top_radius_m; x += spacing_m)  // top
    for (double y = -scene.top_radius_m; y <= scene.top_radius_m; y += spacing_m) {
      if (std::hypot(x, y) > scene.top_radius_m) continue;
      ++samples;
      hits += covered(scene.base_m + Eigen::Vector3d(x, y, scene.height_m)) ? 1 : 0;
    }
  return samples > 0 ? static_cast<double>(hits) / samples : NAN;
}

void benchVent(nlohmann::ordered_json& json, const std::string& output_dir,
               const VentSettings& settings = VentSettings()) {
  namespace sim = exocet_servo::sim;
  namespace mesh = exocet_stereo::mesh;
  const sim::VentSceneConfig scene;  // 0.3 m high, radius 0.1 m at the base, 0.05 m at the top
  const sim::VentRenderer renderer(scene);
  const double object_size_m = scene.height_m;
  const Eigen::Vector3d target = scene.base_m + Eigen::Vector3d(0, 0, 0.5 * scene.height_m);
  // The crop box: 1.5 base radii around the axis, from just below the seabed to just above the top.
  const double half_width_m = 1.5 * scene.base_radius_m;
  const Eigen::Vector3d box_min = scene.base_m + Eigen::Vector3d(-half_width_m, -half_width_m, -0.01);
  const Eigen::Vector3d box_max = scene.base_m + Eigen::Vector3d(half_width_m, half_width_m, scene.height_m + 0.01);

  // Two cameras with different (known) intrinsics and no distortion.
  sim::PinholeCamera left_camera, right_camera;
  left_camera.k = sim::intrinsics(800.0, 800.0, 319.5, 239.5);
  right_camera.k = sim::intrinsics(790.0, 792.0, 324.0, 236.0);

  auto pairPoses = [&](int i) {
    const double a = 2.0 * M_PI * i / settings.pairs;
    const Eigen::Vector3d left_centre =
        scene.base_m + Eigen::Vector3d(settings.ring_radius_m * std::cos(a), settings.ring_radius_m * std::sin(a),
                                       settings.camera_height_m);
    const Eigen::Isometry3d world_T_left = sim::lookAt(left_centre, target);
    // A fixed rig: the right camera beside the left one, turned inwards (about its y axis) to look at the same point.
    const double toe_in_rad = std::atan(settings.baseline_m / (target - left_centre).norm());
    Eigen::Isometry3d left_T_right = Eigen::Isometry3d::Identity();
    left_T_right.linear() = Eigen::AngleAxisd(-toe_in_rad, Eigen::Vector3d::UnitY()).toRotationMatrix();
    left_T_right.translation() = Eigen::Vector3d(settings.baseline_m, 0.0, 0.0);
    return std::make_pair(world_T_left, world_T_left * left_T_right);
  };
  double render_s = 0.0, stereo_s = 0.0;
  std::vector<mesh::DepthView> views;
  long depth_pixels = 0;
  int max_disparity_px = 0, offset_px = 0;
  for (int i = 0; i < settings.pairs; ++i) {
    const auto poses = pairPoses(i);
    auto start = Clock::now();
    mesh::CalibratedPair pair;
    pair.left = renderer.render(left_camera, poses.first).image;
    pair.right = renderer.render(right_camera, poses.second).image;
    pair.K_left = left_camera.k;
    pair.K_right = right_camera.k;
    pair.world_T_left = poses.first;
    pair.world_T_right = poses.second;
    render_s += secondsSince(start);

    start = Clock::now();
    // Search only the depths of the crop box (its corners in the left camera, 2 % margin).
    mesh::PairDepthConfig depth_config;
    depth_config.method = settings.method;
    double z_min = INFINITY, z_max = 0.0;
    const Eigen::Isometry3d left_T_world = poses.first.inverse();
    for (int corner = 0; corner < 8; ++corner) {
      const Eigen::Vector3d p((corner & 1) ? box_max.x() : box_min.x(), (corner & 2) ? box_max.y() : box_min.y(),
                              (corner & 4) ? box_max.z() : box_min.z());
      const double z = (left_T_world * p).z();
      z_min = std::min(z_min, z);
      z_max = std::max(z_max, z);
    }
    depth_config.min_depth_m = 0.98 * z_min;
    depth_config.max_depth_m = 1.02 * z_max;
    mesh::PairDepthStats pair_stats;
    views.push_back(mesh::depthFromPair(pair, depth_config, &pair_stats));
    depth_pixels += pair_stats.depth_pixels;
    max_disparity_px = std::max(max_disparity_px, pair_stats.disparities_px);
    offset_px = pair_stats.offset_px;
    stereo_s += secondsSince(start);
  }

  auto start = Clock::now();
  mesh::CloudFusionConfig fusion;
  fusion.voxel_m = 0.0015;
  fusion.depth_tolerance = 0.005;
  fusion.min_confirmations = 2;
  fusion.max_incidence_deg = 75.0;
  mesh::CloudFusionStats fusion_stats;
  const mesh::FusedCloud all = mesh::fuseDepthMaps(views, fusion, &fusion_stats);
  const mesh::FusedCloud cloud = all.cropped(box_min, box_max);
  const double fusion_s = secondsSince(start);

  start = Clock::now();
  mesh::CloudSurfaceConfig surface_config;
  surface_config.cell_m = 0.002;
  surface_config.radius_m = 0.006;
  mesh::CloudSurfaceStats surface_stats;
  const mesh::TexturedMesh surface = mesh::surfaceFromCloud(cloud, surface_config, &surface_stats);
  const double surface_s = secondsSince(start);
  const double total_s = stereo_s + fusion_s + surface_s;

  const double chimney_z = scene.base_m.z() + settings.seabed_margin_m, anywhere = -INFINITY;
  const auto cloud_rms = rmsDistance(scene, cloud.points, chimney_z);
  const auto surface_rms = rmsDistance(scene, surface.vertices, chimney_z);
  const auto cloud_box_rms = rmsDistance(scene, cloud.points, anywhere);
  const auto surface_box_rms = rmsDistance(scene, surface.vertices, anywhere);
  const double pct = 100.0 / object_size_m;
  const double complete = completeness(scene, surface.vertices, 0.002, 0.003);

  if (!surface.empty()) exocet_stereo::io::writePly((fs::path(output_dir) / "vent_surface.ply").string(), surface);
  json["vent_pairs"] = settings.pairs;
  json["vent_points"] = cloud_rms.second;
  json["vent_rms_pct"] = surface_rms.first * pct;
  json["vent_cloud_rms_pct"] = cloud_rms.first * pct;
  json["vent_seconds"] = total_s;
  json["vent_completeness_pct"] = complete * 100.0;
  json["vent_surface_rms_mm"] = surface_rms.first * 1e3;
  json["vent_cloud_rms_mm"] = cloud_rms.first * 1e3;
  json["vent_box_rms_pct"] = surface_box_rms.first * pct;
  json["vent_cloud_box_rms_pct"] = cloud_box_rms.first * pct;
  json["vent_box_points"] = cloud.size();
  json["vent_surface_vertices"] = surface.vertices.size();
  json["vent_surface_triangles"] = surface.triangles.size();
  json["vent_object_size_m"] = object_size_m;
  json["vent_baseline_m"] = settings.baseline_m;
  json["vent_stereo_seconds"] = stereo_s;
  json["vent_fusion_seconds"] = fusion_s;
  json["vent_surface_seconds"] = surface_s;
  json["vent_render_seconds"] = render_s;
  json["vent_method"] = settings.method;

  std::cout << "\nVent (exocet_servo ray-cast scene, object size = height " << object_size_m
            << " m): " << settings.pairs << " stereo pairs on a ring of radius " << settings.ring_radius_m
            << " m, baseline " << settings.baseline_m * 1e3 << " mm, 640x480, dense '" << settings.method
            << "' over up to " << max_disparity_px << " disparities (the crop box's range, offset " << offset_px
            << " px in the last pair), " << depth_pixels << " depth pixels\n";
  std::cout << "fusion: " << fusion_stats.candidates << " candidates, " << fusion_stats.discontinuity
            << " on discontinuities, " << fusion_stats.oblique << " oblique, " << fusion_stats.unconfirmed
            << " unconfirmed (< " << fusion.min_confirmations << " other views), " << all.size() << " voxels, "
            << cloud.size() << " in the box around the vent\n";
  std::cout << std::left << std::setw(34) << "" << std::setw(12) << "points" << std::setw(12) << "RMS (mm)"
            << "RMS (% of height)\n";
  auto row = [&](const std::string& name, const std::pair<double, long>& r) {
    std::cout << std::left << std::setw(34) << name << std::setw(12) << r.second << std::setw(12)
              << std::setprecision(3) << r.first * 1e3 << r.first * pct << "\n";
  };
  row("fused cloud, chimney", cloud_rms);
  row("surface vertices, chimney", surface_rms);
  row("fused cloud, box with seabed", cloud_box_rms);
  row("surface vertices, box with seabed", surface_box_rms);
  std::cout << "completeness: " << std::setprecision(3) << complete * 100.0
            << " % of the true chimney and top (2 mm samples) have a surface vertex within 3 mm\n";
  std::cout << "time (s): stereo " << stereo_s << ", fusion " << fusion_s << ", surface " << surface_s << ", total "
            << total_s << " (rendering " << render_s << " not counted); goal RMS <= 0.5 % of the height\n";
}

/// The figures of an earlier run's JSON except the vent's, so that "--only vent" rewrites the file without losing them.
nlohmann::ordered_json earlierFigures(const std::string& json_path) {
  nlohmann::ordered_json figures = nlohmann::ordered_json::object();
  const auto earlier = exocet_common::readJsonObjectFile<nlohmann::ordered_json>(json_path);
  if (!earlier) return figures;
  for (const auto& [key, value] : earlier->items())
    if (key.rfind("vent_", 0) != 0 && (value.is_number() || value.is_string() || value.is_null())) figures[key] = value;
  return figures;
}

/// Writes the figures; false (with a message) if the file cannot be written.
bool writeFigures(const std::string& json_path, const nlohmann::ordered_json& json) {
  try {
    exocet_common::writeJsonFileAtomically(json_path, json);
    return true;
  } catch (const std::exception& e) {
    std::cerr << "bench_reconstruction: " << e.what() << "\n";
    return false;
  }
}

}  // namespace

int main(int argc, char** argv) {
  exocet_common::BenchmarkPaths paths;
  paths.shared_data = exocet_common::testing::sharedDataDir();
  std::string only = "all";
  CLI::App app(
      "bench_reconstruction: the stereo rig calibration against OpenCV's stored result, the temple ring\n"
      "reconstructed from perturbed poses beside COLMAP, and the dense reconstruction of the simulated vent.\n"
      "Writes OUTPUT_DIR/reconstruction.json.",
      "bench_reconstruction");
  exocet_common::addBenchmarkPathOptions(app, &paths);
  app.add_option("--only", only,
                 "all sections, or the vent's alone (the file keeps the other figures of an earlier run)")
      ->check(CLI::IsMember({"all", "vent"}))
      ->capture_default_str();
  if (const auto exit_status = exocet_common::parseCommandLine(app, argc, argv)) return *exit_status;
  const std::string& output_dir = paths.output_dir;
  const std::string& shared = paths.shared_data;
  fs::create_directories(output_dir);
  const std::string json_path = (fs::path(output_dir) / "reconstruction.json").string();
  const std::string unwritable = exocet_common::checkWritableDestination(json_path);
  if (!unwritable.empty()) {
    std::cerr << "bench_reconstruction: cannot write " << json_path << ": " << unwritable << "\n";
    return 1;
  }
  // "--only vent" keeps the other sections' figures of an earlier run.
  nlohmann::ordered_json json = only == "vent" ? earlierFigures(json_path) : nlohmann::ordered_json::object();
  try {
    if (only == "vent") {
      benchVent(json, output_dir);
      if (!writeFigures(json_path, json)) return 1;
      std::cout << "written " << json_path << "\n";
      return 0;
    }
    // --- Rig calibration on OpenCV's chessboard pairs. ---
    const fs::path board_dir = fs::path(shared) / "stereo_chessboard";
    std::vector<std::string> left, right;
    for (int i : {1, 2, 3, 4, 5, 6, 7, 8, 9, 11, 12, 13, 14}) {
      char name[16];
      std::snprintf(name, sizeof(name), "%02d.jpg", i);
      left.push_back((board_dir / ("left" + std::string(name))).string());
      right.push_back((board_dir / ("right" + std::string(name))).string());
    }
    auto start = Clock::now();
    const StereoRig rig = calibrateStereoRig(left, right);
    const double calib_s = secondsSince(start);
    const StereoRig stored = readStereoRig((board_dir / "intrinsics.yml").string());
    json["calib_pairs_used"] = rig.pairs_used;
    json["calib_rms_left_px"] = rig.rms_left_px;
    json["calib_rms_right_px"] = rig.rms_right_px;
    json["calib_rms_stereo_px"] = rig.rms_stereo_px;
    json["calib_fx_left_px"] = rig.K_left.at<double>(0, 0);
    json["calib_fx_right_px"] = rig.K_right.at<double>(0, 0);
    json["calib_fx_left_minus_opencv_px"] = rig.K_left.at<double>(0, 0) - stored.K_left.at<double>(0, 0);
    json["calib_fx_right_minus_opencv_px"] = rig.K_right.at<double>(0, 0) - stored.K_right.at<double>(0, 0);
    json["calib_cx_left_minus_opencv_px"] = rig.K_left.at<double>(0, 2) - stored.K_left.at<double>(0, 2);
    json["calib_cy_left_minus_opencv_px"] = rig.K_left.at<double>(1, 2) - stored.K_left.at<double>(1, 2);
    json["calib_baseline_mm"] = rig.baseline_m * 1000.0;
    json["calib_optical_axes_deg"] = rig.optical_axes_angle_deg;
    json["calib_time_s"] = calib_s;

    // --- Temple ring from perturbed poses. ---
    const fs::path temple_dir = fs::path(shared) / "temple_sparse_ring";
    const std::vector<PinholeView> truth = readMiddleburyViews((temple_dir / "templeSR_par.txt").string());
    std::vector<cv::Mat> images;
    for (const auto& v : truth) {
      images.push_back(cv::imread((temple_dir / v.name).string(), cv::IMREAD_GRAYSCALE));
      if (images.back().empty()) throw std::runtime_error("cannot read " + (temple_dir / v.name).string());
    }
    const double angle_rad = 3.0 * M_PI / 180.0, fraction = 0.05;
    const std::vector<PinholeView> initial = perturbPoses(truth, kTempleCentre, fraction, angle_rad, 2026);
    SparseReconstructionConfig config;
    config.matching.contrast_threshold = 0.02;
    config.pose_epipolar_tolerance_px =
        epipolarToleranceForPoseError_px(truth[0].K(0, 0), 2 * angle_rad, 2 * fraction, 2.0);
    start = Clock::now();
    const SparseReconstruction result = reconstructSparse(images, initial, config);
    const double ours_s = secondsSince(start);
    const CentreErrors before = centreErrorsAfterSimilarity(initial, truth, kTempleCentre);
    const CentreErrors after = centreErrorsAfterSimilarity(result.views, truth, kTempleCentre);
    json["temple_views_registered"] = result.views_registered;
    json["temple_points"] = result.points.size();
    json["temple_observations"] = result.observations;
    json["temple_reproj_rms_px"] = result.final_rms_px;
    json["temple_center_err_pct"] = after.max_pct;
    json["temple_center_err_rms_pct"] = after.rms_pct;
    json["temple_initial_center_err_pct"] = before.max_pct;
    json["temple_initial_reproj_rms_px"] = result.initial_rms_px;
    json["temple_time_s"] = ours_s;

    // --- COLMAP on the same images. ---
    const ColmapOutcome colmap = runColmap(temple_dir, truth);
    json["colmap_status"] = colmap.status;
    json["colmap_usable"] = colmap.ok ? 1 : 0;
    json["colmap_time_s"] = colmap.ok ? colmap.seconds : NAN;
    json["colmap_time_ratio"] = colmap.ok ? ours_s / colmap.seconds : NAN;
    json["colmap_views_registered"] = colmap.ok ? colmap.views_registered : NAN;
    json["colmap_points"] = colmap.ok ? colmap.points : NAN;
    json["colmap_reproj_px"] = colmap.reproj_rms_px;
    json["colmap_center_err_pct"] = colmap.centre_err_max_pct;
    json["colmap_center_err_rms_pct"] = colmap.centre_err_rms_pct;

    std::cout << "Stereo rig calibration (" << rig.pairs_used << " chessboard pairs): RMS left " << rig.rms_left_px
              << " px, right " << rig.rms_right_px << " px, stereo " << rig.rms_stereo_px << " px; fx "
              << rig.K_left.at<double>(0, 0) << " / " << rig.K_right.at<double>(0, 0) << " px (OpenCV stored "
              << stored.K_left.at<double>(0, 0) << "); baseline " << rig.baseline_m * 1000.0 << " mm; " << calib_s
              << " s\n\n";
    std::cout << "Temple ring, 16 views (ours: start " << std::setprecision(3) << before.max_pct
              << " % centre error from 5 % / 3 deg perturbation; COLMAP: no pose prior)\n";
    std::cout << std::left << std::setw(30) << "" << std::setw(16) << "ours"
              << "COLMAP\n";
    auto row = [](const std::string& name, const std::string& a, const std::string& b) {
      std::cout << std::left << std::setw(30) << name << std::setw(16) << a << b << "\n";
    };
    auto num = [](double v, int precision = 3) {
      if (!std::isfinite(v)) return std::string("n/a");
      std::ostringstream s;
      s << std::setprecision(precision) << v;
      return s.str();
    };
    row("views registered", std::to_string(result.views_registered),
        colmap.ok ? std::to_string(colmap.views_registered) : "n/a");
    row("points", std::to_string(result.points.size()), colmap.ok ? std::to_string(colmap.points) : "n/a");
    row("reprojection RMS (px)", num(result.final_rms_px), num(colmap.reproj_rms_px));
    row("centre error max (%)", num(after.max_pct), num(colmap.centre_err_max_pct));
    row("centre error RMS (%)", num(after.rms_pct), num(colmap.centre_err_rms_pct));
    row("wall time (s)", num(ours_s), colmap.ok ? num(colmap.seconds) : "n/a");
    std::cout << "COLMAP: " << colmap.status << "\n";

    benchVent(json, output_dir);
  } catch (const std::exception& e) {
    std::cerr << "bench_reconstruction: " << e.what() << "\n";
    writeFigures(json_path, json);  // what was measured before the failure
    return 1;
  }
  if (!writeFigures(json_path, json)) return 1;
  std::cout << "written " << json_path << "\n";
  return 0;
}
