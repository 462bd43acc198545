// Which tiles a live image-gain solve takes (tiles::gainWindow) and which tiles' levels stay in memory
// (tiles::TileLevelsCache): a lawnmower of tiles, the newest solved, the ones of the line before under them anchors.
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <vector>

#include "exocet_mosaic/tiles/image_gain_window.h"

namespace et = exocet_mosaic::tiles;

namespace {

constexpr double kGsd = 0.01;
constexpr int kWidth = 100, kHeight = 80;

/// A tile of three images (1 m x 0.8 m each) whose top-left corner is at (east_m, north_m) of the UTM origin below.
et::TileRecord tileAt(int index, double east_m, double north_m) {
  et::TileRecord r;
  r.index = index;
  r.gsd_m = kGsd;
  r.ground_origin_en_m = Eigen::Vector2d(500000.0, 4800000.0);
  for (int i = 0; i < 3; ++i) {
    et::RecordedImage image;
    image.file = "t" + std::to_string(index) + "_" + std::to_string(i) + ".jpg";
    image.width_px = kWidth;
    image.height_px = kHeight;
    image.ground_from_px = cv::Matx33d(kGsd, 0, east_m + 0.5 * i, 0, -kGsd, north_m, 0, 0, 1);
    r.images.push_back(image);
  }
  return r;
}

/// Two lines of four tiles 2 m long going east then west, 0.6 m apart (their images overlap across the lines).
std::map<int, et::TileRecord> lawnmower() {
  std::map<int, et::TileRecord> records;
  for (int i = 0; i < 4; ++i) records[i] = tileAt(i, 2.0 * i, 0.0);
  for (int i = 0; i < 4; ++i) records[4 + i] = tileAt(4 + i, 2.0 * (3 - i), -0.6);
  return records;
}

}  // namespace

TEST(ImageGainWindow, TheBoxOfATileIsWhereItsImagesAre) {
  const auto box = et::tileImagesBox(tileAt(0, 1.0, 2.0));
  EXPECT_NEAR(box[0], 500001.0, 1e-9);
  EXPECT_NEAR(box[2], 500001.0 + 1.0 + 1.0, 1e-9);  // the third image starts 1 m east, 1 m wide
  EXPECT_NEAR(box[1], 4800002.0 - 0.8, 1e-9);
  EXPECT_NEAR(box[3], 4800002.0, 1e-9);
  EXPECT_TRUE(std::isnan(et::tileImagesBox(et::TileRecord())[0]));  // no image: no box
}

TEST(ImageGainWindow, TheNewestTilesAreSolvedAgainstTheOlderOnesUnderThem) {
  const auto records = lawnmower();
  // The two newest tiles (6, 7: the return line's west end) lie under tiles 0 and 1 of the first line.
  const et::GainWindow w = et::gainWindow(records, 2);
  EXPECT_EQ(w.solved, (std::vector<int>{6, 7}));
  EXPECT_EQ(w.anchors, (std::vector<int>{0, 1}));  // 2 and 5 only touch them (east edge at 4 m): no common cell
  // 0, or as many as there are tiles: the whole dive, no anchor.
  for (int n : {0, 8, 20}) {
    const et::GainWindow all = et::gainWindow(records, n);
    EXPECT_EQ(all.solved.size(), 8u) << n;
    EXPECT_TRUE(all.anchors.empty()) << n;
  }
  EXPECT_TRUE(et::gainWindow({}, 4).solved.empty());
}

TEST(ImageGainWindow, TheLevelsOfTheLeastRecentlyUsedTilesAreLetGo) {
  et::TileLevelsCache cache(3);
  EXPECT_TRUE(cache.use({1, 2}).empty());
  EXPECT_TRUE(cache.use({3}).empty());
  EXPECT_EQ(cache.use({1, 4}), (std::vector<int>{2}));  // 1 used again: 2 is the least recent
  EXPECT_EQ(cache.size(), 3u);
  EXPECT_TRUE(cache.contains(1));
  EXPECT_FALSE(cache.contains(2));
  EXPECT_EQ(cache.use({5, 6, 7}), (std::vector<int>{3, 1, 4}));
  EXPECT_EQ(cache.size(), 3u);
}
