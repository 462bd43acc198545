// Benchmark of the sparse geometry (2D4 report sections 3.1.1 and 3.2): the chessboard rig calibration against
// OpenCV's stored result, and the temple ring (16 real views) reconstructed from poses perturbed by 5 % of the
// camera-to-object distance and 3 degrees, beside COLMAP (SIFT on CPU, exhaustive matching, incremental mapper with
// the exact intrinsics held) on the same 16 images. Prints a side-by-side table and writes reconstruction.json.
//   bench_reconstruction --output-dir out/bench --shared-data /abs/path/shared/data
#include <unistd.h>

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
#include <opencv2/core/persistence.hpp>
#include <opencv2/imgcodecs.hpp>

#include "exocet_stereo/geometry/epipolar.h"
#include "exocet_stereo/geometry/pose_perturbation.h"
#include "exocet_stereo/geometry/rig_calibration.h"
#include "exocet_stereo/geometry/sparse_reconstruction.h"

namespace {

namespace fs = std::filesystem;
using namespace exocet_stereo::geometry;
using Clock = std::chrono::steady_clock;

// Centre of the tight bounding box given in the temple data set's README.txt.
const Eigen::Vector3d kTempleCentre(0.5 * (-0.073568 + 0.028855), 0.5 * (0.021728 + 0.181892),
                                    0.5 * (-0.012445 + 0.062736));

double secondsSince(Clock::time_point start) { return std::chrono::duration<double>(Clock::now() - start).count(); }

/// The benchmark's JSON, written by OpenCV's FileStorage; a figure that could not be measured is the string "n/a".
class JsonReport {
 public:
  explicit JsonReport(const std::string& path)
      : storage_(path, cv::FileStorage::WRITE | cv::FileStorage::FORMAT_JSON) {}
  bool ok() const { return storage_.isOpened(); }
  void number(const std::string& key, double value) {
    if (std::isfinite(value))
      storage_ << key << value;
    else
      storage_ << key << "n/a";
  }
  void text(const std::string& key, const std::string& value) { storage_ << key << value; }
  void close() { storage_.release(); }

 private:
  cv::FileStorage storage_;
};

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

}  // namespace

int main(int argc, char** argv) {
  std::string output_dir = "out/bench", shared = EXOCET_SHARED_DATA_DIR;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string arg = argv[i];
    if (arg == "--output-dir")
      output_dir = argv[i + 1];
    else if (arg == "--shared-data")
      shared = argv[i + 1];
    else {
      std::cerr << "bench_reconstruction: unknown argument '" << arg << "' (--output-dir DIR --shared-data DIR)\n";
      return 2;
    }
  }
  fs::create_directories(output_dir);
  const std::string json_path = (fs::path(output_dir) / "reconstruction.json").string();
  JsonReport json(json_path);
  if (!json.ok()) {
    std::cerr << "bench_reconstruction: cannot write " << json_path << "\n";
    return 1;
  }
  try {
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
    json.number("calib_pairs_used", rig.pairs_used);
    json.number("calib_rms_left_px", rig.rms_left_px);
    json.number("calib_rms_right_px", rig.rms_right_px);
    json.number("calib_rms_stereo_px", rig.rms_stereo_px);
    json.number("calib_fx_left_px", rig.K_left.at<double>(0, 0));
    json.number("calib_fx_right_px", rig.K_right.at<double>(0, 0));
    json.number("calib_fx_left_minus_opencv_px", rig.K_left.at<double>(0, 0) - stored.K_left.at<double>(0, 0));
    json.number("calib_fx_right_minus_opencv_px", rig.K_right.at<double>(0, 0) - stored.K_right.at<double>(0, 0));
    json.number("calib_cx_left_minus_opencv_px", rig.K_left.at<double>(0, 2) - stored.K_left.at<double>(0, 2));
    json.number("calib_cy_left_minus_opencv_px", rig.K_left.at<double>(1, 2) - stored.K_left.at<double>(1, 2));
    json.number("calib_baseline_mm", rig.baseline_m * 1000.0);
    json.number("calib_optical_axes_deg", rig.optical_axes_angle_deg);
    json.number("calib_time_s", calib_s);

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
    json.number("temple_views_registered", result.views_registered);
    json.number("temple_points", static_cast<double>(result.points.size()));
    json.number("temple_observations", result.observations);
    json.number("temple_reproj_rms_px", result.final_rms_px);
    json.number("temple_center_err_pct", after.max_pct);
    json.number("temple_center_err_rms_pct", after.rms_pct);
    json.number("temple_initial_center_err_pct", before.max_pct);
    json.number("temple_initial_reproj_rms_px", result.initial_rms_px);
    json.number("temple_time_s", ours_s);

    // --- COLMAP on the same images. ---
    const ColmapOutcome colmap = runColmap(temple_dir, truth);
    json.text("colmap_status", colmap.status);
    json.number("colmap_usable", colmap.ok ? 1 : 0);
    json.number("colmap_time_s", colmap.ok ? colmap.seconds : NAN);
    json.number("colmap_time_ratio", colmap.ok ? ours_s / colmap.seconds : NAN);
    json.number("colmap_views_registered", colmap.ok ? colmap.views_registered : NAN);
    json.number("colmap_points", colmap.ok ? colmap.points : NAN);
    json.number("colmap_reproj_px", colmap.reproj_rms_px);
    json.number("colmap_center_err_pct", colmap.centre_err_max_pct);
    json.number("colmap_center_err_rms_pct", colmap.centre_err_rms_pct);

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
  } catch (const std::exception& e) {
    std::cerr << "bench_reconstruction: " << e.what() << "\n";
    return 1;
  }
  json.close();
  std::cout << "written " << json_path << "\n";
  return 0;
}
