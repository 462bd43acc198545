// Throughput of the composer on 720x576 images at 25 fps with the default configuration (printed, not asserted):
// key-frame composition time and overall frames per second (rendering of the frames excluded).
#include <gtest/gtest.h>

#include <chrono>
#include <cstdio>

#include "compose_fixtures.h"

namespace ec = exocet_mosaic::compose;

TEST(ComposeThroughput, Pal25FpsDefaultConfig) {
  const compose_test::TruthOrtho truth =
      compose_test::TruthOrtho::make(8.0, 5.0, 0.004, 500000.0 - 2.0, 4800000.0 + 2.5);
  compose_test::FrameFactory factory;
  factory.truth = &truth;
  factory.flight.image_size = cv::Size(720, 576);
  factory.flight.k = cv::Matx33d(620, 0, 359.5, 0, 620, 287.5, 0, 0, 1);  // ~60 deg horizontal field of view
  factory.flight.height_m = 2.5;
  factory.flight.step_m = 0.3 / 25;  // 0.3 m/s at 25 fps
  factory.flight.yaw_rate_rad = 0.0005;
  factory.position_noise_m = 0.1;
  const int n = 250;  // 10 s
  std::vector<ec::ComposerFrame> frames;
  for (int i = 0; i < n; ++i) frames.push_back(factory.frame(i));
  ec::ComposerConfig config;  // defaults: feather, key frames at 10 % shift, lighting on
  ec::MosaicComposer composer(config);
  double total_ms = 0, key_ms = 0, max_ms = 0;
  int keys = 0, tiles = 0;
  for (const auto& f : frames) {
    const auto composed_before = composer.stats().frames_composed;
    const auto t0 = std::chrono::steady_clock::now();
    if (composer.add(f)) ++tiles;
    const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    total_ms += ms;
    max_ms = std::max(max_ms, ms);
    if (composer.stats().frames_composed > composed_before) {
      key_ms += ms;
      ++keys;
    }
  }
  const auto t0 = std::chrono::steady_clock::now();
  const auto last = composer.flush();
  const double close_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  ASSERT_TRUE(last);
  std::printf(
      "720x576 @25 fps, defaults (gsd %.3f m): %d images, %d composed (%.1f ms each incl. skip costs), "
      "%.2f ms per skipped image, overall %.0f frames/s, worst %.1f ms, close %.1f ms (%dx%d px), %d tiles\n",
      last->gsd_m, n, keys, keys ? key_ms / keys : 0.0, (total_ms - key_ms) / std::max(1, n - keys),
      1000.0 * n / total_ms, max_ms, close_ms, last->image.cols, last->image.rows, tiles + 1);
  EXPECT_GT(keys, 3);
  EXPECT_LT(keys, n / 3);
}
