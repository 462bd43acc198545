// Self-calibration end to end on images rendered by the dive simulator: a dive over relief with a yaw turn and roll and
// pitch oscillations (the intrinsics against the simulator's camera, the extrinsics against its poses), the same dive
// over a flat seabed (refused, or calibrated from homographies with --planar), and the self_calibrate tool on image
// folders and bags (exit codes, messages, the YAML it writes and that camera_calibration_parsers reads back).
#include <dlfcn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <gtest/gtest.h>
#include <rosbag/bag.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/CompressedImage.h>
#include <sensor_msgs/Image.h>
#include <yaml-cpp/yaml.h>
#include <opencv2/imgcodecs.hpp>

#include "exocet_mosaic/selfcal/self_calibration.h"
#include "exocet_common/camera_model.h"
#include "exocet_mosaic/sim/dive_description.h"
#include "exocet_mosaic/sim/rendered_dive.h"
#include "exocet_common/testing/paths.h"
#include "test_selfcal_scenes.h"

namespace {

using namespace exocet_mosaic;
namespace fs = std::filesystem;

const char* const kReliefDive = selfcal::testing::kRenderedReliefDiveYaml;
constexpr int kStep = selfcal::testing::kRenderedDiveStep;

struct Dive {
  sim::RenderedDive rendered;
  fs::path folder;  ///< the frames as PNG files
};

std::array<double, 4> percentErrors(const selfcal::Intrinsics& e, const exocet_common::CameraModel& truth) {
  return {100.0 * (e.alpha_u / truth.fx - 1.0), 100.0 * (e.alpha_v / truth.fy - 1.0), 100.0 * (e.u0 / truth.cx - 1.0),
          100.0 * (e.v0 / truth.cy - 1.0)};
}

struct ToolRun {
  int exit_code = -1;
  std::string out, err;
};

ToolRun runTool(const std::string& arguments, const fs::path& scratch) {
  const fs::path out = scratch / "tool.out", err = scratch / "tool.err";
  const std::string command = exocet_common::testing::executableDir() + "/self_calibrate " + arguments + " > " +
                              out.string() + " 2> " + err.string();
  const int status = std::system(command.c_str());
  ToolRun run;
  run.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  std::ifstream o(out), e(err);
  std::stringstream so, se;
  so << o.rdbuf();
  se << e.rdbuf();
  run.out = so.str();
  run.err = se.str();
  return run;
}

class RenderedSelfCalibration : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    scratch_ = new fs::path(fs::temp_directory_path() / ("exocet_test_selfcal_" + std::to_string(getpid())));
    fs::create_directories(*scratch_);
    relief_ = render({}, "relief");
    flat_ = render({"seabed.relief=false"}, "flat");
  }
  static void TearDownTestSuite() {
    std::error_code ignored;
    fs::remove_all(*scratch_, ignored);
    delete relief_;
    delete flat_;
    delete scratch_;
  }

  static Dive* render(const std::vector<std::string>& overrides, const std::string& name) {
    const sim::DiveDescription description = sim::parseDiveDescription(kReliefDive, overrides, ".");
    Dive* dive = new Dive{sim::renderDive(description, 2), *scratch_ / name};
    fs::create_directories(dive->folder);
    for (size_t i = 0; i < dive->rendered.gray.size(); ++i) {
      char file[32];
      std::snprintf(file, sizeof file, "frame_%04zu.png", i);
      cv::imwrite((dive->folder / file).string(), dive->rendered.gray[i]);
    }
    return dive;
  }

  static std::vector<selfcal::KeyFramePair> pairsOf(const Dive& dive) {
    selfcal::TrackerConfig config;
    config.step = kStep;
    selfcal::FeatureTrackBuilder builder(config);
    for (const cv::Mat& frame : dive.rendered.gray) builder.addFrame(frame);
    return builder.keyFramePairs();
  }

  static fs::path* scratch_;
  static Dive* relief_;
  static Dive* flat_;
};
fs::path* RenderedSelfCalibration::scratch_ = nullptr;
Dive* RenderedSelfCalibration::relief_ = nullptr;
Dive* RenderedSelfCalibration::flat_ = nullptr;

TEST_F(RenderedSelfCalibration, TheReliefDiveGivesTheSimulatorsIntrinsicsAndExtrinsics) {
  ASSERT_EQ(relief_->rendered.gray.size(), 71u);
  const exocet_common::CameraModel& truth = relief_->rendered.camera;
  const selfcal::SelfCalibrationResult r =
      selfcal::selfCalibrate(pairsOf(*relief_), cv::Size(truth.width, truth.height), selfcal::SelfCalibrationConfig());
  const std::string summary = selfcal::summaryText(r);
  std::cout << summary.substr(0, summary.find("Extrinsics"));
  const std::array<double, 4> err = percentErrors(r.intrinsics.value, truth);
  std::cout << "Errors against the simulator's camera (%): alpha_u " << err[0] << ", alpha_v " << err[1] << ", u0 "
            << err[2] << ", v0 " << err[3] << "\n";
  EXPECT_EQ(r.method, selfcal::CalibrationMethod::kMendoncaCipolla);
  EXPECT_FALSE(r.scene_planar);
  EXPECT_GE(r.key_frames_used, 5);
  // Measured: |errors| <= 0.6 %; asserted with margin for the rendering's and the tracker's small changes.
  for (double e : err) EXPECT_LT(std::abs(e), 3.0);
  // The 1-sigma must cover the error at 3 sigma.
  const double sigma[4] = {r.intrinsics.sigma.alpha_u, r.intrinsics.sigma.alpha_v, r.intrinsics.sigma.u0,
                           r.intrinsics.sigma.v0};
  const double value_error[4] = {r.intrinsics.value.alpha_u - truth.fx, r.intrinsics.value.alpha_v - truth.fy,
                                 r.intrinsics.value.u0 - truth.cx, r.intrinsics.value.v0 - truth.cy};
  for (int i = 0; i < 4; ++i) EXPECT_LT(std::abs(value_error[i]), 3.0 * sigma[i] + 0.5) << "parameter " << i;

  // Extrinsics of each used pair against the simulator's camera poses.
  std::vector<double> rotation_errors, direction_errors;
  for (const selfcal::PairReport& p : r.pairs) {
    if (!p.used) continue;
    ASSERT_TRUE(p.pose.ok);
    const Eigen::Isometry3d b_from_a =
        relief_->rendered.local_from_camera[p.frame_b].inverse() * relief_->rendered.local_from_camera[p.frame_a];
    rotation_errors.push_back(Eigen::AngleAxisd(p.pose.R_b_a * b_from_a.linear().transpose()).angle() * 180.0 / M_PI);
    direction_errors.push_back(std::acos(std::min(1.0, p.pose.t_b_a.dot(b_from_a.translation().normalized()))) * 180.0 /
                               M_PI);
  }
  std::sort(rotation_errors.begin(), rotation_errors.end());
  std::sort(direction_errors.begin(), direction_errors.end());
  const double rotation_median = rotation_errors[rotation_errors.size() / 2];
  const double direction_median = direction_errors[direction_errors.size() / 2];
  std::cout << "Extrinsics over " << rotation_errors.size() << " pairs: rotation error median " << rotation_median
            << " deg (worst " << rotation_errors.back() << "), translation direction median " << direction_median
            << " deg (worst " << direction_errors.back() << ")\n";
  EXPECT_LT(rotation_median, 0.5);
  EXPECT_LT(direction_median, 8.0);  // measured 4.3 deg: short baselines make the direction the weakest part
}

TEST_F(RenderedSelfCalibration, TheSameDiveOverAFlatSeabedIsDetectedAsPlanar) {
  const exocet_common::CameraModel& truth = flat_->rendered.camera;
  const std::vector<selfcal::KeyFramePair> pairs = pairsOf(*flat_);
  try {
    selfcal::selfCalibrate(pairs, cv::Size(truth.width, truth.height), selfcal::SelfCalibrationConfig());
    FAIL() << "a flat seabed must be refused";
  } catch (const selfcal::CalibrationImpossible& e) {
    EXPECT_EQ(e.reason(), selfcal::CalibrationImpossible::Reason::kFlatSeabed) << e.what();
  }
  selfcal::SelfCalibrationConfig planar;
  planar.allow_planar = true;
  const selfcal::SelfCalibrationResult r = selfcal::selfCalibrate(pairs, cv::Size(truth.width, truth.height), planar);
  const std::array<double, 4> err = percentErrors(r.intrinsics.value, truth);
  std::cout << "Flat dive, planar calibration errors (%): " << err[0] << ", " << err[1] << ", " << err[2] << ", "
            << err[3] << " (" << r.planar_pairs << " of " << r.pairs.size() << " pairs planar)\n";
  EXPECT_EQ(r.method, selfcal::CalibrationMethod::kPlanarHomographies);
  EXPECT_EQ(r.general_pairs, 0);
  for (double e : err) EXPECT_LT(std::abs(e), 3.0);  // measured: < 0.1 %
}

/// camera_calibration_parsers::readCalibration, loaded at run time: the package's CMakeLists does not link
/// camera_calibration_parsers (not a catkin component of it), but the library is installed. Null if it is not.
using ReadCalibration = bool (*)(const std::string&, std::string&, sensor_msgs::CameraInfo&);
ReadCalibration loadReadCalibration() {
  void* library = dlopen("libcamera_calibration_parsers.so", RTLD_NOW);
  if (!library) return nullptr;
  return reinterpret_cast<ReadCalibration>(dlsym(
      library,
      "_ZN26camera_calibration_parsers15readCalibrationERKNSt7__cxx1112basic_stringIcSt11char_traitsIcESaIcEEERS5_"
      "RN11sensor_msgs11CameraInfo_ISaIvEEE"));
}

TEST_F(RenderedSelfCalibration, TheToolCalibratesAnImageFolderAndWritesAYamlThatReloads) {
  const fs::path yaml = *scratch_ / "relief.yaml";
  const ToolRun run = runTool("--images " + relief_->folder.string() + " --step " + std::to_string(kStep) +
                                  " --output " + yaml.string() + " --camera-name downward",
                              *scratch_);
  ASSERT_EQ(run.exit_code, 0) << run.out << run.err;
  for (const char* word : {"alpha_u", "alpha_v", "u0", "v0", "+-", "Planarity: relief", "key-frame pairs"})
    EXPECT_NE(run.out.find(word), std::string::npos) << word << " missing from:\n" << run.out;

  // The same images through the library give the same numbers.
  const exocet_common::CameraModel& truth = relief_->rendered.camera;
  const selfcal::SelfCalibrationResult expected =
      selfcal::selfCalibrate(pairsOf(*relief_), cv::Size(truth.width, truth.height), selfcal::SelfCalibrationConfig());
  const exocet_common::CameraModel loaded = exocet_common::loadCameraModelYaml(yaml.string());
  EXPECT_EQ(loaded.width, truth.width);
  EXPECT_EQ(loaded.height, truth.height);
  EXPECT_NEAR(loaded.fx, expected.intrinsics.value.alpha_u, 1e-9 * truth.fx);
  EXPECT_NEAR(loaded.fy, expected.intrinsics.value.alpha_v, 1e-9 * truth.fy);
  EXPECT_NEAR(loaded.cx, expected.intrinsics.value.u0, 1e-9 * truth.cx);
  EXPECT_NEAR(loaded.cy, expected.intrinsics.value.v0, 1e-9 * truth.cy);
  EXPECT_NEAR(loaded.fx, truth.fx, 0.03 * truth.fx);

  const YAML::Node root = YAML::LoadFile(yaml.string());
  ASSERT_TRUE(root["self_calibration"]) << "the 1-sigma keys";
  EXPECT_NEAR(root["self_calibration"]["alpha_u_sigma_px"].as<double>(), expected.intrinsics.sigma.alpha_u, 1e-6);
  EXPECT_NEAR(root["self_calibration"]["v0_sigma_px"].as<double>(), expected.intrinsics.sigma.v0, 1e-6);
  EXPECT_EQ(root["self_calibration"]["method"].as<std::string>(), "mendonca_cipolla");
  EXPECT_EQ(root["camera_name"].as<std::string>(), "downward");

  const ReadCalibration read = loadReadCalibration();
  if (!read) GTEST_SKIP() << "libcamera_calibration_parsers.so is not installed";
  std::string name;
  sensor_msgs::CameraInfo info;
  ASSERT_TRUE(read(yaml.string(), name, info)) << "camera_calibration_parsers cannot read " << yaml;
  EXPECT_EQ(name, "downward");
  EXPECT_EQ(static_cast<int>(info.width), truth.width);
  EXPECT_EQ(static_cast<int>(info.height), truth.height);
  EXPECT_NEAR(info.K[0], loaded.fx, 1e-9);
  EXPECT_NEAR(info.K[2], loaded.cx, 1e-9);
  EXPECT_NEAR(info.K[4], loaded.fy, 1e-9);
  EXPECT_NEAR(info.K[5], loaded.cy, 1e-9);
  EXPECT_EQ(info.distortion_model, "plumb_bob");
}

TEST_F(RenderedSelfCalibration, TheToolRefusesAFlatSeabedWithExitCode3AndCalibratesItWithPlanar) {
  const fs::path yaml = *scratch_ / "flat.yaml";
  const std::string common =
      "--images " + flat_->folder.string() + " --step " + std::to_string(kStep) + " --output " + yaml.string();
  const ToolRun refused = runTool(common, *scratch_);
  EXPECT_EQ(refused.exit_code, 3) << refused.out << refused.err;
  EXPECT_NE(refused.err.find("the seabed is flat"), std::string::npos) << refused.err;
  EXPECT_NE(refused.err.find("fly over relief"), std::string::npos) << refused.err;
  EXPECT_NE(refused.err.find("--planar"), std::string::npos) << refused.err;
  EXPECT_FALSE(fs::exists(yaml)) << "nothing is written when the calibration is impossible";

  const ToolRun planar = runTool(common + " --planar", *scratch_);
  ASSERT_EQ(planar.exit_code, 0) << planar.out << planar.err;
  EXPECT_NE(planar.out.find("FLAT seabed"), std::string::npos) << planar.out;
  const exocet_common::CameraModel loaded = exocet_common::loadCameraModelYaml(yaml.string());
  EXPECT_NEAR(loaded.fx, flat_->rendered.camera.fx, 0.03 * flat_->rendered.camera.fx);
  EXPECT_EQ(YAML::LoadFile(yaml.string())["self_calibration"]["method"].as<std::string>(), "planar_homographies");
}

TEST_F(RenderedSelfCalibration, TheToolReadsRawAndCompressedImagesFromABag) {
  const fs::path bag_path = *scratch_ / "relief.bag";
  {
    rosbag::Bag bag(bag_path.string(), rosbag::bagmode::Write);
    for (size_t i = 0; i < relief_->rendered.gray.size(); ++i) {
      const ros::Time stamp(relief_->rendered.stamps_s[i]);
      sensor_msgs::Image raw;
      raw.header.stamp = stamp;
      raw.encoding = "mono8";
      raw.width = relief_->rendered.gray[i].cols;
      raw.height = relief_->rendered.gray[i].rows;
      raw.step = raw.width;
      raw.data.assign(relief_->rendered.gray[i].datastart, relief_->rendered.gray[i].dataend);
      bag.write("/camera/image_raw", stamp, raw);
      sensor_msgs::CompressedImage compressed;
      compressed.header.stamp = stamp;
      compressed.format = "mono8; png compressed ";
      cv::imencode(".png", relief_->rendered.gray[i], compressed.data);
      bag.write("/camera/image_raw/compressed", stamp, compressed);
    }
  }
  const std::string common = "--bag " + bag_path.string() + " --step " + std::to_string(kStep);
  std::vector<exocet_common::CameraModel> results;
  for (const char* topic : {"/camera/image_raw", "/camera/image_raw/compressed"}) {
    const fs::path yaml = *scratch_ / "bag.yaml";
    const ToolRun run = runTool(common + " --image-topic " + topic + " --output " + yaml.string(), *scratch_);
    ASSERT_EQ(run.exit_code, 0) << topic << "\n" << run.out << run.err;
    EXPECT_NE(run.out.find("Read 71 frames (384x288)"), std::string::npos) << run.out;
    results.push_back(exocet_common::loadCameraModelYaml(yaml.string()));
  }
  // Lossless PNG: both topics carry the same pixels, hence the same calibration.
  EXPECT_DOUBLE_EQ(results[0].fx, results[1].fx);
  EXPECT_DOUBLE_EQ(results[0].cy, results[1].cy);
  EXPECT_NEAR(results[0].fx, relief_->rendered.camera.fx, 0.03 * relief_->rendered.camera.fx);

  // --start-frame and --max-frames select the frames read.
  const ToolRun few = runTool(common + " --image-topic /camera/image_raw --start-frame 40 --max-frames 20 --output " +
                                  (*scratch_ / "few.yaml").string(),
                              *scratch_);
  EXPECT_EQ(few.exit_code, 3) << few.out << few.err;
  EXPECT_NE(few.out.find("Read 20 frames"), std::string::npos) << few.out;
  EXPECT_NE(few.err.find("too few key frames"), std::string::npos) << few.err;
}

TEST_F(RenderedSelfCalibration, TheToolNamesBadInputWithExitCode2) {
  const fs::path bag_path = *scratch_ / "relief.bag";
  const std::string out = " --output " + (*scratch_ / "bad.yaml").string();
  struct Case {
    std::string arguments, expected;
  };
  const std::vector<Case> cases = {
      {"--images /nonexistent/folder" + out, "/nonexistent/folder"},
      {"--images " + relief_->folder.string() + " --step 0" + out, "--step"},
      {"--images " + relief_->folder.string() + " --initial-hfov-deg 250" + out, "--initial-hfov-deg"},
      {"--images " + relief_->folder.string(), "--output"},
      {"--images " + relief_->folder.string() + " --frobnicate" + out, "--frobnicate"},
      {"--bag /nonexistent.bag --image-topic /camera/image_raw" + out, "/nonexistent.bag"},
      {"--images " + relief_->folder.string() + " --output /nonexistent/dir/camera.yaml", "/nonexistent/dir"},
  };
  for (const Case& c : cases) {
    const ToolRun run = runTool(c.arguments, *scratch_);
    EXPECT_EQ(run.exit_code, 2) << c.arguments << "\n" << run.err;
    EXPECT_NE(run.err.find(c.expected), std::string::npos) << c.arguments << "\n" << run.err;
  }
  if (fs::exists(bag_path)) {  // written by the bag test when it ran first
    const ToolRun run = runTool("--bag " + bag_path.string() + " --image-topic /camera/wrong" + out, *scratch_);
    EXPECT_EQ(run.exit_code, 2) << run.err;
    EXPECT_NE(run.err.find("/camera/wrong"), std::string::npos) << run.err;
    EXPECT_NE(run.err.find("/camera/image_raw/compressed (sensor_msgs/CompressedImage)"), std::string::npos)
        << "the bag's image topics are listed:\n"
        << run.err;
  }
}

}  // namespace
