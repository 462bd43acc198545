// When the composer closes a mosaic (frames, extent, memory, navigation jump, flush), how it bridges a failed
// registration, skips images without pose, and keeps its memory bounded on a long line.
#include <gtest/gtest.h>

#include <cstdio>

#include "compose_fixtures.h"

namespace ec = exocet_mosaic::compose;
using compose_test::FrameFactory;
using compose_test::TruthOrtho;

namespace {

// Small images (fast): 96x72 px, 2 cm pixels at 2.2 m.
const TruthOrtho& truth() {
  static const TruthOrtho t = TruthOrtho::make(30.0, 10.0, 0.01, 500000.0 - 3.0, 4800000.0 + 5.0);
  return t;
}

FrameFactory smallFactory(double noise_m = 0.0) {
  FrameFactory f;
  f.truth = &truth();
  f.position_noise_m = noise_m;
  f.flight.image_size = cv::Size(96, 72);
  f.flight.k = cv::Matx33d(110, 0, 47.5, 0, 110, 35.5, 0, 0, 1);
  f.flight.step_m = 0.05;
  return f;
}

ec::ComposerConfig smallConfig() {
  ec::ComposerConfig c;
  c.lighting.enabled = false;
  c.frames_per_mosaic = 100000;
  c.block_size_px = 64;
  return c;
}

double footprintExtent(const ec::ClosedMosaic& t) {
  Eigen::Vector2d lo = Eigen::Vector2d::Constant(1e300), hi = -lo;
  for (const auto& f : t.footprints_en_m)
    for (const auto& p : f) {
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
  return (hi - lo).maxCoeff();
}

}  // namespace

TEST(ComposeClosing, ByFrameCountWithOneSharedImage) {
  FrameFactory factory = smallFactory();
  ec::ComposerConfig config = smallConfig();
  config.frames_per_mosaic = 10;
  ec::MosaicComposer composer(config);
  std::vector<ec::ClosedMosaic> tiles;
  for (int i = 0; i < 25; ++i)
    if (auto t = composer.add(factory.frame(i))) tiles.push_back(*t);
  ASSERT_EQ(tiles.size(), 2u);
  EXPECT_EQ(tiles[0].close_reason, "frames");
  EXPECT_EQ(tiles[0].first_frame, 0);
  EXPECT_EQ(tiles[0].last_frame, 9);
  EXPECT_EQ(tiles[0].frames_added, 10);
  EXPECT_EQ(tiles[1].first_frame, 9);  // the closing image starts the next mosaic
  EXPECT_EQ(tiles[1].last_frame, 18);
  EXPECT_NEAR(tiles[0].start_time_s, 0.0, 1e-12);
  EXPECT_NEAR(tiles[0].end_time_s, 0.36, 1e-12);
  EXPECT_NEAR(tiles[0].mean_camera_height_m, 2.2, 0.1);
  // The last image before a close is composed even when it is not a key frame.
  const auto fp_last = factory.flight.footprint(9);
  bool found = false;
  for (const auto& f : tiles[0].footprints_en_m) found |= (f[0] - fp_last[0]).norm() < 1e-6;
  EXPECT_TRUE(found);
  const auto flushed = composer.flush();
  ASSERT_TRUE(flushed);
  EXPECT_EQ(flushed->close_reason, "flush");
  EXPECT_EQ(flushed->first_frame, 18);
  EXPECT_EQ(flushed->last_frame, 24);
  EXPECT_FALSE(composer.flush());  // nothing open any more
  EXPECT_EQ(composer.stats().mosaics_closed, 3);
}

TEST(ComposeClosing, ByExtent) {
  FrameFactory factory = smallFactory();
  ec::ComposerConfig config = smallConfig();
  config.max_extent_m = 3.0;
  ec::MosaicComposer composer(config);
  std::vector<ec::ClosedMosaic> tiles;
  for (int i = 0; i < 200; ++i)  // 10 m
    if (auto t = composer.add(factory.frame(i))) tiles.push_back(*t);
  ASSERT_GE(tiles.size(), 3u);
  for (const auto& t : tiles) {
    EXPECT_EQ(t.close_reason, "extent");
    const double extent = footprintExtent(t);
    EXPECT_GE(extent, 3.0);
    EXPECT_LT(extent, 3.0 + 0.25);  // at most one key-frame step beyond
  }
}

TEST(ComposeClosing, ByMemory) {
  FrameFactory factory = smallFactory();
  ec::ComposerConfig config = smallConfig();
  config.max_memory_mb = 1.0;  // 64x64x4 floats = 64 KiB a block: 16 blocks
  ec::MosaicComposer composer(config);
  std::vector<ec::ClosedMosaic> tiles;
  std::size_t peak = 0;
  for (int i = 0; i < 400; ++i) {  // 20 m
    if (auto t = composer.add(factory.frame(i))) tiles.push_back(*t);
    peak = std::max(peak, composer.stats().open_memory_bytes);
  }
  ASSERT_GE(tiles.size(), 2u);
  for (const auto& t : tiles) EXPECT_EQ(t.close_reason, "memory");
  std::printf("memory limit 1 MiB: peak of the open mosaic %.2f MiB, %zu tiles\n", peak / 1048576.0, tiles.size());
  EXPECT_LT(peak, 1.5 * 1048576);
}

TEST(ComposeClosing, ByNavigationJump) {
  FrameFactory factory = smallFactory(0.05);
  ec::ComposerConfig config = smallConfig();
  ec::MosaicComposer composer(config);
  std::vector<ec::ClosedMosaic> tiles;
  for (int i = 0; i < 60; ++i) {
    ec::ComposerFrame f = factory.frame(i);
    if (i >= 30) f.pose->camera_en_m += Eigen::Vector2d(0.0, 3.0);  // the fused navigation jumps 3 m north
    if (auto t = composer.add(f)) tiles.push_back(*t);
  }
  ASSERT_EQ(tiles.size(), 1u);
  EXPECT_EQ(tiles[0].close_reason, "navigation_jump");
  // Confirmed on its third image: the two before stay in the old mosaic, placed by the chain.
  EXPECT_EQ(tiles[0].last_frame, 31);
  EXPECT_EQ(composer.stats().navigation_jumps, 1);
  EXPECT_NE(composer.stats().last_problem.find("navigation jump"), std::string::npos);
  EXPECT_LT(compose_test::placementError(tiles[0], factory.flight).norm(), 0.05);
  const auto next = composer.flush();
  ASSERT_TRUE(next);
  EXPECT_EQ(next->first_frame, 32);  // starts at the new pose
  const Eigen::Vector2d e = compose_test::placementError(*next, factory.flight);
  EXPECT_NEAR(e.x(), 0.0, 0.05);  // follows the (jumped) navigation
  EXPECT_NEAR(e.y(), 3.0, 0.05);
}

TEST(ComposeClosing, OneOutlyingFixIsNoJump) {
  FrameFactory factory = smallFactory(0.05);
  ec::MosaicComposer composer(smallConfig());
  for (int i = 0; i < 60; ++i) {
    ec::ComposerFrame f = factory.frame(i);
    if (i == 30) f.pose->camera_en_m += Eigen::Vector2d(0.0, 3.0);  // one fix 3 m off, then the navigation is back
    EXPECT_FALSE(composer.add(f)) << "frame " << i;
  }
  EXPECT_EQ(composer.stats().navigation_jumps, 0);
  const auto tile = composer.flush();
  ASSERT_TRUE(tile);
  EXPECT_LT(compose_test::placementError(*tile, factory.flight).norm(), 0.05) << "the outlier is left out of the fit";
}

TEST(ComposeClosing, NoJumpOnNavigationNoise) {
  FrameFactory factory = smallFactory(0.15);
  ec::MosaicComposer composer(smallConfig());
  for (int i = 0; i < 150; ++i) EXPECT_FALSE(composer.add(factory.frame(i))) << "frame " << i;
  EXPECT_EQ(composer.stats().navigation_jumps, 0);
}

TEST(ComposeClosing, RegistrationFailureBridgedByThePose) {
  FrameFactory factory = smallFactory();
  ec::ComposerConfig config = smallConfig();
  config.min_key_frame_shift_fraction = 0.0;  // every image composed: the bridged one is visible
  ec::MosaicComposer composer(config);
  for (int i = 0; i < 40; ++i) EXPECT_FALSE(composer.add(factory.frame(i, /*with_registration=*/i != 15)));
  EXPECT_EQ(composer.stats().registration_fallbacks, 1);
  // An image without registration nor pose: skipped; the next one (registered to it) is bridged by its pose.
  EXPECT_FALSE(composer.add(factory.frame(40, false, false)));
  EXPECT_EQ(composer.stats().frames_skipped_no_chain, 1);
  EXPECT_FALSE(composer.add(factory.frame(41)));
  EXPECT_EQ(composer.stats().registration_fallbacks, 2);
  // Images with registration but no pose continue the chain.
  for (int i = 42; i < 50; ++i) EXPECT_FALSE(composer.add(factory.frame(i, true, false)));
  const auto tile = composer.flush();
  ASSERT_TRUE(tile);
  EXPECT_EQ(tile->frames_added, 49);
  EXPECT_EQ(tile->frames_composed, 49);
  EXPECT_LT(compose_test::placementError(*tile, factory.flight).norm(), 1e-6);
  // Every composed footprint where the truth has it (the bridged ones included).
  for (std::size_t k = 0; k < tile->footprints_en_m.size(); ++k) {
    const int frame = k < 40 ? static_cast<int>(k) : static_cast<int>(k) + 1;
    EXPECT_LT((tile->footprints_en_m[k][2] - factory.flight.footprint(frame)[2]).norm(), 1e-6) << "frame " << frame;
  }
}

TEST(ComposeClosing, ImagesWithoutPoseSkippedUntilOneHasIt) {
  FrameFactory factory = smallFactory();
  ec::MosaicComposer composer(smallConfig());
  for (int i = 0; i < 5; ++i) EXPECT_FALSE(composer.add(factory.frame(i, true, false)));
  EXPECT_EQ(composer.stats().frames_skipped_no_pose, 5);
  EXPECT_TRUE(composer.preview(100).empty());
  for (int i = 5; i < 20; ++i) EXPECT_FALSE(composer.add(factory.frame(i)));
  const cv::Mat preview = composer.preview(100);
  ASSERT_FALSE(preview.empty());
  EXPECT_EQ(preview.type(), CV_8UC3);
  EXPECT_LE(std::max(preview.cols, preview.rows), 100);
  const auto tile = composer.flush();
  ASSERT_TRUE(tile);
  EXPECT_EQ(tile->first_frame, 5);
  EXPECT_EQ(composer.stats().frames_added, 20);
}

TEST(ComposeClosing, LongLineKeepsMemoryBounded) {
  // 2000 images along a diagonal: sparse blocks follow the track, and the memory limit closes mosaics.
  FrameFactory factory = smallFactory();
  factory.flight.step_m = 0.01;
  factory.flight.heading_start_rad = 0.78;  // north-east: the bounding box is mostly empty
  ec::ComposerConfig config = smallConfig();
  config.max_memory_mb = 2.0;
  config.max_extent_m = 1000;
  ec::MosaicComposer composer(config);
  std::size_t peak = 0;
  int closed = 0;
  ec::ClosedMosaic first;
  for (int i = 0; i < 2000; ++i) {
    if (auto t = composer.add(factory.frame(i))) {
      if (closed++ == 0) first = *t;
      EXPECT_EQ(t->close_reason, "memory");
    }
    peak = std::max(peak, composer.stats().open_memory_bytes);
  }
  std::printf("2000 images: %d mosaics closed, open memory peak %.2f MiB (limit 2)\n", closed, peak / 1048576.0);
  EXPECT_GE(closed, 1);
  EXPECT_LT(peak, 2.5 * 1048576);
  // Memory follows the covered area, not the bounding box of the diagonal track.
  ASSERT_FALSE(first.image.empty());
  const double dense_bytes = static_cast<double>(first.image.total()) * 4 * sizeof(float);
  EXPECT_GT(dense_bytes, 1.5 * 2.0 * 1048576);
  std::printf("first tile %dx%d px: dense accumulators would hold %.2f MiB\n", first.image.cols, first.image.rows,
              dense_bytes / 1048576.0);
}
