// Lighting correction: frames lit by a known lamp cone; the corrector estimates it from the images and divides it out.
#include <gtest/gtest.h>

#include <cstdio>

#include "compose_fixtures.h"
#include "exocet_mosaic/compose/lighting_corrector.h"

namespace ec = exocet_mosaic::compose;
using compose_test::FrameFactory;
using compose_test::TruthOrtho;

namespace {

const TruthOrtho& truth() {
  static const TruthOrtho t = TruthOrtho::make(16.0, 8.0, 0.01, 500000.0 - 3.0, 4800000.0 + 4.0);
  return t;
}

// Lamp cone off-centre with vignetting: 1 at its peak, 0.3 far out.
cv::Mat coneField(const cv::Size& size) {
  cv::Mat v(size, CV_32F);
  const double cx = 0.55 * size.width, cy = 0.45 * size.height, s = 0.4 * size.width;
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) {
      const double r2 = (x - cx) * (x - cx) + (y - cy) * (y - cy);
      v.at<float>(y, x) = static_cast<float>(0.3 + 0.7 * std::exp(-r2 / (2 * s * s)));
    }
  return v;
}

cv::Mat applyField(const cv::Mat& image, const cv::Mat& field) {
  cv::Mat f3, img_f, out;
  cv::merge(std::vector<cv::Mat>{field, field, field}, f3);
  image.convertTo(img_f, CV_32F);
  cv::multiply(img_f, f3, img_f);
  img_f.convertTo(out, CV_8U);
  return out;
}

FrameFactory factory() {
  FrameFactory f;
  f.truth = &truth();
  f.flight.image_size = cv::Size(160, 120);
  f.flight.k = cv::Matx33d(200, 0, 79.5, 0, 200, 59.5, 0, 0, 1);
  f.flight.step_m = 0.04;
  f.flight.yaw_rate_rad = 0.01;
  return f;
}

struct LightingRun {
  double mae_second_tile = 0;
  cv::Mat field;
  int rejected = 0;
  bool ready = false;
};

LightingRun runLighting(bool lighting, bool dark_frames) {
  FrameFactory fac = factory();
  const cv::Mat cone = coneField(fac.flight.image_size);
  ec::ComposerConfig config;
  config.lighting.enabled = lighting;
  config.lighting.warmup_frames = 30;
  config.lighting.sample_interval_frames = 1;  // every image: the dark ones are all seen
  config.frames_per_mosaic = 150;
  ec::MosaicComposer composer(config);
  std::vector<ec::ClosedMosaic> tiles;
  for (int i = 0; i < 300; ++i) {
    ec::ComposerFrame f = fac.frame(i);
    f.image = applyField(f.image, cone);
    if (dark_frames && i % 10 == 5) f.image = f.image * 0.1;  // lamps flicker off
    if (auto t = composer.add(f)) tiles.push_back(*t);
  }
  EXPECT_GE(tiles.size(), 1u);
  LightingRun r;
  if (tiles.empty()) return r;
  const auto& t = tiles.back();
  const cv::Mat expected = truth().onGrid(t.origin_easting_m, t.origin_northing_m, t.gsd_m, t.image.size());
  cv::Mat inner;
  cv::erode(t.mask, inner, cv::Mat(), cv::Point(-1, -1), 3);
  r.mae_second_tile = compose_test::meanAbsError(t.image, expected, inner);
  r.field = composer.lighting().fieldAt(fac.flight.image_size);
  r.rejected = composer.lighting().framesRejected();
  r.ready = composer.stats().lighting_ready;
  return r;
}

}  // namespace

TEST(ComposeLighting, CorrectedMosaicCloserToTruthAndFieldEstimated) {
  const LightingRun off = runLighting(false, false);
  const LightingRun on = runLighting(true, true);
  std::printf("mean abs error vs truth: uncorrected %.2f, corrected %.2f grey (%d dark frames rejected)\n",
              off.mae_second_tile, on.mae_second_tile, on.rejected);
  EXPECT_TRUE(on.ready);
  EXPECT_LT(on.mae_second_tile, 0.4 * off.mae_second_tile);
  EXPECT_EQ(on.rejected, 30);
  // The estimated field, normalised, against the true cone (normalised).
  const cv::Mat cone = coneField(factory().flight.image_size);
  std::vector<cv::Mat> planes;
  cv::split(on.field, planes);
  double worst = 0, sum = 0;
  for (const auto& p : planes) {
    cv::Mat ratio;
    cv::divide(p, cone, ratio);
    ratio /= cv::mean(ratio)[0];
    double lo, hi;  // worst inside a 10 % margin (the low-pass flattens the field's slope at the very edges)
    const cv::Rect inner(ratio.cols / 10, ratio.rows / 10, ratio.cols * 8 / 10, ratio.rows * 8 / 10);
    cv::minMaxLoc(ratio(inner), &lo, &hi);
    worst = std::max(worst, std::max(hi - 1.0, 1.0 - lo));
    cv::Mat dev = cv::abs(ratio - 1.0);
    sum += cv::mean(dev)[0] / planes.size();
  }
  std::printf("estimated field / true field: mean deviation %.2f %%, worst (inner 80 %%) %.2f %%\n", 100 * sum,
              100 * worst);
  EXPECT_LT(sum, 0.03);
  EXPECT_LT(worst, 0.10);
}

TEST(ComposeLighting, NotReadyBeforeWarmupAndGainsClamped) {
  ec::LightingConfig c;
  c.warmup_frames = 3;
  c.max_gain = 2.0;
  ec::LightingCorrector corrector(c);
  cv::Mat image(60, 80, CV_8UC1, cv::Scalar(100));
  image(cv::Rect(0, 0, 10, 60)).setTo(10);  // a very dark band: its gain would be 10
  EXPECT_FALSE(corrector.ready());
  EXPECT_EQ(corrector.correct(image).data, image.data);  // passthrough
  for (int i = 0; i < 3; ++i) EXPECT_TRUE(corrector.observe(image));
  EXPECT_TRUE(corrector.ready());
  const cv::Mat out = corrector.correct(image);
  EXPECT_LE(out.at<uchar>(30, 0), 21);                                       // clamped to twice
  EXPECT_NEAR(out.at<uchar>(30, 60), 100, 3);                                // the peak keeps its level
  EXPECT_FALSE(corrector.observe(cv::Mat(60, 80, CV_8UC1, cv::Scalar(5))));  // dark frame rejected
  c.max_gain = 0.5;
  EXPECT_THROW(corrector.setConfig(c), std::invalid_argument);
}
