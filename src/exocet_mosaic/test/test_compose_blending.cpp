// Blending: seams between images of different brightness ("none" shows them, "feather" and "multiband" hide them).
#include <gtest/gtest.h>

#include <cstdio>

#include "compose_fixtures.h"

namespace ec = exocet_mosaic::compose;
using compose_test::FrameFactory;
using compose_test::TruthOrtho;

namespace {

const TruthOrtho& truth() {
  static const TruthOrtho t = TruthOrtho::make(12.0, 8.0, 0.01, 500000.0 - 3.0, 4800000.0 + 4.0);
  return t;
}

struct SeamEnergy {
  double seam = 0, elsewhere = 0;
  double ratio() const { return seam / elsewhere; }
};

// Gradient energy in a band along the composed images' edges vs in the rest of the mosaic's interior.
SeamEnergy seamEnergy(const ec::ClosedMosaic& t, bool on_truth = false) {
  cv::Mat seams(t.image.size(), CV_8U, cv::Scalar(0));
  for (const auto& f : t.footprints_en_m) {
    std::vector<cv::Point> poly;
    for (const auto& p : f)
      poly.emplace_back(static_cast<int>(std::lround((p.x() - t.origin_easting_m) / t.gsd_m - 0.5)),
                        static_cast<int>(std::lround((t.origin_northing_m - p.y()) / t.gsd_m - 0.5)));
    cv::polylines(seams, poly, true, cv::Scalar(255), 3);
  }
  cv::Mat interior, band, rest;
  cv::erode(t.mask, interior, cv::Mat(), cv::Point(-1, -1), 6);
  cv::bitwise_and(seams, interior, band);
  cv::dilate(seams, rest, cv::Mat(), cv::Point(-1, -1), 4);
  cv::bitwise_not(rest, rest);
  cv::bitwise_and(rest, interior, rest);
  cv::Mat grey, gx, gy, energy;
  // on_truth: the same measure on the truth resampled on the tile's grid (what the texture alone gives).
  const cv::Mat source =
      on_truth ? truth().onGrid(t.origin_easting_m, t.origin_northing_m, t.gsd_m, t.image.size()) : t.image;
  cv::cvtColor(source, grey, cv::COLOR_BGR2GRAY);
  cv::Sobel(grey, gx, CV_32F, 1, 0);
  cv::Sobel(grey, gy, CV_32F, 0, 1);
  energy = gx.mul(gx) + gy.mul(gy);
  EXPECT_GT(cv::countNonZero(band), 1000);
  EXPECT_GT(cv::countNonZero(rest), 1000);
  return {cv::mean(energy, band)[0], cv::mean(energy, rest)[0]};
}

ec::ClosedMosaic composeAlternatingBrightness(const std::string& blend) {
  FrameFactory factory;
  factory.truth = &truth();
  factory.flight.image_size = cv::Size(160, 120);
  factory.flight.k = cv::Matx33d(200, 0, 79.5, 0, 200, 59.5, 0, 0, 1);
  factory.flight.step_m = 0.3;
  ec::ComposerConfig config;
  config.lighting.enabled = false;
  config.blend = blend;
  config.min_key_frame_shift_fraction = 0.0;
  config.frames_per_mosaic = 1000;
  ec::MosaicComposer composer(config);
  for (int i = 0; i < 25; ++i) {
    ec::ComposerFrame f = factory.frame(i);
    if (i % 2) f.image.convertTo(f.image, -1, 1.3);  // every other image 30 % brighter
    composer.add(f);
  }
  auto t = composer.flush();
  EXPECT_TRUE(t);
  EXPECT_EQ(t->blend, blend);
  return *t;
}

}  // namespace

TEST(ComposeBlending, NoneShowsSeamsFeatherHidesThem) {
  const ec::ClosedMosaic none_tile = composeAlternatingBrightness("none");
  const SeamEnergy none = seamEnergy(none_tile);
  const SeamEnergy feather = seamEnergy(composeAlternatingBrightness("feather"));
  const SeamEnergy texture = seamEnergy(none_tile, true);
  std::printf("truth texture alone: %.0f / %.0f = %.2f\n", texture.seam, texture.elsewhere, texture.ratio());
  std::printf("gradient energy seam band / elsewhere: none %.0f / %.0f = %.2f, feather %.0f / %.0f = %.2f\n", none.seam,
              none.elsewhere, none.ratio(), feather.seam, feather.elsewhere, feather.ratio());
  // Relative to the texture's own ratio (the checker landmarks make it uneven).
  EXPECT_GT(none.ratio() / texture.ratio(), 1.6);
  EXPECT_LT(feather.ratio() / texture.ratio(), 1.15);
}

TEST(ComposeBlending, MultibandHidesSeams) {
  const ec::ClosedMosaic t = composeAlternatingBrightness("multiband");
  const SeamEnergy multiband = seamEnergy(t);
  const SeamEnergy texture = seamEnergy(t, true);
  std::printf("gradient energy seam band / elsewhere: multiband %.0f / %.0f = %.2f, truth texture %.2f\n",
              multiband.seam, multiband.elsewhere, multiband.ratio(), texture.ratio());
  EXPECT_LT(multiband.ratio() / texture.ratio(), 1.3);
  // And it stays faithful to the truth's texture (same place, no blur): compare with the brightest-agnostic truth.
  const cv::Mat expected = truth().onGrid(t.origin_easting_m, t.origin_northing_m, t.gsd_m, t.image.size());
  cv::Mat inner;
  cv::erode(t.mask, inner, cv::Mat(), cv::Point(-1, -1), 8);
  const cv::Rect r = compose_test::innerRect(inner, 2.0);
  ASSERT_GT(r.width, 60);
  const cv::Point2d shift = compose_test::phaseShift(expected(r), t.image(r));
  EXPECT_LT(std::hypot(shift.x, shift.y), 0.3);
}
