/**
 * Tests of mosaic_video: the chain (VideoMosaicker through runVideoMosaic) on a rendered clip against its ground
 * truth; the built tool as a process: every bad input exits 2 with one line naming the argument and writes nothing;
 * SIGINT ends a run with status 130, complete tiles and no temporary file.
 */
#include <gtest/gtest.h>

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <gdal_priv.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "exocet_common/camera_model.h"
#include "exocet_common/testing/paths.h"
#include "exocet_common/testing/temp_dir.h"
#include "exocet_common/utm_grid.h"
#include "exocet_mosaic/video/video_run.h"
#include "tool_runner.h"
#include "video_fixtures.h"

namespace {

namespace fs = std::filesystem;
using exocet_common::testing::TempDir;
using exocet_mosaic::testing::RenderedVideo;
using nlohmann::json;

// 9 s of a PAL camera at 10 frames/s, 2.5 m over a flat seabed, starting a line at 0.4 m/s: about 2.8 m.
const char kClip[] = R"(
seed: 19
seabed_depth_m: 40.0
duration_s: 8.99
origin: {latitude_deg: 43.0712, longitude_deg: 5.8790}
seabed: {kind: procedural, relief: false}
camera: {preset: pal, hfov_deg: 60, fps: 10, encoding: bgr8, lever_arm_m: [0.0, 0.0, 0.0]}
trajectory: {kind: out_and_back, heading_deg: 75, speed_mps: 0.4, line_length_m: 6, altitude_m: 2.5}
imaging: {light_cone_strength: 0.4, vignetting: 0.2, noise_sigma_dn: 1.0}
)";

using exocet_mosaic::testing::readText;
using exocet_mosaic::testing::RunResult;

class MosaicVideo : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    scratch_ = new TempDir("exocet_test_mosaic_video_");
    const exocet_mosaic::sim::DiveDescription description =
        exocet_mosaic::sim::parseDiveDescription(kClip, {}, ".");
    const exocet_mosaic::sim::RenderedDive dive = exocet_mosaic::sim::renderDive(description, 2);
    clip_ = new RenderedVideo(exocet_mosaic::testing::writeVideo(dive, description, scratch_->file("clip.avi")));
    long_clip_ =
        new RenderedVideo(exocet_mosaic::testing::writeVideo(dive, description, scratch_->file("long.avi"), 8));
    exocet_common::saveCameraModelYaml(scratch_->file("camera.yaml"), clip_->camera, "pal");
    exocet_common::CameraModel hd = exocet_common::CameraModel::hd();
    exocet_common::saveCameraModelYaml(scratch_->file("camera_hd.yaml"), hd, "hd");
  }
  static void TearDownTestSuite() {
    delete clip_;
    delete long_clip_;
    delete scratch_;
  }

  static TempDir* scratch_;
  static RenderedVideo* clip_;
  static RenderedVideo* long_clip_;
};
TempDir* MosaicVideo::scratch_ = nullptr;
RenderedVideo* MosaicVideo::clip_ = nullptr;
RenderedVideo* MosaicVideo::long_clip_ = nullptr;

struct TrackRow {
  int frame = 0;
  bool has_position = false;
  Eigen::Vector2d en_m = Eigen::Vector2d::Zero();
  bool placed = false;
};

std::vector<TrackRow> readTrack(const std::string& path) {
  std::ifstream in(path);
  std::string line;
  std::getline(in, line);
  EXPECT_EQ(line, "frame,t_s,easting_m,northing_m,sigma_m,placed");
  std::vector<TrackRow> rows;
  while (std::getline(in, line)) {
    std::vector<std::string> cells;
    std::stringstream s(line);
    std::string cell;
    while (std::getline(s, cell, ',')) cells.push_back(cell);
    if (cells.size() != 6) {
      ADD_FAILURE() << "bad track row: " << line;
      continue;
    }
    TrackRow r;
    r.frame = std::stoi(cells[0]);
    r.has_position = !cells[2].empty();
    if (r.has_position) r.en_m = Eigen::Vector2d(std::stod(cells[2]), std::stod(cells[3]));
    r.placed = cells[5] == "1";
    rows.push_back(r);
  }
  return rows;
}

/// Opens a GeoTIFF with GDAL and reads every band whole: a complete file or a failure.
bool readableGeoTiff(const std::string& path, int* epsg) {
  GDALAllRegister();
  GDALDataset* dataset = static_cast<GDALDataset*>(GDALOpen(path.c_str(), GA_ReadOnly));
  if (dataset == nullptr) return false;
  bool ok = dataset->GetRasterXSize() > 0 && dataset->GetRasterYSize() > 0 && dataset->GetRasterCount() >= 1;
  std::vector<uint8_t> buffer(size_t(dataset->GetRasterXSize()) * dataset->GetRasterYSize());
  for (int b = 1; ok && b <= dataset->GetRasterCount(); ++b)
    ok = dataset->GetRasterBand(b)->RasterIO(GF_Read, 0, 0, dataset->GetRasterXSize(), dataset->GetRasterYSize(),
                                             buffer.data(), dataset->GetRasterXSize(), dataset->GetRasterYSize(),
                                             GDT_Byte, 0, 0, nullptr) == CE_None;
  if (epsg) {
    *epsg = 0;
    if (const OGRSpatialReference* srs = dataset->GetSpatialRef()) {
      const char* code = srs->GetAuthorityCode(nullptr);
      if (code) *epsg = std::atoi(code);
    }
  }
  GDALClose(dataset);
  return ok;
}

TEST_F(MosaicVideo, PlacesEveryFrameAtItsTrueDistanceAndDirection) {
  ASSERT_GE(clip_->frames, 80);
  TempDir out("exocet_test_mosaic_video_run_");
  exocet_mosaic::video::VideoRunOptions o;
  o.video_path = clip_->path;
  o.output_dir = out.file("dive");
  o.altitude_m = 2.5;
  o.camera_path = scratch_->file("camera.yaml");
  o.origin_latitude_deg = clip_->origin_latitude_deg;
  o.origin_longitude_deg = clip_->origin_longitude_deg;
  o.heading_deg = clip_->true_heading_deg;
  std::atomic<bool> stop{false};
  std::ostringstream messages, errors;
  ASSERT_EQ(exocet_mosaic::video::runVideoMosaic(o, stop, messages, errors), 0) << errors.str();

  const json summary = json::parse(readText(o.output_dir + "/summary.json"));
  EXPECT_EQ(summary["frames_read"].get<int>(), clip_->frames);
  EXPECT_GE(summary["frames_placed_fraction"].get<double>(), 0.99) << summary.dump(2);
  EXPECT_GE(summary["frames_registered"].get<int>(), clip_->frames - 1 - clip_->frames / 100);
  EXPECT_EQ(summary["frame"], "utm");
  EXPECT_EQ(summary["epsg"].get<int>(), 32631);
  EXPECT_EQ(summary["camera"], "file");
  EXPECT_FALSE(summary["scale_approximate"].get<bool>());
  EXPECT_TRUE(summary["reason"].is_null());
  ASSERT_GE(summary["tiles_written"].get<int>(), 1);
  for (const auto& tile : summary["tiles"]) {
    int epsg = 0;
    EXPECT_TRUE(readableGeoTiff(tile.get<std::string>(), &epsg)) << tile;
    EXPECT_EQ(epsg, 32631) << tile;
  }
  EXPECT_TRUE(fs::is_regular_file(o.output_dir + "/overview.png"));
  EXPECT_FALSE(cv::imread(o.output_dir + "/overview.png").empty());

  // The fused track against the truth: the first frame at the start point, the others at their true displacement
  // from it (distance within 2 %, direction within 2 % of the distance).
  const std::vector<TrackRow> track = readTrack(o.output_dir + "/track.csv");
  ASSERT_EQ(static_cast<int>(track.size()), clip_->frames);
  ASSERT_TRUE(track[0].has_position);
  const exocet_common::UtmGrid grid = exocet_common::UtmGrid::forLatLon(clip_->origin_latitude_deg,
                                                                        clip_->origin_longitude_deg);
  const Eigen::Vector2d start = grid.toGrid(clip_->origin_latitude_deg, clip_->origin_longitude_deg);
  EXPECT_LT((track[0].en_m - start).norm(), 1e-3);
  int placed = 0, compared = 0;
  double worst_distance = 0.0, worst_vector = 0.0;
  for (const TrackRow& r : track) {
    placed += r.placed ? 1 : 0;
    const Eigen::Vector2d truth = clip_->camera_local_m[r.frame] - clip_->camera_local_m[0];
    if (!r.has_position || truth.norm() < 1.0) continue;
    const Eigen::Vector2d fused = r.en_m - track[0].en_m;
    worst_distance = std::max(worst_distance, std::abs(fused.norm() - truth.norm()) / truth.norm());
    worst_vector = std::max(worst_vector, (fused - truth).norm() / truth.norm());
    ++compared;
  }
  std::cout << "frames " << clip_->frames << ", placed " << placed << ", compared " << compared
            << ", worst relative distance error " << worst_distance << ", worst relative displacement error "
            << worst_vector << ", " << summary["fps"].get<double>() << " frames/s\n";
  EXPECT_GE(placed, static_cast<int>(std::ceil(0.99 * clip_->frames)));
  EXPECT_GE(compared, 20);
  EXPECT_LT(worst_distance, 0.02) << "relative distance error";
  EXPECT_LT(worst_vector, 0.02) << "relative displacement error (direction included)";
}

// ---- The built tool as a process ------------------------------------------------------------------------------------

RunResult runTool(const std::vector<std::string>& args, const TempDir& scratch) {
  return exocet_mosaic::testing::runTool("mosaic_video", args, scratch);
}

TEST_F(MosaicVideo, BadInputsExitTwoWithOneLineNamingTheArgument) {
  TempDir scratch("exocet_test_mosaic_video_bad_");
  std::ofstream(scratch.file("text.mp4")) << "not a video\n";
  std::ofstream(scratch.file("empty.mp4")).close();
  {
    cv::VideoWriter one(scratch.file("one.avi"), cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 10.0,
                        cv::Size(clip_->camera.width, clip_->camera.height), true);
    ASSERT_TRUE(one.isOpened());
    one.write(cv::Mat(clip_->camera.height, clip_->camera.width, CV_8UC3, cv::Scalar(90, 120, 100)));
  }
  fs::create_directories(scratch.file("full"));
  std::ofstream(scratch.file("full/notes.txt")) << "someone's file\n";
  const std::string out = scratch.file("out");
  struct Case {
    std::vector<std::string> args;
    std::string names;
  };
  const std::vector<Case> cases = {
      {{scratch.file("missing.mp4"), "--altitude", "2", "--output", out}, "VIDEO"},
      {{scratch.file("text.mp4"), "--altitude", "2", "--output", out}, "VIDEO"},
      {{scratch.file("empty.mp4"), "--altitude", "2", "--output", out}, "VIDEO"},
      {{scratch.file("one.avi"), "--altitude", "2", "--output", out}, "too short"},
      {{clip_->path, "--altitude", "0", "--output", out}, "--altitude"},
      {{clip_->path, "--altitude", "500", "--output", out}, "--altitude"},
      {{clip_->path, "--altitude", "abc", "--output", out}, "--altitude"},
      {{clip_->path, "--altitude", "2", "--output", out, "--camera", scratch_->file("camera_hd.yaml")}, "--camera"},
      {{clip_->path, "--altitude", "2", "--output", scratch.file("full")}, "--output"},
      {{clip_->path, "--altitude", "2", "--output", scratch.file("full"), "--overwrite"}, "--output"},
      {{clip_->path, "--altitude", "2", "--output", out, "--origin-lat", "43"}, "--origin-lon"},
      {{clip_->path, "--altitude", "2", "--output", out, "--hfov", "180"}, "--hfov"},
      {{clip_->path, "--output", out}, "--altitude"},
  };
  for (const Case& c : cases) {
    std::string line;
    for (const auto& a : c.args) line += a + " ";
    const RunResult r = runTool(c.args, scratch);
    EXPECT_EQ(r.exit_code, 2) << line << "\n" << r.err;
    EXPECT_NE(r.err.find(c.names), std::string::npos) << line << "\n" << r.err;
    EXPECT_TRUE(r.out.empty()) << line << "\n" << r.out;
    // One line: the tool's own checks; CLI11's parse errors add the line pointing at --help.
    EXPECT_LE(std::count(r.err.begin(), r.err.end(), '\n'), 2) << line << "\n" << r.err;
    EXPECT_FALSE(fs::exists(out)) << line << ": the output folder was made";
    EXPECT_FALSE(fs::exists(scratch.file("full/summary.json"))) << line;
  }
  // The help states the defaults of the camera's field of view and the altitude's range.
  const RunResult help = runTool({"--help"}, scratch);
  EXPECT_EQ(help.exit_code, 0);
  for (const char* part : {"--altitude", "[0.1, 100]", "--hfov", "60", "--camera", "--origin-lat", "--origin-lon",
                           "--heading", "--nav", "--overwrite", "--progress"})
    EXPECT_NE(help.out.find(part), std::string::npos) << part << "\n" << help.out;
}

TEST_F(MosaicVideo, InterruptedRunExits130WithCompleteTilesAndNoTemporaries) {
  TempDir scratch("exocet_test_mosaic_video_int_");
  const std::string out = scratch.file("dive");
  const std::string tool = exocet_common::testing::executableDir() + "/mosaic_video";
  const std::string camera = scratch_->file("camera.yaml");
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    const int null = ::open("/dev/null", O_WRONLY);
    dup2(null, STDOUT_FILENO);
    dup2(null, STDERR_FILENO);
    execl(tool.c_str(), tool.c_str(), long_clip_->path.c_str(), "--altitude", "2.5", "--output", out.c_str(),
          "--camera", camera.c_str(), "--origin-lat", "43.0712", "--origin-lon", "5.879", static_cast<char*>(nullptr));
    _exit(127);
  }
  // Interrupt once the run is under way (its first tile written, a second mosaic open), before the clip's end.
  int status = 0;
  bool still_running = true;
  const auto started = std::chrono::steady_clock::now();
  while ((still_running = waitpid(pid, &status, WNOHANG) == 0) && !fs::exists(out + "/tile_0000.tif") &&
         std::chrono::steady_clock::now() - started < std::chrono::seconds(120))
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  ASSERT_TRUE(still_running) << "the run ended (status " << status << ") before it could be interrupted";
  ASSERT_EQ(kill(pid, SIGINT), 0);
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 130);

  const json summary = json::parse(readText(out + "/summary.json"));
  EXPECT_EQ(summary["reason"], "interrupted");
  EXPECT_GT(summary["frames_read"].get<int>(), 0);
  EXPECT_LT(summary["frames_read"].get<int>(), long_clip_->frames);
  EXPECT_GE(summary["tiles_written"].get<int>(), 1);
  int tiles = 0;
  for (const fs::directory_entry& e : fs::directory_iterator(out)) {
    const std::string name = e.path().filename().string();
    EXPECT_EQ(name.find("partial"), std::string::npos) << "temporary file left: " << name;
    EXPECT_NE(name[0], '.') << "temporary file left: " << name;
    if (e.path().extension() == ".tif") {
      ++tiles;
      int epsg = 0;
      EXPECT_TRUE(readableGeoTiff(e.path().string(), &epsg)) << name;
      EXPECT_EQ(epsg, 32631) << name;
    }
  }
  EXPECT_EQ(tiles, summary["tiles_written"].get<int>());
  EXPECT_TRUE(fs::is_regular_file(out + "/track.csv"));
}

}  // namespace
