// Gains of many images solved over their overlaps (compose::ImageGains) and the lighting's gain over blocks
// (LightingCorrector::gainGrid): images cut from one synthetic seabed with known gains.
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <numeric>
#include <string>
#include <vector>

#include "compose_fixtures.h"
#include "exocet_mosaic/compose/image_gains.h"
#include "exocet_mosaic/compose/lighting_corrector.h"

namespace ec = exocet_mosaic::compose;

namespace {

constexpr double kGsd = 0.01;
constexpr int kWidth = 320, kHeight = 240;

struct Scene {
  compose_test::TruthOrtho truth = compose_test::TruthOrtho::make(12.0, 6.0, kGsd, 500000.0, 4800006.0, 11);
  ec::ImageGains gains;
  std::map<std::string, ec::ImagePlacement> placements;
  std::map<std::string, double> true_gain;

  /// An image whose top-left pixel is the seabed's (x, y), darkened or brightened by `gain`, with noise.
  void addImage(const std::string& id, int x, int y, double gain) {
    cv::Mat crop;
    truth.image(cv::Rect(x, y, kWidth, kHeight)).convertTo(crop, CV_32FC3, 0.8 * gain);
    cv::Mat noise(crop.size(), CV_32FC3);
    cv::randn(noise, 0.0, 3.0);
    crop += noise;
    cv::Mat image;
    crop.convertTo(image, CV_8UC3);
    ASSERT_TRUE(gains.add(id, ec::imageLevels(image, gains.config().grid_columns, gains.config().grid_rows)));
    ec::ImagePlacement p;
    p.en_from_px = cv::Matx33d(kGsd, 0, truth.origin_e_m + x * kGsd, 0, -kGsd, truth.origin_n_m - y * kGsd, 0, 0, 1);
    placements[id] = p;
    true_gain[id] = gain;
  }
};

double meanGain(const ec::ImageGainSolution& s, const std::string& prefix, int channel) {
  double sum = 0;
  int n = 0;
  for (const auto& [id, g] : s.gain)
    if (id.rfind(prefix, 0) == 0) {
      sum += g[channel];
      ++n;
    }
  return n > 0 ? sum / n : NAN;
}

}  // namespace

TEST(ImageGains, TwoPassesLitDifferentlyAreMatchedOverTheirOverlap) {
  Scene scene;
  // Two passes along the seabed, overlapping by a third of an image; the second lit at 0.8; one image far away.
  for (int i = 0; i < 8; ++i) scene.addImage("a" + std::to_string(i), 60 + 100 * i, 20, 1.0);
  for (int i = 0; i < 8; ++i) scene.addImage("b" + std::to_string(i), 60 + 100 * i, 180, 0.8);
  scene.addImage("lone", 60, 20, 1.0);
  scene.placements["lone"].en_from_px(0, 2) += 50.0;  // 50 m east: overlaps nothing
  const ec::ImageGainSolution s = scene.gains.solve(scene.placements);
  ASSERT_TRUE(s.problem.empty()) << s.problem;
  EXPECT_EQ(s.images, 17);
  EXPECT_EQ(s.gain.count("lone"), 0u);  // no overlap: no gain (1)
  for (int c = 0; c < 3; ++c) {
    // What matters is the ratio between the passes (the prior, weighed by each image's overlaps as in Brown & Lowe,
    // takes a little of it back); the prior on log g shares it evenly between them.
    EXPECT_NEAR(meanGain(s, "b", c) / meanGain(s, "a", c), 1.25, 0.03) << "channel " << c;
    EXPECT_NEAR(meanGain(s, "b", c) * meanGain(s, "a", c), 1.0, 0.01) << "channel " << c;
    for (const auto& [id, g] : s.gain)  // images of one pass agree with each other
      EXPECT_NEAR(g[c], meanGain(s, id.substr(0, 1), c), 0.01) << id;
  }
  EXPECT_GT(s.step_before_grey, 15.0);
  EXPECT_LT(s.step_after_grey, 0.25 * s.step_before_grey);
}

TEST(ImageGains, ImagesWithFixedGainsAnchorTheOthersAsASolveOfAllWould) {
  Scene scene;
  for (int i = 0; i < 8; ++i) scene.addImage("a" + std::to_string(i), 60 + 100 * i, 20, 1.0);
  for (int i = 0; i < 8; ++i) scene.addImage("b" + std::to_string(i), 60 + 100 * i, 180, 0.8);
  const ec::ImageGainSolution all = scene.gains.solve(scene.placements);
  ASSERT_TRUE(all.problem.empty()) << all.problem;

  // The first pass fixed at the values of the solve of all: the second gets the same values (same least squares).
  std::map<std::string, std::array<double, 3>> fixed;
  for (int i = 0; i < 8; ++i) fixed["a" + std::to_string(i)] = all.gain.at("a" + std::to_string(i));
  const ec::ImageGainSolution anchored = scene.gains.solve(scene.placements, fixed);
  ASSERT_TRUE(anchored.problem.empty()) << anchored.problem;
  EXPECT_EQ(anchored.images, 16);
  EXPECT_EQ(anchored.fixed_images, 8);
  EXPECT_EQ(anchored.gain.size(), 8u);  // the fixed ones are not in the solution
  for (int i = 0; i < 8; ++i) {
    const std::string id = "b" + std::to_string(i);
    ASSERT_EQ(anchored.gain.count(id), 1u) << id;
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(anchored.gain.at(id)[c], all.gain.at(id)[c], 1e-6) << id << " " << c;
  }

  // Fixed at 1: the second pass takes most of the ratio 1.25 (the prior, weighed by all of its overlaps, the ones
  // along its own pass included, keeps it nearer 1: 1.20 here).
  for (auto& [id, g] : fixed) g = {1.0, 1.0, 1.0};
  const ec::ImageGainSolution to_one = scene.gains.solve(scene.placements, fixed);
  ASSERT_TRUE(to_one.problem.empty()) << to_one.problem;
  for (int c = 0; c < 3; ++c) {
    EXPECT_GT(meanGain(to_one, "b", c), 1.15) << "channel " << c;
    EXPECT_LT(meanGain(to_one, "b", c), 1.25) << "channel " << c;
  }
  EXPECT_LT(to_one.step_after_grey, 0.25 * to_one.step_before_grey);

  // Every image fixed: nothing to solve, said so.
  for (int i = 0; i < 8; ++i) fixed["b" + std::to_string(i)] = {1.0, 1.0, 1.0};
  const ec::ImageGainSolution none = scene.gains.solve(scene.placements, fixed);
  EXPECT_FALSE(none.problem.empty());
  EXPECT_TRUE(none.gain.empty());
}

TEST(ImageGains, TheLightingGainOfEachBlockIsAppliedBeforeMatching) {
  Scene scene;
  for (int i = 0; i < 6; ++i) scene.addImage("a" + std::to_string(i), 60 + 100 * i, 20, 1.0);
  for (int i = 0; i < 6; ++i) scene.addImage("b" + std::to_string(i), 60 + 100 * i, 180, 0.8);
  // The second pass's darkness is the lighting's to correct (a lamp field of 1.25 there): nothing left for the gains.
  const auto& config = scene.gains.config();
  for (auto& [id, p] : scene.placements)
    p.block_gain = cv::Mat(config.grid_rows, config.grid_columns, CV_32FC3, cv::Scalar::all(id[0] == 'b' ? 1.25 : 1.0));
  const ec::ImageGainSolution s = scene.gains.solve(scene.placements);
  ASSERT_TRUE(s.problem.empty()) << s.problem;
  for (const auto& [id, g] : s.gain)
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(g[c], 1.0, 0.015) << id << " channel " << c;
}

TEST(ImageGains, ALongLineWithoutCrossingsStaysNearOne) {
  // 60 images along one line, each overlapping the next by 3/4: ratio noise along the chain must not add up into a
  // drift of the gains (the prior weighs like the overlaps).
  compose_test::TruthOrtho wide = compose_test::TruthOrtho::make(22.0, 3.0, kGsd, 500000.0, 4800003.0, 21);
  Scene scene;
  scene.truth = wide;
  for (int i = 0; i < 60; ++i) scene.addImage("l" + std::to_string(i), 30 + 30 * i, 20, 1.0);
  const ec::ImageGainSolution s = scene.gains.solve(scene.placements);
  ASSERT_TRUE(s.problem.empty()) << s.problem;
  ASSERT_EQ(s.gain.size(), 60u);
  for (const auto& [id, g] : s.gain)
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(g[c], 1.0, 0.02) << id << " channel " << c;
}

TEST(ImageGains, RefusesLevelsItCannotCompareAndNamesBadSettings) {
  ec::ImageGains gains;
  const cv::Mat colour(240, 320, CV_8UC3, cv::Scalar(90, 100, 110)), grey(240, 320, CV_8UC1, cv::Scalar(100));
  EXPECT_TRUE(gains.add("c", ec::imageLevels(colour, 16, 12)));
  EXPECT_FALSE(gains.add("g", ec::imageLevels(grey, 16, 12)));  // another channel count than the first
  EXPECT_FALSE(gains.add("s", ec::imageLevels(colour, 8, 6)));  // another grid
  EXPECT_EQ(gains.size(), 1u);
  EXPECT_THROW(ec::imageLevels(cv::Mat(), 16, 12), std::invalid_argument);
  EXPECT_THROW(ec::imageLevels(cv::Mat(10, 10, CV_32F), 4, 4), std::invalid_argument);
  const ec::ImageLevels levels = ec::imageLevels(colour, 16, 12);
  EXPECT_NEAR(levels.block_mean.at<cv::Vec3f>(5, 7)[2], 110.0, 1e-3);
  std::map<std::string, ec::ImagePlacement> one{{"c", ec::ImagePlacement()}};
  EXPECT_FALSE(gains.solve(one).problem.empty());  // one image: nothing to solve
  ec::ImageGainsConfig bad;
  bad.gain_sigma = 0.0;
  bad.grid_rows = 1;
  try {
    ec::ImageGains refused(bad);
    FAIL() << "a bad config was accepted";
  } catch (const std::invalid_argument& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("gain_sigma = 0 outside (0, 10]"), std::string::npos) << what;
    EXPECT_NE(what.find("grid_rows = 1 outside [2, 256]"), std::string::npos) << what;
  }
}

TEST(LightingCorrector, TheGainOverBlocksIsWhatCorrectAppliesThere) {
  ec::LightingConfig config;
  config.warmup_frames = 3;
  ec::LightingCorrector lighting(config);
  cv::Mat lit(120, 160, CV_8UC3);
  for (int c = 0; c < lit.cols; ++c) lit.col(c).setTo(cv::Scalar(40 + c, 60 + c / 2, 80));  // a lamp to the east
  for (int i = 0; i < 5; ++i) lighting.observe(lit);
  ASSERT_TRUE(lighting.ready());
  EXPECT_TRUE(lighting.gainGrid(cv::Size(100, 100), cv::Size(8, 6)).empty());  // another image size
  const cv::Mat grid = lighting.gainGrid(lit.size(), cv::Size(8, 6));
  ASSERT_EQ(grid.size(), cv::Size(8, 6));
  ASSERT_EQ(grid.type(), CV_32FC3);
  // correct() on a flat image of 50 (gains up to max_gain 4: no saturation): its block means over 50 are the gains.
  const cv::Mat flat(lit.size(), CV_8UC3, cv::Scalar::all(50));
  cv::Mat corrected;
  lighting.correct(flat).convertTo(corrected, CV_32FC3, 0.02);
  cv::Mat block_means;
  cv::resize(corrected, block_means, cv::Size(8, 6), 0, 0, cv::INTER_AREA);
  for (int r = 0; r < 6; ++r)
    for (int c = 0; c < 8; ++c)
      for (int k = 0; k < 3; ++k)
        EXPECT_NEAR(grid.at<cv::Vec3f>(r, c)[k], block_means.at<cv::Vec3f>(r, c)[k],
                    0.02 * block_means.at<cv::Vec3f>(r, c)[k] + 0.01)
            << r << "," << c << " channel " << k;
}
