/**
 * Tests of the command lines of the built tools and benchmarks (parsed with CLI11 through exocet_common/command_line.h):
 * --help exits 0 and names every option; an unknown option, a value out of range, a missing file exit 2 with a
 * message naming the option and the value; register_images prints its JSON object with the same keys.
 */
#include <gtest/gtest.h>

#include <sys/wait.h>

#include <cstdlib>
#include <fstream>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "exocet_common/testing/paths.h"
#include "exocet_common/testing/temp_dir.h"
#include "tool_runner.h"

namespace {

using exocet_common::testing::TempDir;

using exocet_mosaic::testing::readText;
using exocet_mosaic::testing::RunResult;

/// Runs the built `tool` of this package with `args`.
RunResult run(const std::string& tool, const std::vector<std::string>& args, const TempDir& scratch) {
  return exocet_mosaic::testing::runTool(tool, args, scratch);
}

void expectMentions(const std::string& text, const std::vector<std::string>& parts, const std::string& what) {
  for (const auto& part : parts)
    EXPECT_NE(text.find(part), std::string::npos) << what << ": no '" << part << "' in\n" << text;
}

struct ToolOptions {
  std::string tool;
  std::vector<std::string> options;
};

TEST(CommandLineTools, HelpExitsZeroAndNamesEveryOption) {
  TempDir scratch;
  const std::vector<std::string> bench = {"--output-dir", "--shared-data"};
  const auto with_bench = [&](std::vector<std::string> o) {
    o.insert(o.end(), bench.begin(), bench.end());
    return o;
  };
  const std::vector<ToolOptions> tools = {
      {"adjust_tiles", {"--tiles", "--output", "--report", "--patch-px", "--patch-sigma-px", "--rotation-scale-sigma"}},
      {"register_images", {"--method", "--model", "klt", "rmr", "auto", "homography", "translation"}},
      {"self_calibrate",
       {"--bag", "--image-topic", "--images", "--output", "--step", "--max-frames", "--start-frame",
        "--initial-hfov-deg", "--planar", "--seed", "--camera-name"}},
      {"dive_synth",
       {"--config", "--output", "--seed", "--duration", "--preset", "--trajectory", "--waypoints", "--relief",
        "--seabed-image", "--seabed-pixel-size", "--ideal", "--encoding", "--image-storage", "--threads", "--set",
        "--print-config", "--quiet"}},
      {"dive_import",
       {"--images", "--nav", "--camera", "--output", "--image-times", "--start-time", "--fps", "--origin-lat",
        "--origin-lon", "--encoding", "--image-storage", "--camera-pose", "t_unix_s"}},
      {"bench_dive_synth", bench},
      {"bench_selfcal", with_bench({"--runs"})},
      {"bench_fusion", with_bench({"--dive", "--no-cross-pass", "--monte-carlo", "--monte-carlo-set",
                                   "--monte-carlo-exact-camera", "--filter"})},
      {"bench_registration", with_bench({"--frames", "--only", "--methods"})},
  };
  for (const ToolOptions& t : tools) {
    const RunResult r = run(t.tool, {"--help"}, scratch);
    EXPECT_EQ(r.exit_code, 0) << t.tool << ": " << r.err;
    EXPECT_TRUE(r.err.empty()) << t.tool << ": " << r.err;
    expectMentions(r.out, t.options, t.tool + " --help");
    expectMentions(r.out, {"--help"}, t.tool + " --help");
  }
}

TEST(CommandLineTools, BadInputExitsTwoNamingTheOptionAndValue) {
  TempDir scratch;
  const std::string image = scratch.file("a.png");
  ASSERT_TRUE(cv::imwrite(image, cv::Mat(64, 64, CV_8UC1, cv::Scalar(128))));
  struct Case {
    std::string tool;
    std::vector<std::string> args;
    std::vector<std::string> mentions;
  };
  const std::vector<Case> cases = {
      // Unknown options (the required ones given, so that the unknown one is what is wrong).
      {"adjust_tiles", {"--tiles", scratch.path(), "--output", scratch.path(), "--frobnicate"}, {"--frobnicate"}},
      {"register_images", {image, image, "--frobnicate"}, {"--frobnicate"}},
      {"bench_dive_synth", {"--frobnicate"}, {"--frobnicate"}},
      {"bench_fusion", {"--output-dir", scratch.path(), "--frobnicate"}, {"--frobnicate"}},
      // Values out of range or not among the allowed ones.
      {"self_calibrate",
       {"--images", scratch.path(), "--output", scratch.file("k.yaml"), "--step", "0"},
       {"--step", "0"}},
      {"self_calibrate",
       {"--images", scratch.path(), "--output", scratch.file("k.yaml"), "--initial-hfov-deg", "179"},
       {"--initial-hfov-deg", "179"}},
      {"self_calibrate",
       {"--images", scratch.path(), "--output", scratch.file("k.yaml"), "--max-frames", "x"},
       {"--max-frames", "x"}},
      {"register_images", {"--method", "sift", image, image}, {"--method", "sift"}},
      {"register_images", {"--model", "projective", image, image}, {"--model", "projective"}},
      {"bench_selfcal", {"--runs", "0"}, {"--runs", "0"}},
      {"bench_registration", {"--only", "accuracy,speedy"}, {"--only", "speedy"}},
      {"bench_fusion", {"--filter", "no_such_field=1"}, {"--filter", "no_such_field"}},
      {"bench_fusion", {"--filter", "position_noise_m2_per_s"}, {"--filter", "NAME=VALUE"}},
      {"bench_fusion", {"--monte-carlo", "-1"}, {"--monte-carlo", "-1"}},
      // Files and folders that do not exist, missing values and required options.
      {"adjust_tiles", {"--tiles", scratch.file("none"), "--output", scratch.path()}, {"--tiles", "none"}},
      {"register_images", {image, scratch.file("missing.png")}, {"missing.png"}},
      {"register_images", {image}, {"images"}},
      {"dive_synth", {"--config", scratch.file("none.yaml"), "--print-config"}, {"--config", "none.yaml"}},
      {"dive_synth", {"--seed"}, {"--seed"}},
      {"self_calibrate", {"--images", scratch.path()}, {"--output"}},
      {"dive_import", {"--images", scratch.path(), "--nav", image, "--camera", image}, {"--output"}},
  };
  for (const Case& c : cases) {
    std::string command = c.tool;
    for (const auto& a : c.args) command += " " + a;
    const RunResult r = run(c.tool, c.args, scratch);
    EXPECT_EQ(r.exit_code, 2) << command << "\n" << r.out << r.err;
    expectMentions(r.err, c.mentions, command);
  }
}

// The shortcuts of dive_synth are applied in the order given, among --set's: the last setting of a key wins.
TEST(CommandLineTools, DiveSynthShortcutsKeepTheirOrder) {
  TempDir scratch;
  const RunResult set_last = run("dive_synth", {"--seed", "5", "--set", "seed=3", "--print-config"}, scratch);
  ASSERT_EQ(set_last.exit_code, 0) << set_last.err;
  EXPECT_NE(set_last.out.find("seed: 3\n"), std::string::npos) << set_last.out;
  const RunResult seed_last = run("dive_synth", {"--set", "seed=3", "--seed", "5", "--print-config"}, scratch);
  ASSERT_EQ(seed_last.exit_code, 0) << seed_last.err;
  EXPECT_NE(seed_last.out.find("seed: 5\n"), std::string::npos) << seed_last.out;
}

TEST(CommandLineTools, RegisterImagesPrintsOneJsonObject) {
  TempDir scratch;
  cv::Mat a(240, 320, CV_8UC1);
  cv::RNG rng(7);
  rng.fill(a, cv::RNG::UNIFORM, 0, 255);
  cv::GaussianBlur(a, a, cv::Size(0, 0), 2.0);
  cv::Mat b;
  const cv::Mat shift = (cv::Mat_<double>(2, 3) << 1, 0, 3.0, 0, 1, -2.0);
  cv::warpAffine(a, b, shift, a.size(), cv::INTER_LINEAR, cv::BORDER_REFLECT);
  ASSERT_TRUE(cv::imwrite(scratch.file("a.png"), a));
  ASSERT_TRUE(cv::imwrite(scratch.file("b.png"), b));
  const RunResult r =
      run("register_images", {"--model", "translation", scratch.file("a.png"), scratch.file("b.png")}, scratch);
  ASSERT_TRUE(r.exit_code == 0 || r.exit_code == 3) << r.exit_code << " " << r.err;
  const nlohmann::json json = nlohmann::json::parse(r.out);
  std::set<std::string> keys;
  for (const auto& item : json.items()) keys.insert(item.key());
  EXPECT_EQ(keys, (std::set<std::string>{"matrix", "homography", "model", "method", "centre_px", "parameters",
                                         "covariance", "quality", "failed", "failure", "failure_detail"}));
  EXPECT_EQ(json["model"], "translation");
  EXPECT_EQ(json["homography"].size(), 3u);
  EXPECT_EQ(json["matrix"].size(), 2u);
  EXPECT_TRUE(json["quality"].contains("inlier_fraction"));
  if (r.exit_code == 0) {
    EXPECT_NEAR(json["homography"][0][2].get<double>(), 3.0, 0.2) << r.out;
    EXPECT_NEAR(json["homography"][1][2].get<double>(), -2.0, 0.2) << r.out;
  }
}

}  // namespace
