// LoopCloser: live loop closure from rendered key frames of an out-and-back line whose return pass drifted.
#include <chrono>
#include <cmath>
#include <filesystem>
#include <vector>

#include <gtest/gtest.h>

#include "exocet_mosaic/graph/background_pose_graph.h"
#include "exocet_mosaic/graph/loop_closer.h"
#include "loop_scene.h"

namespace exocet_mosaic {
namespace graph {
namespace {

using namespace testing;

/// The scene of ClosesTheLoopsOfADriftedReturnPass, searched with `config`; checks the loops close.
void closeTheLoopsOfADriftedReturnPass(const LoopCloserConfig& config) {
  const auto start = std::chrono::steady_clock::now();
  sim::ProceduralSeabedConfig seabed;
  seabed.seed = 20261205;
  const Scene scene(seabed, murkyLamp());
  // Out along a 4.8 m line (ENU yaw 20 deg), a key frame every 0.4 m, 1 s apart; back over it 60 s later, 0.2 m to
  // the side. The chain's return pass drifted by 0.5 m and 2 degrees across the turn (within that odometry's
  // 1-sigma); the outbound one is right.
  const double yaw = 20.0 * M_PI / 180.0;
  const Eigen::Vector2d along(std::cos(yaw), std::sin(yaw)), across(-along.y(), along.x());
  std::vector<TruePose> truth;
  std::vector<Pose2d> chain;
  std::vector<double> stamps;
  const int per_pass = 13;
  for (int k = 0; k < per_pass; ++k) {
    const Eigen::Vector2d p = 0.4 * k * along;
    truth.push_back(TruePose{p.x(), p.y(), 2.5, yaw, 0.01 * std::sin(k), 0.01 * std::cos(k)});
    stamps.push_back(100.0 + k);
  }
  for (int k = per_pass - 1; k >= 0; --k) {
    const Eigen::Vector2d p = 0.4 * k * along + 0.2 * across;
    truth.push_back(TruePose{p.x(), p.y(), 2.45, yaw + M_PI, -0.01 * std::cos(k), 0.015 * std::sin(k)});
    stamps.push_back(160.0 + (per_pass - 1 - k));
  }
  // The chain: exact odometry along each pass; across the turn it measured 0.5 m too far and 2 degrees too much.
  std::vector<RelativePose2d> odometry;
  chain.push_back(truth[0].pose2d());
  for (size_t i = 1; i < truth.size(); ++i) {
    RelativePose2d d = between(truth[i - 1].pose2d(), truth[i].pose2d());
    if (i == static_cast<size_t>(per_pass)) {
      d.translation_m += Eigen::Vector2d(0.5, 0.0);
      d.yaw_rad += 2.0 * M_PI / 180.0;
    }
    odometry.push_back(d);
    chain.push_back(compose(chain.back(), d));
  }

  BackgroundPoseGraph graph;
  LoopCloser closer(config, &graph);
  for (size_t i = 0; i < truth.size(); ++i) {
    graph.addKeyFrame(int64_t(i), stamps[i], chain[i]);
    if (i > 0) {
      const bool turn = i == static_cast<size_t>(per_pass);
      // The chain's odometry: what it measured (the drift enters across the turn), with the matching uncertainty.
      const Eigen::Vector3d sigma = turn ? Eigen::Vector3d(0.5, 0.5, 0.05) : Eigen::Vector3d(0.005, 0.005, 0.002);
      graph.addOdometry(int64_t(i - 1), int64_t(i), odometry[i - 1], sigma.cwiseProduct(sigma).asDiagonal());
    }
    LoopCloserKeyFrame k;
    k.key_frame.id = int64_t(i);
    k.key_frame.stamp_s = stamps[i];
    k.key_frame.pose = chain[i];
    k.key_frame.position_cov_m2 = Eigen::Matrix2d::Identity() * (i >= size_t(per_pass) ? 0.36 : 0.01);
    k.key_frame.yaw_sigma_rad = 0.05;
    k.key_frame.camera_height_m = truth[i].height_m;
    k.key_frame.camera = smallCamera();
    k.view = truth[i].view();
    k.gray = scene.render(truth[i], int(i));
    closer.addKeyFrame(k);
  }
  ASSERT_TRUE(closer.waitIdle(120.0));
  ASSERT_TRUE(graph.waitIdle(60.0));
  const LoopCloserStats stats = closer.stats();
  const auto snapshot = graph.snapshot();
  double worst_before = 0.0, worst_after = 0.0;
  for (size_t i = per_pass; i < truth.size(); ++i) {
    const Eigen::Vector2d t = truth[i].pose2d().position_en_m;
    worst_before = std::max(worst_before, (chain[i].position_en_m - t).norm());
    worst_after = std::max(worst_after, (snapshot->find(int64_t(i))->pose.position_en_m - t).norm());
  }
  int accepted = 0;
  for (char a : snapshot->loop_accepted) accepted += a;
  std::cout << stats.key_frames_done << " key frames searched, " << stats.candidates << " candidates verified, "
            << stats.loops_added << " loops added, " << accepted << " accepted by the graph, " << stats.dropped
            << " dropped; return pass worst error " << worst_before << " m -> " << worst_after
            << " m; last refusal: " << stats.last_refusal << "; "
            << std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() << " s\n";
  EXPECT_TRUE(stats.last_error.empty()) << stats.last_error;
  EXPECT_EQ(stats.key_frames_done, truth.size());
  EXPECT_GE(stats.loops_added, 8u);
  EXPECT_EQ(accepted, int(stats.loops_added));
  EXPECT_GT(worst_before, 0.5);
  EXPECT_LT(worst_after, 0.02);
  if (!config.image_folder.empty()) {
    // The images beyond the memory's few were read back from their files.
    EXPECT_EQ(stats.images.in_memory, static_cast<uint64_t>(config.images_in_memory));
    EXPECT_EQ(stats.images.on_disk, truth.size());
    EXPECT_EQ(stats.images.lost, 0u);
    EXPECT_EQ(stats.refusals.count("image unavailable"), 0u);
  }
}

TEST(LoopCloser, ClosesTheLoopsOfADriftedReturnPass) { closeTheLoopsOfADriftedReturnPass(LoopCloserConfig()); }

TEST(LoopCloser, ClosesTheLoopsWithItsImagesOnDisk) {
  LoopCloserConfig config;
  config.image_folder = (std::filesystem::temp_directory_path() / "exocet_test_loop_closer_images").string();
  config.images_in_memory = 2;
  closeTheLoopsOfADriftedReturnPass(config);
  std::filesystem::remove_all(config.image_folder);
}

TEST(LoopCloser, BadInputIsRefusedWithItsName) {
  BackgroundPoseGraph graph;
  LoopCloserConfig bad;
  bad.max_queue = 0;
  bad.jpeg_quality = 10;
  EXPECT_NE(bad.validate().find("max_queue"), std::string::npos);
  EXPECT_NE(bad.validate().find("jpeg_quality"), std::string::npos);
  EXPECT_THROW(LoopCloser(bad, &graph), std::invalid_argument);
  EXPECT_THROW(LoopCloser(LoopCloserConfig(), nullptr), std::invalid_argument);
  LoopCloser closer(LoopCloserConfig(), &graph);
  LoopCloserKeyFrame k;
  k.key_frame.camera = smallCamera();
  k.view = TruePose{0, 0, 2.5, 0.0}.view();
  k.gray = cv::Mat(10, 10, CV_8UC1, cv::Scalar(0));
  try {
    closer.addKeyFrame(k);
    FAIL() << "an image of another size must be refused";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("image"), std::string::npos) << e.what();
  }
  closer.stop();
  closer.stop();  // idempotent
}

}  // namespace
}  // namespace graph
}  // namespace exocet_mosaic
