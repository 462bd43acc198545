// Tests of the simulator's seabeds: the procedural texture and relief (determinism whatever the order, cache or
// threads; seamless tiles; levels that agree in the mean; content a feature tracker can lock on; true relief
// bounds; bounded cache) and the georeferenced image seabed (pixels, orientation, pyramid, errors).

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <unistd.h>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "exocet_mosaic/sim/image_seabed.h"
#include "exocet_mosaic/sim/procedural_seabed.h"
#include "exocet_mosaic/sim/random.h"

namespace fs = std::filesystem;
namespace sim = exocet_mosaic::sim;
using sim::ImageSeabed;
using sim::ProceduralRelief;
using sim::ProceduralSeabedConfig;
using sim::ProceduralSeabedTexture;
using sim::WorldRect;

namespace {

/// Restores OpenCV's thread count at the end of a scope.
class ThreadCountGuard {
 public:
  explicit ThreadCountGuard(int threads) : saved_(cv::getNumThreads()) { cv::setNumThreads(threads); }
  ~ThreadCountGuard() { cv::setNumThreads(saved_); }

 private:
  int saved_;
};

bool sameBytes(const cv::Mat& a, const cv::Mat& b) {
  if (a.size() != b.size() || a.type() != b.type()) return false;
  for (int r = 0; r < a.rows; ++r)
    if (std::memcmp(a.ptr(r), b.ptr(r), a.cols * a.elemSize()) != 0) return false;
  return true;
}

bool sameBytes(const cv::Vec3f& a, const cv::Vec3f& b) { return std::memcmp(&a, &b, sizeof(a)) == 0; }

/// Linear albedo -> 8-bit grey with a display gamma, as a camera would deliver it.
cv::Mat toGray8(const cv::Mat_<cv::Vec3f>& linear) {
  cv::Mat gray(linear.size(), CV_8U);
  for (int r = 0; r < linear.rows; ++r)
    for (int c = 0; c < linear.cols; ++c) {
      const cv::Vec3f& v = linear(r, c);
      const float y = std::min(1.f, 1.6f * (0.2126f * v[0] + 0.7152f * v[1] + 0.0722f * v[2]));
      gray.at<uchar>(r, c) = cv::saturate_cast<uchar>(255.f * std::pow(y, 1.f / 2.2f));
    }
  return gray;
}

/// Mean of the texels of `patch` whose centres lie in the square [x0, x0 + size) x [y0, y0 + size).
cv::Mat_<cv::Vec3f> texelsIn(const sim::TexturePatch<cv::Vec3f>& patch, double x0, double y0, double size) {
  const int i0 = static_cast<int>(std::lround((x0 - patch.x0_m) / patch.texel_m + 0.5));
  const int j0 = static_cast<int>(std::lround((y0 - patch.y0_m) / patch.texel_m + 0.5));
  const int n = static_cast<int>(std::lround(size / patch.texel_m));
  return patch.texels(cv::Rect(i0, j0, n, n));
}

// ---------------------------------------------------------------------------------------------------------------
// Procedural texture

TEST(ProceduralSeabedConfig, ValidateNamesEachBadFieldAndItsRange) {
  ProceduralSeabedConfig c;
  EXPECT_EQ(c.validate(), "");
  c.base_texel_m = 0.0;
  EXPECT_NE(c.validate().find("seabed.base_texel_m 0 out of range [0.0005, 0.05]"), std::string::npos) << c.validate();
  c.tile_texels = 100;
  c.ripple_coverage = 1.5;
  const std::string msg = c.validate();
  EXPECT_NE(msg.find("seabed.base_texel_m"), std::string::npos) << msg;
  EXPECT_NE(msg.find("seabed.tile_texels 100"), std::string::npos) << msg;
  EXPECT_NE(msg.find("seabed.ripple_coverage 1.5 out of range [0, 1]"), std::string::npos) << msg;
  EXPECT_THROW(ProceduralSeabedTexture{c}, std::invalid_argument);
  EXPECT_THROW(ProceduralRelief{c}, std::invalid_argument);
  ProceduralSeabedConfig d;
  d.rock_radius_min_m = 0.3;
  d.rock_radius_max_m = 0.2;
  EXPECT_NE(d.validate().find("seabed.rock_radius_max_m"), std::string::npos) << d.validate();
}

TEST(ProceduralSeabedTexture, BadRequestsAreRejected) {
  ProceduralSeabedTexture t(ProceduralSeabedConfig{});
  EXPECT_THROW(t.albedoPatch(-1, {0, 0, 1, 1}), std::out_of_range);
  EXPECT_THROW(t.albedoPatch(t.maxLevel() + 1, {0, 0, 1, 1}), std::out_of_range);
  EXPECT_THROW(t.albedoPatch(0, {0, 0, -1, 1}), std::invalid_argument);
  EXPECT_THROW(t.albedoPatch(0, {0, 0, NAN, 1}), std::invalid_argument);
  EXPECT_THROW(t.albedoPatch(0, {0, 0, 100, 100}), std::invalid_argument);  // 2.5 Gtexels
  EXPECT_EQ(t.tilesGenerated(), 0u);
}

TEST(ProceduralSeabedTexture, SameSeedSameBytesWhateverTheOrderCacheAndThreads) {
  ProceduralSeabedConfig c;
  c.seed = 1234;
  c.rock_density_per_m2 = 5.0;  // plenty of objects across tile edges
  c.shell_density_per_m2 = 60.0;
  const std::vector<std::pair<int, WorldRect>> requests = {
      {0, {0.40, 0.45, 0.62, 0.60}},  // across a level-0 tile corner (0.512 m)
      {1, {-0.7, -0.3, 0.5, 0.4}},    // around the origin, negative tile indices
      {0, {-0.1, -0.05, 0.05, 0.1}},  // the origin's four tiles
      {2, {3.0, -2.0, 5.5, 0.2}},     // several tiles, 8 mm texels
      {3, {-6.0, 10.0, 2.0, 14.0}},   // a wide area, 16 mm texels
      {0, {0.50, 0.50, 0.53, 0.53}},  // a small patch on the first one's corner
  };
  ProceduralSeabedConfig tiny = c;
  tiny.cache_budget_mb = 0.8;  // about one 256^2 tile: every request evicts
  ProceduralSeabedTexture a(tiny), b(c);
  std::vector<cv::Mat> pa, pb(requests.size());
  for (const auto& r : requests) pa.push_back(a.albedoPatch(r.first, r.second).texels.clone());
  {
    const ThreadCountGuard one_thread(1);
    for (size_t k = requests.size(); k-- > 0;)
      pb[k] = b.albedoPatch(requests[k].first, requests[k].second).texels.clone();
  }
  for (size_t k = 0; k < requests.size(); ++k) EXPECT_TRUE(sameBytes(pa[k], pb[k])) << "request " << k;
  // Regenerated after eviction.
  EXPECT_TRUE(sameBytes(a.albedoPatch(requests[0].first, requests[0].second).texels, pa[0]));
  EXPECT_LE(a.cachedBytes(), static_cast<size_t>(0.8 * 1024 * 1024));
  EXPECT_GT(a.tilesGenerated(), b.tilesGenerated());
}

// The renderer samples windows over the cached tiles instead of copied patches: same geometry, same bits, tile
// borders (where a sample's four texels lie in up to four tiles) and the clamped border included; and a window
// keeps its tiles when the cache evicts them.
TEST(ProceduralSeabedTexture, WindowSamplesEqualPatchSamplesBitForBit) {
  ProceduralSeabedConfig c;
  c.seed = 77;
  c.cache_budget_mb = 0.8;  // about one tile: the window's tiles are evicted as it is built
  ProceduralSeabedTexture t(c);
  const WorldRect area{-0.61, 0.37, 0.58, 1.43};  // around tile corners at 0 and 0.512 m, negative indices
  for (const int level : {0, 1, 3}) {
    const sim::TextureWindow<cv::Vec3f> window = t.albedoWindow(level, area);
    const sim::TexturePatch<cv::Vec3f> patch = t.albedoPatch(level, area);
    ASSERT_EQ(window.cols(), patch.texels.cols);
    ASSERT_EQ(window.rows(), patch.texels.rows);
    EXPECT_EQ(window.level(), level);
    EXPECT_EQ(window.texelSize_m(), patch.texel_m);
    for (int j = 0; j < patch.texels.rows; j += 7)
      for (int i = 0; i < patch.texels.cols; i += 5)
        ASSERT_TRUE(sameBytes(window.texel(i, j), patch.texels(j, i)))
            << "level " << level << " texel " << i << ", " << j;
    sim::RandomStream rs(5, level);
    int across_tiles = 0;
    const double tile_m = c.tile_texels * patch.texel_m;
    for (int k = 0; k < 20000; ++k) {
      // Beyond the area too: the clamped border.
      const double x = area.x_min_m - 0.05 + rs.uniform() * (area.x_max_m - area.x_min_m + 0.1);
      const double y = area.y_min_m - 0.05 + rs.uniform() * (area.y_max_m - area.y_min_m + 0.1);
      if (std::abs(x - tile_m * std::round(x / tile_m)) < patch.texel_m) ++across_tiles;
      ASSERT_TRUE(sameBytes(window.sample(x, y), patch.sample(x, y))) << "level " << level << " at " << x << ", " << y;
    }
    EXPECT_GT(across_tiles, 0) << "no sample straddled a tile border at level " << level;
  }
  EXPECT_LE(t.cachedBytes(), static_cast<size_t>(0.8 * 1024 * 1024));
}

TEST(ProceduralSeabedTexture, DifferentSeedsDiffer) {
  ProceduralSeabedConfig c1, c2;
  c1.seed = 1;
  c2.seed = 2;
  ProceduralSeabedTexture a(c1), b(c2);
  const WorldRect area{0.0, 0.0, 1.0, 1.0};
  const cv::Mat pa = a.albedoPatch(1, area).texels, pb = b.albedoPatch(1, area).texels;
  ASSERT_EQ(pa.size(), pb.size());
  EXPECT_GT(cv::norm(pa, pb, cv::NORM_L1) / (pa.total() * 3), 0.02);
}

TEST(ProceduralSeabedTexture, TilesAssembleSeamlessly) {
  ProceduralSeabedConfig c;
  c.seed = 99;
  c.rock_density_per_m2 = 8.0;
  c.shell_density_per_m2 = 150.0;
  ProceduralSeabedTexture t(c);
  for (int level : {0, 2}) {
    const double w = t.baseTexelSize_m() * (1 << level);
    const double edge = 256 * w;  // a tile corner; the origin is another
    for (double corner : {0.0, edge}) {
      const WorldRect area{corner - 24 * w, corner - 20 * w, corner + 22 * w, corner + 26 * w};
      const auto patch = t.albedoPatch(level, area);
      ASSERT_NEAR(patch.texel_m, w, 1e-15);
      int mismatches = 0;
      for (int r = 0; r < patch.texels.rows; ++r)
        for (int col = 0; col < patch.texels.cols; ++col) {
          const double x = patch.x0_m + col * w, y = patch.y0_m + r * w;
          if (!sameBytes(patch.texels(r, col), t.albedoTexel(level, x, y))) ++mismatches;
        }
      EXPECT_EQ(mismatches, 0) << "level " << level << " corner " << corner;
      // Patches lying within one tile hold the same texels as the patch across the corner.
      const auto inside = t.albedoPatch(level, {corner + 2 * w, corner + 2 * w, corner + 10 * w, corner + 10 * w});
      const int di = static_cast<int>(std::lround((inside.x0_m - patch.x0_m) / w));
      const int dj = static_cast<int>(std::lround((inside.y0_m - patch.y0_m) / w));
      EXPECT_TRUE(sameBytes(inside.texels, patch.texels(cv::Rect(di, dj, inside.texels.cols, inside.texels.rows))));
    }
  }
}

TEST(ProceduralSeabedTexture, LevelsAgreeInTheMean) {
  ProceduralSeabedConfig c;
  c.seed = 5;
  c.max_level = 6;
  ProceduralSeabedTexture t(c);
  // A square that is a whole number of texels at every level, so that the levels cover exactly the same ground.
  const double x0 = 1.024, y0 = -2.048, size = 2.048;
  std::vector<cv::Mat_<cv::Vec3f>> levels;
  for (int L = 0; L <= 6; ++L)
    levels.push_back(texelsIn(t.albedoPatch(L, {x0, y0, x0 + size, y0 + size}), x0, y0, size).clone());
  for (int L = 0; L < 6; ++L) {
    const cv::Scalar fine = cv::mean(levels[L]), coarse = cv::mean(levels[L + 1]);
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(coarse[k], fine[k], 0.02 * fine[k]) << "level " << L << " channel " << k;
    // Texel by texel: level L+1 against the 2x2 means of level L, relative to the texture's own contrast.
    cv::Mat_<cv::Vec3f> down;
    cv::resize(levels[L], down, levels[L + 1].size(), 0, 0, cv::INTER_AREA);
    cv::Scalar mean, sd;
    cv::meanStdDev(levels[L + 1].reshape(1), mean, sd);
    const double rms = cv::norm(down, levels[L + 1], cv::NORM_L2) / std::sqrt(down.total() * 3.0);
    EXPECT_LT(rms, 0.35 * sd[0]) << "level " << L;
  }
}

TEST(ProceduralSeabedTexture, ContentSuitsFeatureTracking) {
  ProceduralSeabedTexture t(ProceduralSeabedConfig{});
  const double w = 2 * t.baseTexelSize_m();
  for (const cv::Point2d origin : {cv::Point2d(0.0, 0.0), cv::Point2d(37.0, -12.0), cv::Point2d(-150.0, 80.0)}) {
    const auto patch = t.albedoPatch(1, {origin.x, origin.y, origin.x + 720 * w, origin.y + 576 * w});
    const cv::Mat_<cv::Vec3f> view = patch.texels(cv::Rect(1, 1, 720, 576));
    double lo, hi;
    cv::minMaxLoc(view.reshape(1), &lo, &hi);
    EXPECT_GE(lo, 0.02f);
    EXPECT_LE(hi, 0.9f);
    std::vector<cv::Point2f> corners;
    cv::goodFeaturesToTrack(toGray8(view), corners, 2000, 0.01, 8.0);
    EXPECT_GE(corners.size(), 200u) << "at " << origin;
  }
}

TEST(ProceduralSeabedTexture, CacheStaysWithinBudgetOverALongStrip) {
  ProceduralSeabedConfig c;
  c.tile_texels = 128;      // 4.096 m at level 4 (32 mm texels), 192 KiB
  c.cache_budget_mb = 4.0;  // 20 tiles
  ProceduralSeabedTexture t(c);
  const size_t budget = static_cast<size_t>(4.0 * 1024 * 1024);
  size_t peak = 0;
  // A 10 m wide strip 200 m long, swept by an 8 m x 10 m footprint (3 x 4 tiles).
  for (double x = 0.0; x <= 192.0; x += 2.0) {
    const auto patch = t.albedoPatch(4, {x, -5.0, x + 8.0, 5.0});
    ASSERT_GE(patch.texels.cols, 250);
    peak = std::max(peak, t.cachedBytes());
    ASSERT_LE(t.cachedBytes(), budget);
  }
  EXPECT_GT(peak, budget / 2);
  // Tile columns -1 (the margin) to 48, rows -2 to 1, each generated once: the LRU keeps the footprint and drops
  // what lies behind.
  EXPECT_EQ(t.tilesGenerated(), 200u);
}

// ---------------------------------------------------------------------------------------------------------------
// Procedural relief

ProceduralSeabedConfig roughRelief() {
  ProceduralSeabedConfig c;
  c.seed = 77;
  c.relief_enabled = true;
  c.rock_density_per_m2 = 4.0;
  c.mound_amplitude_m = 0.4;
  c.mound_size_m = 3.0;
  c.regional_slope = 0.05;
  c.regional_slope_extent_m = 20.0;
  c.ripple_coverage = 0.7;
  return c;
}

TEST(ProceduralRelief, DisabledIsFlat) {
  ProceduralRelief r(ProceduralSeabedConfig{});
  EXPECT_TRUE(r.isFlat());
  EXPECT_EQ(r.heightAt_m(1.0, 2.0), 0.0);
  EXPECT_EQ(r.maxHeight_m(), 0.0);
  EXPECT_EQ(r.minHeight_m(), 0.0);
  EXPECT_EQ(r.maxSlope(), 0.0);
  const auto p = r.heightPatch({0, 0, 3, 2});
  EXPECT_EQ(cv::countNonZero(p.texels), 0);
  EXPECT_EQ(p.sample(1.5, 1.0), 0.f);
}

TEST(ProceduralRelief, BoundsAndSlopeBoundHold) {
  ProceduralRelief r(roughRelief());
  ASSERT_FALSE(r.isFlat());
  EXPECT_LE(r.maxSlope(), 1.3);  // ~1 by construction
  // Dense exact samples: 8 m x 8 m at the 1 cm grid, across the regional slope's steep part.
  const auto p = r.heightPatch({15.0, -4.0, 23.0, 4.0});
  double lo, hi;
  cv::minMaxLoc(p.texels, &lo, &hi);
  EXPECT_GE(lo, r.minHeight_m());
  EXPECT_LE(hi, r.maxHeight_m());
  EXPECT_GT(hi - lo, 0.2);
  double local_lo, local_hi;
  r.heightBounds_m({15.0, -4.0, 23.0, 4.0}, &local_lo, &local_hi);
  EXPECT_GE(lo, local_lo);
  EXPECT_LE(hi, local_hi);
  EXPECT_LT(local_hi - local_lo, r.maxHeight_m() - r.minHeight_m() - 1.0);  // the regional slope's 2 m span
  // Mean value theorem: a finite difference never exceeds the bound of the gradient.
  const double g = r.gridSpacing_m();
  double steepest = 0.0;
  for (int j = 0; j + 1 < p.texels.rows; ++j)
    for (int i = 0; i + 1 < p.texels.cols; ++i) {
      const double h = p.texels(j, i);
      steepest = std::max({steepest, std::abs(p.texels(j, i + 1) - h) / g, std::abs(p.texels(j + 1, i) - h) / g,
                           std::abs(p.texels(j + 1, i + 1) - h) / (g * std::sqrt(2.0))});
    }
  EXPECT_LE(steepest, r.maxSlope());
  EXPECT_GT(steepest, 0.3 * r.maxSlope());  // the bound is not absurdly loose
}

TEST(ProceduralRelief, PatchesAgreeWithExactHeights) {
  ProceduralRelief r(roughRelief());
  const WorldRect area{-1.3, 2.1, 1.4, 4.0};
  const auto p = r.heightPatch(area);
  sim::RandomStream rs(3, 4);
  double worst_node = 0.0, worst_point = 0.0;
  for (int k = 0; k < 400; ++k) {
    const int i = 1 + static_cast<int>(rs.uniform() * (p.texels.cols - 2));
    const int j = 1 + static_cast<int>(rs.uniform() * (p.texels.rows - 2));
    const double x = p.x0_m + i * p.texel_m, y = p.y0_m + j * p.texel_m;
    worst_node = std::max(worst_node, std::abs(p.texels(j, i) - r.heightAt_m(x, y)));
    const double px = rs.uniform(area.x_min_m, area.x_max_m), py = rs.uniform(area.y_min_m, area.y_max_m);
    worst_point = std::max(worst_point, std::abs(p.sample(px, py) - r.heightAt_m(px, py)));
  }
  EXPECT_LT(worst_node, 1e-5);    // float storage of the exact value
  EXPECT_LT(worst_point, 0.002);  // bilinear sampling
  EXPECT_GE(r.tilesGenerated(), 1u);
  EXPECT_GT(r.cachedBytes(), 0u);
}

TEST(ProceduralRelief, RocksOfTheAlbedoAreBumps) {
  const ProceduralSeabedConfig c = roughRelief();
  ProceduralRelief relief(c);
  ProceduralSeabedTexture texture(c);
  const auto rocks = sim::proceduralRocks(c, {0.0, 0.0, 10.0, 10.0});
  int checked = 0;
  double rock_lum = 0.0, ground_lum = 0.0;
  for (const auto& rock : rocks) {
    if (rock.height_m < 0.012) continue;  // well above the ripples' 4 mm
    ++checked;
    const double d = 2.0 * rock.radius_m;
    const double around =
        0.25 * (relief.heightAt_m(rock.x_m + d, rock.y_m) + relief.heightAt_m(rock.x_m - d, rock.y_m) +
                relief.heightAt_m(rock.x_m, rock.y_m + d) + relief.heightAt_m(rock.x_m, rock.y_m - d));
    EXPECT_GT(relief.heightAt_m(rock.x_m, rock.y_m) - around, 0.5 * rock.height_m) << rock.x_m << ", " << rock.y_m;
    rock_lum += cv::sum(texture.albedoTexel(0, rock.x_m, rock.y_m))[0];
    ground_lum += cv::sum(texture.albedoTexel(0, rock.x_m + d, rock.y_m + d))[0];
  }
  EXPECT_GE(checked, 20);
  EXPECT_LT(rock_lum, 0.8 * ground_lum);  // rocks are darker than the sediment around them
}

// ---------------------------------------------------------------------------------------------------------------
// Image seabed

class ImageSeabedTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::path(::testing::TempDir()) / ("exocet_seabed_" + std::to_string(::getpid()));
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }

  fs::path dir_;
};

TEST_F(ImageSeabedTest, RoundTripPixelsOrientationAndPyramid) {
  // 40 x 30 BGR pixels, random; the top row (north) pure red, the bottom row (south) pure blue.
  cv::Mat bgr(30, 40, CV_8UC3);
  sim::RandomStream rs(8, 9);
  for (int r = 0; r < bgr.rows; ++r)
    for (int c = 0; c < bgr.cols; ++c)
      for (int k = 0; k < 3; ++k) bgr.at<cv::Vec3b>(r, c)[k] = static_cast<uchar>(rs.uniform() * 256.0);
  bgr.row(0).setTo(cv::Scalar(0, 0, 255));
  bgr.row(29).setTo(cv::Scalar(255, 0, 0));
  ASSERT_TRUE(cv::imwrite(path("seabed.png"), bgr));

  const double pixel = 0.01, cx = 1.0, cy = 2.0;
  ImageSeabed img(path("seabed.png"), pixel, cx, cy);
  EXPECT_EQ(img.widthPixels(), 40);
  EXPECT_EQ(img.heightPixels(), 30);
  EXPECT_DOUBLE_EQ(img.baseTexelSize_m(), pixel);
  EXPECT_EQ(img.maxLevel(), 6);  // 40 -> 20 -> 10 -> 5 -> 3 -> 2 -> 1
  const WorldRect b = img.bounds();
  EXPECT_NEAR(b.x_min_m, 0.8, 1e-12);
  EXPECT_NEAR(b.x_max_m, 1.2, 1e-12);
  EXPECT_NEAR(b.y_min_m, 1.85, 1e-12);
  EXPECT_NEAR(b.y_max_m, 2.15, 1e-12);

  const auto p = img.albedoPatch(0, b);
  EXPECT_NEAR(p.texel_m, pixel, 1e-15);
  double worst = 0.0;
  for (int r = 0; r < bgr.rows; ++r)
    for (int c = 0; c < bgr.cols; ++c) {
      const double x = b.x_min_m + (c + 0.5) * pixel, y = b.y_max_m - (r + 0.5) * pixel;  // rows go south
      const cv::Vec3f v = p.sample(x, y);
      const cv::Vec3b& px = bgr.at<cv::Vec3b>(r, c);
      for (int k = 0; k < 3; ++k)
        worst = std::max(worst, std::abs(v[k] - std::pow(px[2 - k] / 255.0, 2.2)));  // R, G, B order
    }
  EXPECT_LT(worst, 1e-5);
  // North is up: red along the northern edge, blue along the southern one.
  const cv::Vec3f north = p.sample(1.0, b.y_max_m - 0.5 * pixel), south = p.sample(1.0, b.y_min_m + 0.5 * pixel);
  EXPECT_NEAR(north[0], 1.0, 1e-6);
  EXPECT_NEAR(north[2], 0.0, 1e-6);
  EXPECT_NEAR(south[2], 1.0, 1e-6);
  EXPECT_NEAR(south[0], 0.0, 1e-6);

  // Outside: the mean colour; covers() tells.
  const cv::Vec3f mean = img.meanAlbedo();
  const auto out = img.albedoPatch(0, {5.0, 5.0, 5.1, 5.1});
  for (int k = 0; k < 3; ++k) EXPECT_FLOAT_EQ(out.texels(2, 2)[k], mean[k]);
  EXPECT_TRUE(img.covers({0.85, 1.9, 1.15, 2.1}));
  EXPECT_FALSE(img.covers({0.85, 1.9, 1.25, 2.1}));

  // Level 1: 2x2 means of level 0, on the same ground.
  const auto p1 = img.albedoPatch(1, b);
  EXPECT_NEAR(p1.texel_m, 2 * pixel, 1e-15);
  for (const cv::Point cell : {cv::Point(0, 0), cv::Point(7, 5), cv::Point(19, 14)}) {
    const double x = b.x_min_m + (cell.x + 0.5) * 2 * pixel, y = b.y_min_m + (cell.y + 0.5) * 2 * pixel;
    const double h = 0.5 * pixel;
    const cv::Vec3f expect =
        0.25f * (p.sample(x - h, y - h) + p.sample(x + h, y - h) + p.sample(x - h, y + h) + p.sample(x + h, y + h));
    const cv::Vec3f got = p1.sample(x, y);
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(got[k], expect[k], 1e-6);
  }
  // The coarsest level is one texel: the mean.
  const auto top = img.albedoPatch(img.maxLevel(), b);
  const cv::Scalar all = cv::mean(p.texels(cv::Rect(2, 2, 40, 30)));
  const cv::Vec3f whole = top.sample(1.0, 2.0);
  // Odd sizes pad with the mean, so the top is the mean exactly.
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(whole[k], all[k], 1e-5);
}

TEST_F(ImageSeabedTest, SixteenBitGreyAndLinearDecoding) {
  cv::Mat grey(8, 8, CV_16U, cv::Scalar(0));
  grey.at<uint16_t>(0, 7) = 65535;  // north-east corner
  grey.at<uint16_t>(7, 0) = 32768;  // south-west corner
  ASSERT_TRUE(cv::imwrite(path("grey16.png"), grey));
  ImageSeabed img(path("grey16.png"), 0.5, 0.0, 0.0, 1.0);
  const auto p = img.albedoPatch(0, img.bounds());
  EXPECT_NEAR(p.sample(1.75, 1.75)[1], 1.0, 1e-6);
  EXPECT_NEAR(p.sample(-1.75, -1.75)[0], 32768.0 / 65535.0, 1e-6);
  EXPECT_NEAR(p.sample(0.25, 0.25)[2], 0.0, 1e-6);
}

TEST_F(ImageSeabedTest, ErrorsNameThePathOrTheField) {
  try {
    ImageSeabed img(path("missing.png"), 0.01);
    FAIL() << "no exception";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(path("missing.png")), std::string::npos) << e.what();
  }
  std::ofstream(path("notes.png")) << "not an image";
  try {
    ImageSeabed img(path("notes.png"), 0.01);
    FAIL() << "no exception";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(path("notes.png")), std::string::npos) << e.what();
  }
  cv::imwrite(path("ok.png"), cv::Mat(4, 4, CV_8UC3, cv::Scalar(10, 20, 30)));
  for (double bad : {0.0, -0.01, static_cast<double>(NAN)}) {
    try {
      ImageSeabed img(path("ok.png"), bad);
      FAIL() << "no exception for pixel_size_m " << bad;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("pixel_size_m"), std::string::npos) << e.what();
    }
  }
  EXPECT_THROW(ImageSeabed(path("ok.png"), 0.01, 0.0, 0.0, 0.0), std::invalid_argument);
  ImageSeabed img(path("ok.png"), 0.01);
  EXPECT_THROW(img.albedoPatch(img.maxLevel() + 1, img.bounds()), std::out_of_range);
}

}  // namespace

// catkin's gtest does not link gtest_main.
int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
