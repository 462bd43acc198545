/**
 * Tests of the tiles that follow the pose graph (tiles/tile_revisions.h) and of their versions on disk: the
 * corrections track, where a tile's images go at new corrections (a hand-built tile whose answer is known), the tile
 * drawn again (its pixels and georeference), the record's JSON, versioned files and the folder listing.
 */
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include <gdal_priv.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "exocet_common/testing/temp_dir.h"
#include "exocet_mosaic/compose/ground_projection.h"
#include "exocet_mosaic/tiles/geotiff_tile_writer.h"
#include "exocet_mosaic/tiles/tile_mosaic_vrt.h"
#include "exocet_mosaic/tiles/tile_network_adjustment.h"
#include "exocet_mosaic/tiles/tile_revisions.h"

namespace {

namespace et = exocet_mosaic::tiles;
using exocet_common::testing::TempDir;

constexpr double kGsd = 0.01;
constexpr int kWidth = 64, kHeight = 48;

/// A line of n images 0.2 m apart going east, one pixel = one GSD, their fused centres where the chain put them
/// plus `nav_offset` (the tile's disagreement with its navigation), correction 0 then.
et::TileRecord lineTile(int n, const Eigen::Vector2d& nav_offset = Eigen::Vector2d::Zero()) {
  et::TileRecord r;
  r.index = 3;
  r.gsd_m = kGsd;
  r.utm_zone = 31;
  r.ground_origin_en_m = Eigen::Vector2d(500000.0, 4800000.0);
  r.metadata.first_frame = 0;
  r.metadata.last_frame = n - 1;
  for (int i = 0; i < n; ++i) {
    et::RecordedImage image;
    image.frame = i;
    image.stamp_s = 100.0 + i;
    image.file = "image_" + std::to_string(i) + ".jpg";
    image.width_px = kWidth;
    image.height_px = kHeight;
    // px -> ground: x east, y south, top-left pixel edge at (0.2 i, 0).
    image.closed_ground_from_px = image.ground_from_px =
        cv::Matx33d(kGsd, 0, 0.2 * i + 0.5 * kGsd, 0, -kGsd, -0.5 * kGsd, 0, 0, 1);
    const Eigen::Vector2d centre =
        exocet_mosaic::compose::applyHomography(image.closed_ground_from_px, Eigen::Vector2d(31.5, 23.5));
    image.closed_navigation_m = centre + nav_offset;
    r.images.push_back(image);
  }
  return r;
}

et::GeoTiffTileWriter writerIn(const TempDir& dir) {
  et::TileWriterConfig config;
  config.output_dir = dir.path();
  return et::GeoTiffTileWriter(config);
}

/// A 50 x 40 px uniform tile at (500000, 4800000), GSD kGsd.
et::TileRaster plainRaster() {
  et::TileRaster raster;
  raster.image = cv::Mat(40, 50, CV_8UC3, cv::Scalar(10, 20, 30));
  raster.origin_easting_m = 500000.0;
  raster.origin_northing_m = 4800000.0;
  raster.gsd_m = kGsd;
  return raster;
}

et::PositionCorrectionTrack constantTrack(const Eigen::Vector2d& c) {
  et::PositionCorrectionTrack track;
  track.set({0.0, 1000.0}, {c, c});
  return track;
}

Eigen::Vector2d centreAt(const cv::Matx33d& ground_from_px) {
  return exocet_mosaic::compose::applyHomography(ground_from_px, Eigen::Vector2d(31.5, 23.5));
}

}  // namespace

TEST(PositionCorrectionTrack, InterpolatesInTimeAndHoldsItsEnds) {
  et::PositionCorrectionTrack track;
  EXPECT_TRUE(track.at(5.0).isZero());
  const int left_out = track.set({1.0, 2.0, 2.0, 3.0, NAN}, {Eigen::Vector2d(0, 0), Eigen::Vector2d(1, -1),
                                                             Eigen::Vector2d(9, 9), Eigen::Vector2d(3, 1),
                                                             Eigen::Vector2d(0, 0)});
  EXPECT_EQ(left_out, 2);  // the repeated stamp and the NaN
  ASSERT_EQ(track.size(), 3u);
  EXPECT_NEAR(track.at(1.5).x(), 0.5, 1e-12);
  EXPECT_NEAR(track.at(2.5).x(), 2.0, 1e-12);
  EXPECT_NEAR(track.at(2.5).y(), 0.0, 1e-12);
  EXPECT_NEAR(track.at(-10).x(), 0.0, 1e-12);
  EXPECT_NEAR(track.at(10).x(), 3.0, 1e-12);
}

TEST(TileRevisions, AChangeOfTheCorrectionMovesEveryImageByIt) {
  const et::TileRecord record = lineTile(9);
  const Eigen::Vector2d move(0.03, -0.02);
  const auto placements = et::placementsAt(record, constantTrack(move));
  ASSERT_EQ(placements.size(), 9u);
  for (std::size_t i = 0; i < placements.size(); ++i) {
    const Eigen::Vector2d d = centreAt(placements[i]) - centreAt(record.images[i].closed_ground_from_px);
    EXPECT_NEAR(d.x(), move.x(), 1e-6) << i;
    EXPECT_NEAR(d.y(), move.y(), 1e-6) << i;
  }
  EXPECT_NEAR(et::tileDisplacementM(record, constantTrack(move)), move.norm(), 1e-6);
  EXPECT_NEAR(et::tileDisplacementM(record, constantTrack(Eigen::Vector2d::Zero())), 0.0, 1e-9);
}

TEST(TileRevisions, TheTileGoesToItsNavigationNotWhereTheChainOfTilesHeldIt) {
  // The tile was held 4 cm off its fused positions (tied to the previous tile); the graph's positions are consistent:
  // drawn again, the tile sits on them.
  const et::TileRecord record = lineTile(9, Eigen::Vector2d(0.04, 0.0));
  const auto placements = et::placementsAt(record, constantTrack(Eigen::Vector2d::Zero()));
  for (std::size_t i = 0; i < placements.size(); ++i)
    EXPECT_NEAR((centreAt(placements[i]) - *record.images[i].closed_navigation_m).norm(), 0.0, 2e-4) << i;
}

TEST(TileRevisions, OneWrongPoseDoesNotBendTheTile) {
  et::TileRecord record = lineTile(9);
  *record.images[4].closed_navigation_m += Eigen::Vector2d(0.5, 0.0);
  et::RevisionConfig similarity_only;
  similarity_only.residual_window_images = 0;
  const auto placements = et::placementsAt(record, constantTrack(Eigen::Vector2d::Zero()), similarity_only);
  for (std::size_t i = 0; i < placements.size(); ++i)
    EXPECT_LT((centreAt(placements[i]) - centreAt(record.images[i].closed_ground_from_px)).norm(), 1e-4) << i;
}

TEST(TileRevisions, TheTileBendsWithTheGraphPerImage) {
  // The graph bends the track: the correction changes along the tile, 3.2 cm northwards at its ends, 0 mid-way.
  const et::TileRecord record = lineTile(9);
  et::PositionCorrectionTrack track;
  // A similarity takes the straight part; what a similarity cannot (a bend: here quadratic) the residuals take.
  std::vector<double> stamps;
  std::vector<Eigen::Vector2d> values;
  for (int i = 0; i <= 8; ++i) {
    stamps.push_back(100.0 + i);
    values.emplace_back(0.0, 0.002 * (i - 4) * (i - 4));
  }
  track.set(stamps, values);
  et::RevisionConfig per_tile, per_image;
  per_tile.residual_window_images = 0;
  per_image.residual_window_images = 3;
  double worst_tile = 0, worst_image = 0;
  const auto a = et::placementsAt(record, track, per_tile), b = et::placementsAt(record, track, per_image);
  for (int i = 0; i <= 8; ++i) {
    const Eigen::Vector2d target = *record.images[i].closed_navigation_m + values[i];
    worst_tile = std::max(worst_tile, (centreAt(a[i]) - target).norm());
    worst_image = std::max(worst_image, (centreAt(b[i]) - target).norm());
  }
  EXPECT_GT(worst_tile, 0.005);
  EXPECT_LT(worst_image, 0.5 * worst_tile);
}

namespace {

/// Where a placement lays the image's +x axis at its centre (rad, counter-clockwise from east).
double contentDirectionRad(const cv::Matx33d& ground_from_px) {
  return exocet_mosaic::compose::imageXDirectionRad(ground_from_px, Eigen::Vector2d(31.5, 23.5));
}

/// lineTile(n) whose chain turned image i's content by drift_rad(i) about its centre, while the poses' headings say
/// every image lies east (0 rad), as it does.
template <typename Drift>
et::TileRecord driftedLineTile(int n, Drift drift_rad) {
  et::TileRecord record = lineTile(n);
  for (int i = 0; i < n; ++i) {
    et::RecordedImage& image = record.images[i];
    const Eigen::Vector2d g = centreAt(image.closed_ground_from_px);
    const double a = drift_rad(i), c = std::cos(a), s = std::sin(a);
    const cv::Matx33d turn(c, -s, g.x() - c * g.x() + s * g.y(), s, c, g.y() - s * g.x() - c * g.y(), 0, 0, 1);
    image.closed_ground_from_px = image.ground_from_px = turn * image.closed_ground_from_px;
    image.closed_navigation_heading_rad = 0.0;
  }
  return record;
}

}  // namespace

TEST(TileRevisions, TheImagesTurnBackToTheirHeadingsFromTheChainsDrift) {
  // The chain's rotation drifted by 1 mrad per image (20 mrad over the tile); the heading sensor did not.
  const et::TileRecord record = driftedLineTile(21, [](int i) { return 0.001 * (i - 10); });
  et::RevisionConfig follows_heading, chain_kept;
  chain_kept.content_follows_heading = false;
  const auto track = constantTrack(Eigen::Vector2d(0.01, 0.0));
  const auto a = et::placementsAt(record, track, follows_heading), c = et::placementsAt(record, track, chain_kept);
  for (int i = 0; i < 21; ++i) {
    EXPECT_NEAR(contentDirectionRad(a[i]), 0.0, 1e-6) << i;
    EXPECT_NEAR(contentDirectionRad(c[i]), 0.001 * (i - 10), 1e-6) << i;
    // The centres go where the graph says, turned or not.
    EXPECT_NEAR((centreAt(a[i]) - centreAt(c[i])).norm(), 0.0, 1e-6) << i;
  }
  EXPECT_GT(et::tileDisplacementM(record, constantTrack(Eigen::Vector2d::Zero()), follows_heading), 0.0005);
}

TEST(TileRevisions, TheHeadingsNoiseIsAveragedOverTheTile) {
  // The same drift seen through a heading with 5 mrad of noise per image: the turn is the drift's trend.
  const double noise[] = {4, -5, 2, 5, -3, -4, 1, 5, -2, -5, 3, 0, -1, 4, -4, 2, -3, 5, 1, -5, 3};
  et::TileRecord record = driftedLineTile(21, [](int i) { return 0.001 * (i - 10); });
  for (int i = 0; i < 21; ++i) record.images[i].closed_navigation_heading_rad = 0.001 * noise[i];
  const auto a = et::placementsAt(record, constantTrack(Eigen::Vector2d::Zero()));
  double worst = 0;
  for (int i = 0; i < 21; ++i) worst = std::max(worst, std::abs(contentDirectionRad(a[i])));
  EXPECT_LT(worst, 0.003);  // from 10 mrad at the ends
}

TEST(TileRevisions, AGraphThatTurnsTheTrackMovesTheImagesWithoutTurningThem) {
  // The graph's correction grows across the tile (the track turns by 5 mrad); the headings say the images lie east.
  const et::TileRecord record = driftedLineTile(21, [](int) { return 0.0; });
  et::PositionCorrectionTrack track;
  std::vector<double> stamps;
  std::vector<Eigen::Vector2d> values;
  for (int i = 0; i < 21; ++i) {
    stamps.push_back(100.0 + i);
    values.emplace_back(0.0, 0.005 * 0.2 * (i - 10));
  }
  track.set(stamps, values);
  et::RevisionConfig follows_heading, chain_kept;
  chain_kept.content_follows_heading = false;
  const auto a = et::placementsAt(record, track, follows_heading), c = et::placementsAt(record, track, chain_kept);
  for (int i = 0; i < 21; ++i) {
    const Eigen::Vector2d target = *record.images[i].closed_navigation_m + values[i];
    EXPECT_LT((centreAt(a[i]) - target).norm(), 0.1 * kGsd) << i;  // the rotation prior holds back a little
    EXPECT_NEAR(contentDirectionRad(a[i]), 0.0, 1e-6) << i;
    EXPECT_GT(contentDirectionRad(c[i]), 0.002) << i;  // the similarity turned them with the track
  }
}

TEST(TileRevisions, AHeadingFarFromTheOthersIsLeftOut) {
  et::TileRecord record = driftedLineTile(9, [](int) { return 0.0; });
  record.images[8].closed_navigation_heading_rad = 0.5;  // a wrong pose at the tile's end: 0.5 rad from the others
  const auto a = et::placementsAt(record, constantTrack(Eigen::Vector2d::Zero()));
  for (int i = 0; i < 9; ++i) EXPECT_NEAR(contentDirectionRad(a[i]), 0.0, 1e-6) << i;
}

TEST(TileRevisions, TheTileDrawnAgainIsTheSamePixelsMovedByTheCorrection) {
  TempDir dir;
  et::TileRecord record = lineTile(5);
  cv::RNG rng(7);
  for (auto& image : record.images) {
    cv::Mat pixels(kHeight, kWidth, CV_8UC3);
    rng.fill(pixels, cv::RNG::UNIFORM, 20, 230);
    cv::GaussianBlur(pixels, pixels, cv::Size(3, 3), 0);
    ASSERT_EQ(et::writeRecordedImage(dir.path(), image.file, pixels, 100), "");
  }
  exocet_mosaic::compose::PlacedImageRenderConfig render;
  const et::RevisedTile same = et::renderTileAt(record, constantTrack(Eigen::Vector2d::Zero()), dir.path(), render);
  const Eigen::Vector2d move(3 * kGsd, -2 * kGsd);  // whole pixels
  const et::RevisedTile moved = et::renderTileAt(record, constantTrack(move), dir.path(), render);
  ASSERT_FALSE(same.raster.image.empty()) << same.problem;
  ASSERT_FALSE(moved.raster.image.empty()) << moved.problem;
  EXPECT_EQ(moved.record.version, record.version + 1);
  EXPECT_NEAR(moved.moved_max_m, move.norm(), 1e-6);
  EXPECT_NEAR(moved.raster.origin_easting_m - same.raster.origin_easting_m, move.x(), 1e-6);
  EXPECT_NEAR(moved.raster.origin_northing_m - same.raster.origin_northing_m, move.y(), 1e-6);
  ASSERT_EQ(moved.raster.image.size(), same.raster.image.size());
  cv::Mat diff;
  cv::absdiff(moved.raster.image, same.raster.image, diff);
  double worst = 0;
  cv::minMaxLoc(diff.reshape(1), nullptr, &worst);
  EXPECT_LE(worst, 1.0);
  // The pixel grid stays on multiples of the GSD (versions and neighbours share it).
  EXPECT_NEAR(std::remainder(moved.raster.origin_easting_m, kGsd), 0.0, 1e-6);
  // Each image is drawn with its own gain (after the lighting): one image at 0.5 darkens its part only.
  et::TileRecord dimmed = record;
  for (auto& image : dimmed.images) image.gain = {0.5, 0.5, 0.5};
  const et::RevisedTile dark = et::renderTileAt(dimmed, constantTrack(Eigen::Vector2d::Zero()), dir.path(), render);
  ASSERT_EQ(dark.raster.image.size(), same.raster.image.size());
  EXPECT_NEAR(cv::mean(dark.raster.image, dark.raster.mask)[1], 0.5 * cv::mean(same.raster.image, same.raster.mask)[1],
              1.0);
  EXPECT_EQ(dark.record.images[0].gain[1], 0.5);
  // An image that cannot be read is left out and said.
  std::filesystem::remove(dir.path() + "/" + record.images[2].file);
  const et::RevisedTile missing = et::renderTileAt(record, constantTrack(move), dir.path(), render);
  EXPECT_EQ(missing.images_missing, 1);
  EXPECT_NE(missing.problem.find(record.images[2].file), std::string::npos);
}

TEST(TileRevisions, TheRecordReadsBackAndABadOneIsNamed) {
  et::TileRecord record = lineTile(3);
  record.images[1].closed_navigation_m.reset();
  record.images[2].gain = {1.1, 0.9, 1.05};
  record.images[2].closed_navigation_heading_rad = -0.25;
  record.metadata.extra["blend"] = "feather";
  const et::TileRecord back = et::tileRecordFromJson(et::tileRecordToJson(record));
  EXPECT_FALSE(back.images[0].closed_navigation_heading_rad.has_value());
  ASSERT_TRUE(back.images[2].closed_navigation_heading_rad.has_value());
  EXPECT_EQ(*back.images[2].closed_navigation_heading_rad, -0.25);
  ASSERT_EQ(back.images.size(), 3u);
  EXPECT_EQ(back.index, 3);
  EXPECT_FALSE(back.images[1].closed_navigation_m.has_value());
  EXPECT_NEAR((*back.images[2].closed_navigation_m - *record.images[2].closed_navigation_m).norm(), 0.0, 1e-12);
  EXPECT_EQ(back.images[2].file, record.images[2].file);
  EXPECT_EQ(back.images[2].gain, record.images[2].gain);
  EXPECT_EQ(back.images[0].gain, (std::array<double, 3>{1.0, 1.0, 1.0}));  // no gain written: 1
  EXPECT_EQ(back.metadata.extra.at("blend"), "feather");
  nlohmann::json bad = et::tileRecordToJson(record);
  bad["images"][0]["file"] = "../escape.jpg";
  try {
    et::tileRecordFromJson(bad);
    FAIL() << "a path in an image file name was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("plain name"), std::string::npos) << e.what();
  }
  bad = et::tileRecordToJson(record);
  bad["images"][2]["gain"] = {1.0, -1.0, 1.0};
  try {
    et::tileRecordFromJson(bad);
    FAIL() << "a negative gain was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("gain"), std::string::npos) << e.what();
  }
  bad = et::tileRecordToJson(record);
  bad["images"][2]["closed_navigation_heading_rad"] = "north";
  try {
    et::tileRecordFromJson(bad);
    FAIL() << "a heading that is not a number was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("closed_navigation_heading_rad"), std::string::npos) << e.what();
  }
  bad = et::tileRecordToJson(record);
  bad.erase("gsd_m");
  try {
    et::tileRecordFromJson(bad);
    FAIL() << "a record without gsd_m was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("gsd_m"), std::string::npos) << e.what();
  }
}

TEST(TileVersions, ANewVersionIsWrittenBesideTheOldOneWhichGoesAfter) {
  TempDir dir;
  et::GeoTiffTileWriter writer = writerIn(dir);
  et::TileRaster raster = plainRaster();
  et::TileMetadata metadata;
  const et::WrittenTile first = writer.write(raster, metadata);
  ASSERT_TRUE(first.ok) << first.error;
  EXPECT_EQ(first.version, 1);
  EXPECT_FALSE(writer.writeVersion(raster, metadata, first.index, 1).ok);  // versions start at 2
  const et::WrittenTile second = writer.writeVersion(raster, metadata, first.index, 2);
  ASSERT_TRUE(second.ok) << second.error;
  EXPECT_EQ(second.version, 2);
  EXPECT_EQ(std::filesystem::path(second.geotiff_path).filename().string(), "tile_0000_v2.tif");
  EXPECT_TRUE(std::filesystem::exists(first.geotiff_path));  // until the caller removes it
  EXPECT_FALSE(writer.writeVersion(raster, metadata, first.index, 2).ok);  // never replaces a file
  EXPECT_EQ(writer.removeVersion(first.index, 1), 2);  // .tif and .tfw
  EXPECT_FALSE(std::filesystem::exists(first.geotiff_path));
  // The index stays taken by its later version (a restart does not reuse it).
  EXPECT_EQ(writer.nextIndex(), 1);
  GDALAllRegister();
  GDALDataset* dataset = static_cast<GDALDataset*>(GDALOpen(second.geotiff_path.c_str(), GA_ReadOnly));
  ASSERT_NE(dataset, nullptr);
  const char* version = dataset->GetMetadataItem("EXOCET_TILE_VERSION");
  ASSERT_NE(version, nullptr);
  EXPECT_STREQ(version, "2");
  GDALClose(dataset);
  // The folder's listing gives each tile once, at its newest version.
  ASSERT_TRUE(writer.write(raster, metadata).ok);
  const auto listed = et::listTiles(dir.path());
  ASSERT_EQ(listed.size(), 2u);
  EXPECT_EQ(std::filesystem::path(listed[0]).filename().string(), "tile_0000_v2.tif");
  EXPECT_EQ(std::filesystem::path(listed[1]).filename().string(), "tile_0001.tif");
}

TEST(TileVersions, TheVirtualMosaicCoversTheNewestTilesAndSaysWhatIsWrong) {
  TempDir dir;
  et::GeoTiffTileWriter writer = writerIn(dir);
  et::TileRaster raster = plainRaster();
  ASSERT_TRUE(writer.write(raster, et::TileMetadata()).ok);
  raster.origin_easting_m += 0.3;  // 30 px further east
  ASSERT_TRUE(writer.writeVersion(raster, et::TileMetadata(), 0, 2).ok);
  raster.origin_easting_m += 1.0;
  ASSERT_TRUE(writer.write(raster, et::TileMetadata()).ok);
  writer.removeVersion(0, 1);
  const std::string vrt = dir.path() + "/tile_mosaic.vrt";
  ASSERT_EQ(et::writeTileMosaicVrt(vrt, et::listTiles(dir.path())), "");
  GDALAllRegister();
  GDALDataset* dataset = static_cast<GDALDataset*>(GDALOpen(vrt.c_str(), GA_ReadOnly));
  ASSERT_NE(dataset, nullptr);
  double geo[6];
  ASSERT_EQ(dataset->GetGeoTransform(geo), CE_None);
  EXPECT_NEAR(geo[0], 500000.3, 1e-6);  // the first version is gone: the mosaic starts at the second
  EXPECT_EQ(dataset->GetRasterXSize(), 150);  // 0.3 .. 1.8 m east
  GDALClose(dataset);
  // Relative to its folder: the tiles and their mosaic move together.
  std::ifstream in(vrt);
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_NE(text.find("relativeToVRT=\"1\">tile_0000_v2.tif"), std::string::npos) << text.substr(0, 2000);
  EXPECT_NE(et::writeTileMosaicVrt(vrt, {}).find("no tile"), std::string::npos);
  EXPECT_NE(et::writeTileMosaicVrt(vrt, {dir.path() + "/missing.tif"}), "");
}
