// Placement of the composed mosaics against a rendered truth: exact chain and poses, noisy fused positions, and the
// alignment of consecutive tiles.
#include <gtest/gtest.h>

#include <cstdio>

#include "compose_fixtures.h"

namespace ec = exocet_mosaic::compose;
using compose_test::FrameFactory;
using compose_test::TruthOrtho;

namespace {

ec::ComposerConfig baseConfig() {
  ec::ComposerConfig c;
  c.lighting.enabled = false;  // the rendered frames are evenly lit
  return c;
}

// The flight: about 6 m east with a slow turn; the truth covers it with margin.
FrameFactory makeFactory(const TruthOrtho& truth, double noise_m) {
  FrameFactory f;
  f.truth = &truth;
  f.position_noise_m = noise_m;
  f.flight.turn_rad_per_frame = 0.002;
  return f;
}

/// The same flight with small images (160 x 120, 200 px focal length), for the tests that close many tiles.
FrameFactory makeSmallImageFactory(const TruthOrtho& truth, double noise_m) {
  FrameFactory f = makeFactory(truth, noise_m);
  f.flight.image_size = cv::Size(160, 120);
  f.flight.k = cv::Matx33d(200, 0, 79.5, 0, 200, 59.5, 0, 0, 1);
  return f;
}

const TruthOrtho& truth() {
  static const TruthOrtho t = TruthOrtho::make(11.0, 7.0, 0.005, 500000.0 - 2.0, 4800000.0 + 3.0);
  return t;
}

}  // namespace

TEST(ComposePlacement, ExactPosesExactChainMatchTheTruth) {
  FrameFactory factory = makeFactory(truth(), 0.0);
  ec::ComposerConfig config = baseConfig();
  config.frames_per_mosaic = 1000;
  ec::MosaicComposer composer(config);
  for (int i = 0; i < 120; ++i) ASSERT_FALSE(composer.add(factory.frame(i)));
  const auto tile = composer.flush();
  ASSERT_TRUE(tile);
  EXPECT_EQ(tile->close_reason, "flush");
  EXPECT_DOUBLE_EQ(tile->gsd_m, 0.005);  // 2.2 m / 400 px rounded down
  EXPECT_EQ(tile->frames_added, 120);
  EXPECT_GT(tile->frames_composed, 5);
  EXPECT_LT(tile->frames_composed, 60);  // key frames only
  EXPECT_FALSE(tile->resampled);
  EXPECT_LT(tile->anchor_correction_m.norm(), 1e-6);
  // Origin on the truth's terms: compare the mosaic with the truth resampled on the mosaic's grid.
  const cv::Mat expected =
      truth().onGrid(tile->origin_easting_m, tile->origin_northing_m, tile->gsd_m, tile->image.size());
  cv::Mat inner;
  cv::erode(tile->mask, inner, cv::Mat(), cv::Point(-1, -1), 3);
  const double mae = compose_test::meanAbsError(tile->image, expected, inner);
  const cv::Rect r = compose_test::innerRect(inner, 1.5);
  ASSERT_GT(r.width, 100);
  const cv::Point2d shift = compose_test::phaseShift(expected(r), tile->image(r));
  std::printf("exact: %dx%d px, mean abs error %.2f grey, offset (%.3f, %.3f) px over %dx%d\n", tile->image.cols,
              tile->image.rows, mae, shift.x, shift.y, r.width, r.height);
  EXPECT_LT(mae, 4.0);
  EXPECT_LT(std::hypot(shift.x, shift.y), 0.2);
  // Footprints reported in UTM agree with the truth.
  EXPECT_LT(compose_test::placementError(*tile, factory.flight).norm(), 1e-6);
}

TEST(ComposePlacement, NoisyPositionsAverageOutAndSigmaIsConsistent) {
  // Small images for speed; the navigation noise is independent per image here (a worst case for the fit's
  // assumptions would be correlated noise).
  FrameFactory factory = makeSmallImageFactory(truth(), 0.1);
  ec::ComposerConfig config = baseConfig();
  config.frames_per_mosaic = 50;
  // Independent tiles: each tile's fit against its own navigation (the continuity tie, tested below, makes tiles
  // follow each other and their reported sigma conservative).
  config.tile_continuity_sigma_m = 1000.0;
  ec::MosaicComposer composer(config);
  std::vector<ec::ClosedMosaic> tiles;
  for (int i = 0; i < 300; ++i)
    if (auto t = composer.add(factory.frame(i))) tiles.push_back(*t);
  ASSERT_GE(tiles.size(), 5u);
  double sum_e2 = 0, sum_s2 = 0, max_e = 0;
  for (const auto& t : tiles) {
    EXPECT_EQ(t.close_reason, "frames");
    const Eigen::Vector2d e = compose_test::placementError(t, factory.flight);
    std::printf("tile %d-%d: error (%.4f, %.4f) m, anchor_sigma %.4f m, correction (%.3f, %.3f) m%s\n", t.first_frame,
                t.last_frame, e.x(), e.y(), t.anchor_sigma_m, t.anchor_correction_m.x(), t.anchor_correction_m.y(),
                t.resampled ? ", resampled" : "");
    sum_e2 += e.squaredNorm() / 2.0;  // per axis
    sum_s2 += t.anchor_sigma_m * t.anchor_sigma_m;
    max_e = std::max(max_e, e.norm());
  }
  const double rms_e = std::sqrt(sum_e2 / tiles.size()), rms_s = std::sqrt(sum_s2 / tiles.size());
  std::printf("per-axis placement error RMS %.4f m, anchor_sigma RMS %.4f m (navigation sigma 0.1 m)\n", rms_e, rms_s);
  EXPECT_LT(max_e, 0.04);  // << 0.1 m: averaged over the tile's images
  // The composer counts a tile's fused positions as 4 independent ones (a filter's errors are correlated over many
  // images): its sigma is the fused one / 2, conservative for this white noise.
  EXPECT_NEAR(rms_s, 0.05, 0.005);
  EXPECT_LT(rms_e, rms_s);
}

TEST(ComposePlacement, CorrelatedNavigationErrorsDoNotMoveTheSharedImage) {
  // A filter's fused positions are off by an error that wanders over seconds (here up to 6 cm, changing by 1-4 cm
  // between tiles), not by independent noise. The shared image of consecutive tiles must stay where the closed tile
  // put it (the tie), not follow the navigation's disagreement with the chain: the tiles would show a seam.
  FrameFactory factory = makeSmallImageFactory(truth(), 0.0);
  ec::ComposerConfig config = baseConfig();
  config.frames_per_mosaic = 50;
  ec::MosaicComposer composer(config);
  const double sigma_m = 0.05;  // the filter's 1-sigma, as it reports it
  std::vector<ec::ClosedMosaic> tiles;
  for (int i = 0; i < 300; ++i) {
    ec::ComposerFrame f = factory.frame(i);
    f.pose->camera_en_m += Eigen::Vector2d(0.04 * std::sin(i / 35.0), 0.03 * std::cos(i / 50.0) - 0.03);
    f.pose->position_cov_m2 = Eigen::Matrix2d::Identity() * sigma_m * sigma_m;
    if (auto t = composer.add(f)) tiles.push_back(*t);
  }
  ASSERT_GE(tiles.size(), 5u);
  const double g = tiles.front().gsd_m;
  for (std::size_t k = 1; k < tiles.size(); ++k) {
    const auto& a = tiles[k - 1];
    const auto& b = tiles[k];
    ASSERT_EQ(b.first_frame, a.last_frame);
    // The shared image is the closed tile's last composed image and the next tile's first.
    const auto& fa = a.footprints_en_m.back();
    const auto& fb = b.footprints_en_m.front();
    Eigen::Vector2d mean = Eigen::Vector2d::Zero();
    double worst = 0;
    for (int c = 0; c < 4; ++c) {
      mean += (fb[c] - fa[c]) / 4.0;
      worst = std::max(worst, (fb[c] - fa[c]).norm());
    }
    const Eigen::Vector2d e = compose_test::placementError(b, factory.flight);
    std::printf(
        "tiles %zu/%zu: shared image moved by (%.2f, %.2f) px, corners up to %.2f px; tile %zu placed (%.4f, "
        "%.4f) m from the truth\n",
        k - 1, k, mean.x() / g, mean.y() / g, worst / g, k, e.x(), e.y());
    // The navigation disagrees with the chain by 2-6 cm (4-12 px) here; the tie lets it move the image a few %.
    EXPECT_LT(mean.norm(), 0.4 * g) << "tiles " << k - 1 << " and " << k;
    EXPECT_LT(worst, 0.6 * g) << "tiles " << k - 1 << " and " << k;
    EXPECT_LT(e.norm(), 0.03);  // the exact chain from the first tile (nav error 1 cm there)
  }
}

TEST(ComposePlacement, ConsecutiveTilesOverlapAndAlign) {
  FrameFactory factory = makeFactory(truth(), 0.1);
  ec::ComposerConfig config = baseConfig();
  config.frames_per_mosaic = 60;
  ec::MosaicComposer composer(config);
  std::vector<ec::ClosedMosaic> tiles;
  for (int i = 0; i < 190; ++i)
    if (auto t = composer.add(factory.frame(i))) tiles.push_back(*t);
  ASSERT_GE(tiles.size(), 3u);
  for (std::size_t k = 1; k < tiles.size(); ++k) {
    const auto& a = tiles[k - 1];
    const auto& b = tiles[k];
    EXPECT_EQ(b.first_frame, a.last_frame);  // one shared image
    ASSERT_DOUBLE_EQ(a.gsd_m, b.gsd_m);
    const double g = a.gsd_m;
    // b on a's grid: a's pixel (c, r) = b's pixel (c - dx, r - dy).
    const double dx = (b.origin_easting_m - a.origin_easting_m) / g;
    const double dy = (a.origin_northing_m - b.origin_northing_m) / g;
    const cv::Matx23d m(1, 0, -dx, 0, 1, -dy);
    cv::Mat b_on_a, b_mask_on_a;
    cv::warpAffine(b.image, b_on_a, m, a.image.size(), cv::INTER_LINEAR | cv::WARP_INVERSE_MAP);
    cv::warpAffine(b.mask, b_mask_on_a, m, a.image.size(), cv::INTER_NEAREST | cv::WARP_INVERSE_MAP);
    cv::Mat both;
    cv::bitwise_and(a.mask, b_mask_on_a, both);
    cv::erode(both, both, cv::Mat(), cv::Point(-1, -1), 3);
    const cv::Rect r = compose_test::innerRect(both, 1.3);
    ASSERT_GT(r.width, 60) << "overlap of tiles " << k - 1 << " and " << k;
    const cv::Point2d shift = compose_test::phaseShift(a.image(r), b_on_a(r));
    std::printf("tiles %zu/%zu: overlap window %dx%d px, misalignment (%.3f, %.3f) px\n", k - 1, k, r.width, r.height,
                shift.x, shift.y);
    EXPECT_LT(std::hypot(shift.x, shift.y), 1.0);
  }
}

/// The frame as a compressed stream gives it: shape announced, pixels decoded (counted in *loads) only on demand.
ec::ComposerFrame deferredFrame(const ec::ComposerFrame& frame, int* loads) {
  ec::ComposerFrame deferred = frame;
  deferred.image = cv::Mat();
  deferred.image_size = frame.image.size();
  deferred.image_channels = frame.image.channels();
  deferred.load_image = [image = frame.image, loads](int) {
    ++*loads;
    return image.clone();
  };
  return deferred;
}

TEST(ComposePlacement, LazyImagesGiveTheSameTileAndOnlyTheDrawnOnesAreDecoded) {
  // A compressed stream's images are decoded only for the frames the composer draws: same tile, fewer decodes.
  FrameFactory factory = makeFactory(truth(), 0.0);
  ec::ComposerConfig config = baseConfig();
  config.lighting.enabled = true;  // samples one image in sample_interval_frames: those are decoded too
  config.frames_per_mosaic = 50;
  ec::MosaicComposer eager(config), lazy(config);
  int loads = 0;
  std::vector<ec::ClosedMosaic> eager_tiles, lazy_tiles;
  for (int i = 0; i < 120; ++i) {
    const ec::ComposerFrame frame = factory.frame(i);
    if (auto t = eager.add(frame)) eager_tiles.push_back(*t);
    const ec::ComposerFrame deferred = deferredFrame(frame, &loads);
    if (auto t = lazy.add(deferred)) lazy_tiles.push_back(*t);
  }
  if (auto t = eager.flush()) eager_tiles.push_back(*t);
  if (auto t = lazy.flush()) lazy_tiles.push_back(*t);
  ASSERT_EQ(eager_tiles.size(), 3u);
  ASSERT_EQ(lazy_tiles.size(), eager_tiles.size());
  for (size_t k = 0; k < eager_tiles.size(); ++k) {
    EXPECT_EQ(lazy_tiles[k].frames_composed, eager_tiles[k].frames_composed);
    EXPECT_DOUBLE_EQ(lazy_tiles[k].origin_easting_m, eager_tiles[k].origin_easting_m);
    ASSERT_EQ(lazy_tiles[k].image.size(), eager_tiles[k].image.size());
    EXPECT_EQ(cv::norm(lazy_tiles[k].image, eager_tiles[k].image, cv::NORM_INF), 0.0);
  }
  int composed = 0;
  for (const auto& t : eager_tiles) composed += t.frames_composed;
  std::printf("lazy images: %d decodes for 120 frames, %d drawn\n", loads, composed);
  EXPECT_LT(loads, 120 / 2);
  EXPECT_LE(loads, composed + 120 / config.lighting.sample_interval_frames + 1);
}

TEST(ComposePlacement, TheLightingFieldObservesTheKeyFramesWithoutDecodingMore) {
  // Key frames are decoded to be drawn: the lighting field observes them, and no image is decoded for the field alone
  // while key frames come more often than sample_interval_frames.
  FrameFactory factory = makeFactory(truth(), 0.0);
  ec::ComposerConfig config = baseConfig();
  config.lighting.enabled = true;
  config.lighting.sample_interval_frames = 25;
  config.frames_per_mosaic = 1000;  // one mosaic: no image is drawn twice
  ec::MosaicComposer lazy(config);
  int loads = 0;
  std::vector<ec::ClosedMosaic> tiles;
  for (int i = 0; i < 120; ++i) {
    const ec::ComposerFrame frame = factory.frame(i);
    const ec::ComposerFrame deferred = deferredFrame(frame, &loads);
    if (auto t = lazy.add(deferred)) tiles.push_back(*t);
  }
  if (auto t = lazy.flush()) tiles.push_back(*t);
  ASSERT_EQ(tiles.size(), 1u);
  const int composed = tiles[0].frames_composed;
  const int observed = lazy.lighting().framesUsed() + lazy.lighting().framesRejected();
  std::printf("lighting: %d decodes, %d drawn, %d observed by the field\n", loads, composed, observed);
  ASSERT_GT(composed, 120 / 25 + 2);  // key frames come more often than the interval
  EXPECT_EQ(loads, composed);         // every decode is drawn
  EXPECT_GE(observed, composed - 1);  // and observed (but the last, drawn when the mosaic is flushed)
}

TEST(ComposePlacement, AnImageThatCannotBeLoadedIsSkippedAndSaid) {
  FrameFactory factory = makeFactory(truth(), 0.0);
  ec::ComposerConfig config = baseConfig();
  config.min_key_frame_shift_fraction = 0.0;  // every image is drawn, so every loader is called
  ec::MosaicComposer composer(config);
  for (int i = 0; i < 30; ++i) {
    ec::ComposerFrame frame = factory.frame(i);
    const cv::Mat image = frame.image;
    frame.image = cv::Mat();
    frame.image_size = image.size();
    frame.image_channels = image.channels();
    if (i == 10) {
      frame.load_image = [](int) -> cv::Mat { throw std::invalid_argument("corrupt JPEG"); };
    } else if (i == 20) {
      frame.load_image = [image](int) { return image(cv::Rect(0, 0, 100, 100)).clone(); };  // not the announced size
    } else {
      frame.load_image = [image](int) { return image; };
    }
    composer.add(frame);
    if (i == 10) {
      EXPECT_NE(composer.stats().last_problem.find("corrupt JPEG"), std::string::npos);
    }
    if (i == 20) {
      EXPECT_NE(composer.stats().last_problem.find("announced"), std::string::npos);
    }
  }
  const auto tile = composer.flush();
  ASSERT_TRUE(tile);
  EXPECT_EQ(tile->frames_composed, 28);
}
