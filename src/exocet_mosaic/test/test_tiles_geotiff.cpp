/**
 * Tests of GeoTiffTileWriter: synthetic rasters with a known pattern, origin and zone are written and read back with
 * GDAL (pixels in RGB order, alpha, geotransform, EPSG, metadata, world file, COG, KMZ); the WGS 84 bounds are checked
 * against GeographicLib; the atomicity is checked by killing a writer mid-write, on a read-only and on a full file
 * system.
 */
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <signal.h>
#include <sys/mount.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cpl_vsi.h>
#include <gdal_priv.h>
#include <ogr_spatialref.h>
#include <GeographicLib/UTMUPS.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "exocet_common/testing/paths.h"
#include "exocet_common/testing/temp_dir.h"
#include "exocet_mosaic/tiles/geotiff_tile_writer.h"

namespace fs = std::filesystem;
using exocet_mosaic::tiles::epsgForUtm;
using exocet_mosaic::tiles::GeoTiffTileWriter;
using exocet_mosaic::tiles::TileMetadata;
using exocet_mosaic::tiles::TileRaster;
using exocet_mosaic::tiles::TileWriterConfig;
using exocet_mosaic::tiles::WrittenTile;

namespace {

/// A fresh folder under /tmp, removed with its contents.
using TempDir = exocet_common::testing::TempDir;

struct DatasetCloser {
  void operator()(GDALDataset* d) const {
    if (d) GDALClose(GDALDataset::ToHandle(d));
  }
};
using DatasetPtr = std::unique_ptr<GDALDataset, DatasetCloser>;

DatasetPtr openDataset(const std::string& path) {
  GDALAllRegister();
  return DatasetPtr(
      GDALDataset::FromHandle(GDALOpenEx(path.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY, nullptr, nullptr, nullptr)));
}

/// B, G, R differ per pixel and per channel, so that a swapped channel or a shifted row shows.
cv::Mat patternImage(int width, int height) {
  cv::Mat image(height, width, CV_8UC3);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      image.at<cv::Vec3b>(y, x) = cv::Vec3b(static_cast<uchar>(x % 251), static_cast<uchar>((y * 3) % 253),
                                            static_cast<uchar>((x + 7 * y) % 256));
    }
  }
  return image;
}

/// No data on the left 13 columns and in a disc; 255 elsewhere.
cv::Mat patternMask(int width, int height) {
  cv::Mat mask(height, width, CV_8UC1, cv::Scalar(255));
  mask.colRange(0, 13).setTo(0);
  cv::circle(mask, cv::Point(width * 2 / 3, height / 2), std::min(width, height) / 5, cv::Scalar(0), cv::FILLED);
  return mask;
}

TileRaster makeRaster(int width, int height, int zone, bool northern, double easting_m, double northing_m,
                      double gsd_m = 0.05) {
  TileRaster raster;
  raster.image = patternImage(width, height);
  raster.mask = patternMask(width, height);
  raster.origin_easting_m = easting_m;
  raster.origin_northing_m = northing_m;
  raster.gsd_m = gsd_m;
  raster.utm_zone = zone;
  raster.northern_hemisphere = northern;
  return raster;
}

TileMetadata makeMetadata() {
  TileMetadata metadata;
  metadata.dive_name = "dive_2024_05_17";
  metadata.first_frame = 120;
  metadata.last_frame = 345;
  metadata.start_time_s = 1715940000.25;
  metadata.end_time_s = 1715940112.75;
  metadata.mean_altitude_m = 2.375;
  metadata.close_reason = "size";
  metadata.extra["camera"] = "left";
  return metadata;
}

TileWriterConfig configFor(const std::string& folder) {
  TileWriterConfig config;
  config.output_dir = folder;
  return config;
}

cv::Mat readBand(GDALDataset* dataset, int band) {
  cv::Mat out(dataset->GetRasterYSize(), dataset->GetRasterXSize(), CV_8UC1);
  EXPECT_EQ(dataset->GetRasterBand(band)->RasterIO(GF_Read, 0, 0, out.cols, out.rows, out.data, out.cols, out.rows,
                                                   GDT_Byte, 0, 0, nullptr),
            CE_None);
  return out;
}

int countDifferent(const cv::Mat& a, const cv::Mat& b) {
  cv::Mat diff;
  cv::compare(a, b, diff, cv::CMP_NE);
  return cv::countNonZero(diff);
}

std::vector<std::string> filesIn(const std::string& folder) {
  std::vector<std::string> names;
  for (const auto& entry : fs::directory_iterator(folder)) names.push_back(entry.path().filename().string());
  std::sort(names.begin(), names.end());
  return names;
}

std::string readFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

int epsgOf(GDALDataset* dataset) {
  const OGRSpatialReference* srs = dataset->GetSpatialRef();
  if (!srs) return 0;
  const char* code = srs->GetAuthorityCode(nullptr);
  return code ? std::atoi(code) : 0;
}

}  // namespace

TEST(TilesGeoTiff, GeometryPixelsAlphaAndMetadataReadBack) {
  TempDir dir;
  GeoTiffTileWriter writer(configFor(dir.path()));
  const TileRaster raster = makeRaster(300, 200, 31, true, 500123.5, 4800456.25, 0.05);
  const WrittenTile tile = writer.write(raster, makeMetadata());
  ASSERT_TRUE(tile.ok) << tile.error;
  EXPECT_EQ(tile.index, 0);
  EXPECT_EQ(tile.geotiff_path, dir.path() + "/tile_0000.tif");
  EXPECT_EQ(tile.epsg, 32631);
  EXPECT_EQ(tile.width_px, 300);
  EXPECT_EQ(tile.height_px, 200);
  EXPECT_DOUBLE_EQ(tile.min_easting_m, 500123.5);
  EXPECT_DOUBLE_EQ(tile.max_easting_m, 500123.5 + 300 * 0.05);
  EXPECT_DOUBLE_EQ(tile.max_northing_m, 4800456.25);
  EXPECT_DOUBLE_EQ(tile.min_northing_m, 4800456.25 - 200 * 0.05);
  // Only the final files: no temporary, no .aux.xml.
  EXPECT_EQ(filesIn(dir.path()), (std::vector<std::string>{"tile_0000.tfw", "tile_0000.tif"}));

  DatasetPtr dataset = openDataset(tile.geotiff_path);
  ASSERT_TRUE(dataset);
  EXPECT_STREQ(dataset->GetDriver()->GetDescription(), "GTiff");
  ASSERT_EQ(dataset->GetRasterXSize(), 300);
  ASSERT_EQ(dataset->GetRasterYSize(), 200);
  ASSERT_EQ(dataset->GetRasterCount(), 4);
  EXPECT_EQ(dataset->GetRasterBand(1)->GetColorInterpretation(), GCI_RedBand);
  EXPECT_EQ(dataset->GetRasterBand(2)->GetColorInterpretation(), GCI_GreenBand);
  EXPECT_EQ(dataset->GetRasterBand(3)->GetColorInterpretation(), GCI_BlueBand);
  EXPECT_EQ(dataset->GetRasterBand(4)->GetColorInterpretation(), GCI_AlphaBand);

  // RGB band order: band 1 holds OpenCV's channel 2 (red).
  std::vector<cv::Mat> bgr;
  cv::split(raster.image, bgr);
  EXPECT_EQ(countDifferent(readBand(dataset.get(), 1), bgr[2]), 0);
  EXPECT_EQ(countDifferent(readBand(dataset.get(), 2), bgr[1]), 0);
  EXPECT_EQ(countDifferent(readBand(dataset.get(), 3), bgr[0]), 0);
  const cv::Mat alpha = readBand(dataset.get(), 4);
  EXPECT_EQ(countDifferent(alpha, raster.mask), 0);
  EXPECT_EQ(alpha.at<uchar>(100, 5), 0);  // no-data column
  EXPECT_EQ(alpha.at<uchar>(5, 100), 255);

  double geotransform[6];
  ASSERT_EQ(dataset->GetGeoTransform(geotransform), CE_None);
  EXPECT_DOUBLE_EQ(geotransform[0], 500123.5);
  EXPECT_DOUBLE_EQ(geotransform[1], 0.05);
  EXPECT_DOUBLE_EQ(geotransform[2], 0.0);
  EXPECT_DOUBLE_EQ(geotransform[3], 4800456.25);
  EXPECT_DOUBLE_EQ(geotransform[4], 0.0);
  EXPECT_DOUBLE_EQ(geotransform[5], -0.05);
  EXPECT_EQ(epsgOf(dataset.get()), 32631);

  int block_x = 0, block_y = 0;
  dataset->GetRasterBand(1)->GetBlockSize(&block_x, &block_y);
  EXPECT_EQ(block_x, 256);
  EXPECT_EQ(block_y, 256);
  EXPECT_STREQ(dataset->GetMetadataItem("COMPRESSION", "IMAGE_STRUCTURE"), "DEFLATE");
  EXPECT_STREQ(dataset->GetMetadataItem("PREDICTOR", "IMAGE_STRUCTURE"), "2");
  EXPECT_EQ(dataset->GetRasterBand(1)->GetOverviewCount(), 0);  // small: no overviews

  const auto item = [&](const char* key) {
    const char* value = dataset->GetMetadataItem(key);
    return std::string(value ? value : "<missing>");
  };
  EXPECT_EQ(item("TIFFTAG_SOFTWARE"), "Exocet");
  EXPECT_EQ(item("TIFFTAG_DOCUMENTNAME"), "dive_2024_05_17");
  EXPECT_EQ(item("TIFFTAG_DATETIME").size(), 19u);  // "YYYY:MM:DD HH:MM:SS"
  EXPECT_EQ(item("EXOCET_DIVE_NAME"), "dive_2024_05_17");
  EXPECT_EQ(item("EXOCET_FIRST_FRAME"), "120");
  EXPECT_EQ(item("EXOCET_LAST_FRAME"), "345");
  EXPECT_DOUBLE_EQ(std::stod(item("EXOCET_START_TIME_S")), 1715940000.25);
  EXPECT_DOUBLE_EQ(std::stod(item("EXOCET_END_TIME_S")), 1715940112.75);
  EXPECT_DOUBLE_EQ(std::stod(item("EXOCET_MEAN_ALTITUDE_M")), 2.375);
  EXPECT_EQ(item("EXOCET_CLOSE_REASON"), "size");
  EXPECT_EQ(item("EXOCET_TILE_INDEX"), "0");
  EXPECT_EQ(item("EXOCET_CAMERA"), "left");

  // WGS 84 box: GeographicLib's reverse of the corners lies inside it, and (small tile) spans it.
  double lat_min = 90, lat_max = -90, lon_min = 180, lon_max = -180;
  for (const double e : {tile.min_easting_m, tile.max_easting_m}) {
    for (const double n : {tile.min_northing_m, tile.max_northing_m}) {
      double lat, lon;
      GeographicLib::UTMUPS::Reverse(31, true, e, n, lat, lon);
      lat_min = std::min(lat_min, lat), lat_max = std::max(lat_max, lat);
      lon_min = std::min(lon_min, lon), lon_max = std::max(lon_max, lon);
    }
  }
  EXPECT_NEAR(tile.south_deg, lat_min, 1e-8);
  EXPECT_NEAR(tile.north_deg, lat_max, 1e-8);
  EXPECT_NEAR(tile.west_deg, lon_min, 1e-8);
  EXPECT_NEAR(tile.east_deg, lon_max, 1e-8);
}

TEST(TilesGeoTiff, GreyImageGetsGreyAndAlphaBandsAndEmptyMaskIsAllData) {
  TempDir dir;
  GeoTiffTileWriter writer(configFor(dir.path()));
  TileRaster raster = makeRaster(64, 48, 30, true, 400000.0, 5000000.0);
  cv::cvtColor(raster.image, raster.image, cv::COLOR_BGR2GRAY);
  raster.mask.release();
  const WrittenTile tile = writer.write(raster, TileMetadata());
  ASSERT_TRUE(tile.ok) << tile.error;
  DatasetPtr dataset = openDataset(tile.geotiff_path);
  ASSERT_TRUE(dataset);
  ASSERT_EQ(dataset->GetRasterCount(), 2);
  EXPECT_EQ(dataset->GetRasterBand(1)->GetColorInterpretation(), GCI_GrayIndex);
  EXPECT_EQ(dataset->GetRasterBand(2)->GetColorInterpretation(), GCI_AlphaBand);
  EXPECT_EQ(countDifferent(readBand(dataset.get(), 1), raster.image), 0);
  EXPECT_EQ(cv::countNonZero(readBand(dataset.get(), 2) == 255), 64 * 48);
  EXPECT_EQ(dataset->GetMetadataItem("EXOCET_MEAN_ALTITUDE_M"), nullptr);  // NaN: not written
}

TEST(TilesGeoTiff, SouthernHemisphereSydney) {
  // Sydney Harbour, -33.86 S 151.21 E: zone 56 south.
  double easting, northing;
  int zone;
  bool northern;
  GeographicLib::UTMUPS::Forward(-33.86, 151.21, zone, northern, easting, northing);
  ASSERT_EQ(zone, 56);
  ASSERT_FALSE(northern);
  TempDir dir;
  GeoTiffTileWriter writer(configFor(dir.path()));
  const TileRaster raster = makeRaster(400, 300, 56, false, std::floor(easting), std::floor(northing), 0.1);
  const WrittenTile tile = writer.write(raster, makeMetadata());
  ASSERT_TRUE(tile.ok) << tile.error;
  EXPECT_EQ(tile.epsg, 32756);
  DatasetPtr dataset = openDataset(tile.geotiff_path);
  ASSERT_TRUE(dataset);
  EXPECT_EQ(epsgOf(dataset.get()), 32756);
  double geotransform[6];
  ASSERT_EQ(dataset->GetGeoTransform(geotransform), CE_None);
  EXPECT_GT(geotransform[3], 6e6);
  EXPECT_GT(geotransform[3] + 300 * geotransform[5], 6e6);
  EXPECT_DOUBLE_EQ(geotransform[3], std::floor(northing));

  EXPECT_LT(tile.north_deg, 0.0);
  EXPECT_LT(tile.south_deg, tile.north_deg);
  EXPECT_NEAR(tile.north_deg, -33.86, 0.01);
  EXPECT_NEAR(tile.west_deg, 151.21, 0.01);
  for (const double e : {tile.min_easting_m, tile.max_easting_m}) {
    for (const double n : {tile.min_northing_m, tile.max_northing_m}) {
      double lat, lon;
      GeographicLib::UTMUPS::Reverse(56, false, e, n, lat, lon);
      EXPECT_LT(lat, 0.0);
      EXPECT_GE(lat, tile.south_deg - 1e-9);
      EXPECT_LE(lat, tile.north_deg + 1e-9);
      EXPECT_GE(lon, tile.west_deg - 1e-9);
      EXPECT_LE(lon, tile.east_deg + 1e-9);
    }
  }
  // A small tile: its box is the corners' box (the edges' curvature is negligible at 40 m).
  double lat_min = 90, lat_max = -90, lon_min = 180, lon_max = -180;
  for (const double e : {tile.min_easting_m, tile.max_easting_m}) {
    for (const double n : {tile.min_northing_m, tile.max_northing_m}) {
      double lat, lon;
      GeographicLib::UTMUPS::Reverse(56, false, e, n, lat, lon);
      lat_min = std::min(lat_min, lat), lat_max = std::max(lat_max, lat);
      lon_min = std::min(lon_min, lon), lon_max = std::max(lon_max, lon);
    }
  }
  EXPECT_NEAR(tile.south_deg, lat_min, 1e-8);
  EXPECT_NEAR(tile.north_deg, lat_max, 1e-8);
  EXPECT_NEAR(tile.west_deg, lon_min, 1e-8);
  EXPECT_NEAR(tile.east_deg, lon_max, 1e-8);
}

TEST(TilesGeoTiff, WorldFileMatchesGeoTransformWithHalfPixelShift) {
  TempDir dir;
  GeoTiffTileWriter writer(configFor(dir.path()));
  const WrittenTile tile = writer.write(makeRaster(120, 80, 32, true, 612345.125, 5123456.375, 0.025), TileMetadata());
  ASSERT_TRUE(tile.ok) << tile.error;
  ASSERT_EQ(tile.world_file_path, dir.path() + "/tile_0000.tfw");
  std::istringstream lines(readFile(tile.world_file_path));
  std::vector<double> values;
  for (std::string line; std::getline(lines, line);) values.push_back(std::stod(line));
  ASSERT_EQ(values.size(), 6u);
  DatasetPtr dataset = openDataset(tile.geotiff_path);
  ASSERT_TRUE(dataset);
  double gt[6];
  ASSERT_EQ(dataset->GetGeoTransform(gt), CE_None);
  EXPECT_DOUBLE_EQ(values[0], gt[1]);
  EXPECT_DOUBLE_EQ(values[1], gt[4]);
  EXPECT_DOUBLE_EQ(values[2], gt[2]);
  EXPECT_DOUBLE_EQ(values[3], gt[5]);
  EXPECT_DOUBLE_EQ(values[4], gt[0] + 0.5 * gt[1]);  // centre of the top-left pixel
  EXPECT_DOUBLE_EQ(values[5], gt[3] + 0.5 * gt[5]);
  EXPECT_DOUBLE_EQ(values[4], 612345.1375);

  // Without world file: none written.
  TileWriterConfig config = configFor(dir.path());
  config.write_world_file = false;
  GeoTiffTileWriter no_world(config);
  const WrittenTile second = no_world.write(makeRaster(16, 16, 32, true, 612345.0, 5123456.0), TileMetadata());
  ASSERT_TRUE(second.ok) << second.error;
  EXPECT_TRUE(second.world_file_path.empty());
  EXPECT_FALSE(fs::exists(dir.path() + "/tile_0001.tfw"));
}

TEST(TilesGeoTiff, ZoneBorderGivesDifferentEpsgAndTheSamePlace) {
  // 45 N 6 E is on the border of zones 31 and 32: the same point in both grids.
  TempDir dir;
  GeoTiffTileWriter writer(configFor(dir.path()));
  std::vector<WrittenTile> tiles;
  for (const int zone : {31, 32}) {
    double easting, northing, gamma, k;
    int zone_used;
    bool northern;
    GeographicLib::UTMUPS::Forward(45.0, 6.0, zone_used, northern, easting, northing, gamma, k, zone);
    ASSERT_EQ(zone_used, zone);
    tiles.push_back(writer.write(makeRaster(100, 100, zone, true, easting, northing, 0.05), TileMetadata()));
    ASSERT_TRUE(tiles.back().ok) << tiles.back().error;
  }
  EXPECT_EQ(tiles[0].epsg, 32631);
  EXPECT_EQ(tiles[1].epsg, 32632);
  EXPECT_EQ(epsgOf(openDataset(tiles[0].geotiff_path).get()), 32631);
  EXPECT_EQ(epsgOf(openDataset(tiles[1].geotiff_path).get()), 32632);
  // Both tiles start at the same point (their NW corner): their boxes' north-west agree to ~1 cm.
  EXPECT_NEAR(tiles[0].north_deg, 45.0, 1e-7);
  EXPECT_NEAR(tiles[1].north_deg, 45.0, 1e-3);
  EXPECT_NEAR(tiles[0].west_deg, 6.0, 1e-3);
  EXPECT_NEAR(tiles[1].west_deg, 6.0, 1e-7);
  EXPECT_EQ(epsgForUtm(0, true), 32661);
  EXPECT_EQ(epsgForUtm(0, false), 32761);
  EXPECT_EQ(epsgForUtm(1, false), 32701);
  EXPECT_EQ(epsgForUtm(60, true), 32660);
  EXPECT_THROW(epsgForUtm(61, true), std::invalid_argument);
}

TEST(TilesGeoTiff, UpsTileHoldingTheNorthPole) {
  TempDir dir;
  GeoTiffTileWriter writer(configFor(dir.path()));
  // UPS north: the pole is at (2000 km, 2000 km); the tile spans 1999990..2000010 m in both.
  const WrittenTile tile = writer.write(makeRaster(400, 400, 0, true, 1999990.0, 2000010.0), TileMetadata());
  ASSERT_TRUE(tile.ok) << tile.error;
  EXPECT_EQ(tile.epsg, 32661);
  EXPECT_EQ(epsgOf(openDataset(tile.geotiff_path).get()), 32661);
  EXPECT_DOUBLE_EQ(tile.north_deg, 90.0);
  EXPECT_DOUBLE_EQ(tile.west_deg, -180.0);
  EXPECT_DOUBLE_EQ(tile.east_deg, 180.0);
  EXPECT_NEAR(tile.south_deg, 90.0 - 10.0 * std::sqrt(2.0) / 111694.0, 2e-6);  // the corners, ~14 m from the pole
}

TEST(TilesGeoTiff, NeverOverwritesAndPicksTheNextIndex) {
  TempDir dir;
  {
    GeoTiffTileWriter writer(configFor(dir.path()));
    EXPECT_EQ(writer.nextIndex(), 0);
    const WrittenTile first = writer.write(makeRaster(32, 32, 31, true, 500000, 4800000), TileMetadata());
    const WrittenTile second = writer.write(makeRaster(32, 32, 31, true, 500000, 4800000), TileMetadata());
    ASSERT_TRUE(first.ok && second.ok) << first.error << second.error;
    EXPECT_EQ(first.index, 0);
    EXPECT_EQ(second.index, 1);
    EXPECT_EQ(second.geotiff_path, dir.path() + "/tile_0001.tif");
  }
  // A restart (new writer) continues after them.
  EXPECT_EQ(GeoTiffTileWriter(configFor(dir.path())).nextIndex(), 2);

  // A pre-existing tile_0000.tif (anything) is kept byte for byte.
  TempDir other;
  const std::string existing = other.path() + "/tile_0000.tif";
  { std::ofstream(existing, std::ios::binary) << "a tile from yesterday's dive\n"; }
  GeoTiffTileWriter writer(configFor(other.path()));
  EXPECT_EQ(writer.nextIndex(), 1);
  const WrittenTile tile = writer.write(makeRaster(32, 32, 31, true, 500000, 4800000), TileMetadata());
  ASSERT_TRUE(tile.ok) << tile.error;
  EXPECT_EQ(tile.index, 1);
  EXPECT_EQ(readFile(existing), "a tile from yesterday's dive\n");
  // A companion alone (e.g. a KMZ of an earlier run) also reserves its index.
  { std::ofstream(other.path() + "/tile_0002.kmz") << "x"; }
  EXPECT_EQ(writer.nextIndex(), 3);
  // Another prefix is independent.
  TileWriterConfig config = configFor(other.path());
  config.prefix = "dive7";
  EXPECT_EQ(GeoTiffTileWriter(config).nextIndex(), 0);
}

TEST(TilesGeoTiff, KilledMidWriteLeavesNoFinalFileAndStaleTemporariesAreRemoved) {
  TempDir dir;
  const std::string temporary = dir.path() + "/.tile_0000.tif.partial";
  bool caught = false;
  for (int attempt = 0; attempt < 5 && !caught; ++attempt) {
    const pid_t child = ::fork();
    ASSERT_GE(child, 0);
    if (child == 0) {
      // Large and incompressible, so that the write lasts seconds.
      TileRaster raster;
      raster.image.create(8000, 8000, CV_8UC3);
      cv::randu(raster.image, 0, 256);
      raster.gsd_m = 0.01;
      raster.origin_easting_m = 500000;
      raster.origin_northing_m = 4800000;
      raster.utm_zone = 31;
      GeoTiffTileWriter writer(configFor(dir.path()));
      const WrittenTile tile = writer.write(raster, TileMetadata());
      ::_exit(tile.ok ? 0 : 1);
    }
    // Wait for the temporary to appear, let the writer work on it a little, then kill it.
    for (int i = 0; i < 60000 && !fs::exists(temporary); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    std::this_thread::sleep_for(std::chrono::milliseconds(20 + 30 * attempt));
    ::kill(child, SIGKILL);
    int status = 0;
    ::waitpid(child, &status, 0);
    caught = WIFSIGNALED(status) && fs::exists(temporary);
    if (!caught) {
      for (const auto& name : filesIn(dir.path())) fs::remove(dir.path() + "/" + name);  // finished: try again
    }
  }
  ASSERT_TRUE(caught) << "the writer was never caught in the middle of a write";
  for (const char* final_name : {"tile_0000.tif", "tile_0000.tfw", "tile_0000.cog.tif", "tile_0000.kmz"}) {
    EXPECT_FALSE(fs::exists(dir.path() + "/" + final_name)) << final_name;
  }
  GeoTiffTileWriter writer(configFor(dir.path()));
  EXPECT_EQ(writer.nextIndex(), 0);
  // A stale temporary of another prefix is not ours to remove.
  { std::ofstream(dir.path() + "/.other_0000.tif.partial") << "x"; }
  EXPECT_GE(writer.removeStaleTemporaries(), 1);
  EXPECT_EQ(filesIn(dir.path()), (std::vector<std::string>{".other_0000.tif.partial"}));
  EXPECT_EQ(writer.removeStaleTemporaries(), 0);
}

TEST(TilesGeoTiff, UnwritableFolderGivesAClearErrorAndNoFile) {
  TempDir dir;
  const std::string file = dir.path() + "/not_a_folder";
  { std::ofstream(file) << "x"; }
  // Root ignores permissions, but not a path through a regular file.
  for (const std::string& folder : {file + "/tiles", file, dir.path() + "/missing"}) {
    GeoTiffTileWriter writer(configFor(folder));
    WrittenTile tile;
    EXPECT_NO_THROW(tile = writer.write(makeRaster(32, 32, 31, true, 500000, 4800000), TileMetadata()));
    EXPECT_FALSE(tile.ok);
    EXPECT_NE(tile.error.find(folder), std::string::npos) << tile.error;
    EXPECT_TRUE(tile.geotiff_path.empty());
    std::cout << "[ info     ] " << tile.error << "\n";
  }
  EXPECT_EQ(filesIn(dir.path()), (std::vector<std::string>{"not_a_folder"}));

  // A read-only file system (the same for root).
  const std::string mount_point = dir.path() + "/readonly";
  fs::create_directory(mount_point);
  if (::mount("tmpfs", mount_point.c_str(), "tmpfs", MS_RDONLY, "size=1m") != 0) {
    GTEST_SKIP() << "cannot mount a read-only tmpfs here: " << std::strerror(errno);
  }
  GeoTiffTileWriter writer(configFor(mount_point));
  const WrittenTile tile = writer.write(makeRaster(32, 32, 31, true, 500000, 4800000), TileMetadata());
  const auto files = filesIn(mount_point);
  ::umount(mount_point.c_str());
  EXPECT_FALSE(tile.ok);
  EXPECT_NE(tile.error.find(mount_point), std::string::npos) << tile.error;
  EXPECT_NE(tile.error.find("ead-only"), std::string::npos) << tile.error;
  EXPECT_TRUE(files.empty());
  std::cout << "[ info     ] " << tile.error << "\n";
}

TEST(TilesGeoTiff, FullDiskGivesAClearErrorAndNoFile) {
  TempDir dir;
  const std::string mount_point = dir.path() + "/small";
  fs::create_directory(mount_point);
  if (::mount("tmpfs", mount_point.c_str(), "tmpfs", 0, "size=1m") != 0) {
    GTEST_SKIP() << "cannot mount a 1 MB tmpfs here: " << std::strerror(errno);
  }
  TileWriterConfig config = configFor(mount_point);
  GeoTiffTileWriter writer(config);
  // 1200 x 1200 noise: about 4 MB even with DEFLATE.
  TileRaster raster = makeRaster(1200, 1200, 31, true, 500000, 4800000);
  cv::randu(raster.image, 0, 256);
  WrittenTile tile;
  EXPECT_NO_THROW(tile = writer.write(raster, TileMetadata()));
  const auto files_after_failure = filesIn(mount_point);
  // The folder is usable again once the failed tile's temporaries are gone: a small tile fits.
  const WrittenTile small = writer.write(makeRaster(32, 32, 31, true, 500000, 4800000), TileMetadata());
  const auto files_after_small = filesIn(mount_point);
  ::umount(mount_point.c_str());
  EXPECT_FALSE(tile.ok);
  EXPECT_NE(tile.error.find("No space left on device"), std::string::npos) << tile.error;
  EXPECT_NE(tile.error.find(mount_point), std::string::npos) << tile.error;
  EXPECT_TRUE(files_after_failure.empty());
  EXPECT_TRUE(small.ok) << small.error;
  EXPECT_EQ(small.index, 0);
  EXPECT_EQ(files_after_small, (std::vector<std::string>{"tile_0000.tfw", "tile_0000.tif"}));
  std::cout << "[ info     ] " << tile.error << "\n";
}

TEST(TilesGeoTiff, OverviewsAverageTheDataAndIgnoreTheNoDataColour) {
  // The overviews are filled from memory: each pixel of the first level is the mean colour of the pixels with data in
  // its 2x2 block (GDAL's AVERAGE with a mask) and the mean alpha; the colour under no-data never leaks in.
  TempDir dir;
  GeoTiffTileWriter writer(configFor(dir.path()));
  const TileRaster raster = makeRaster(1200, 900, 31, true, 500000.0, 4800000.0, 0.05);  // colour under no-data too
  const WrittenTile tile = writer.write(raster, makeMetadata());
  ASSERT_TRUE(tile.ok) << tile.error;
  DatasetPtr tif = openDataset(tile.geotiff_path);
  ASSERT_TRUE(tif);
  ASSERT_EQ(tif->GetRasterBand(1)->GetOverviewCount(), 3);  // 600, 300, 150 px wide: down to a 256 px block
  GDALRasterBand* first_level = tif->GetRasterBand(1)->GetOverview(0);
  ASSERT_EQ(first_level->GetXSize(), 600);
  ASSERT_EQ(first_level->GetYSize(), 450);
  std::vector<cv::Mat> levels;
  for (int band = 1; band <= 4; ++band) {
    cv::Mat out(450, 600, CV_8UC1);
    ASSERT_EQ(tif->GetRasterBand(band)->GetOverview(0)->RasterIO(GF_Read, 0, 0, 600, 450, out.data, 600, 450, GDT_Byte,
                                                                 0, 0, nullptr),
              CE_None);
    levels.push_back(out);
  }
  int checked_full = 0, checked_edge = 0, worst_colour = 0, worst_alpha = 0;
  for (int y = 0; y < 450; ++y) {
    for (int x = 0; x < 600; ++x) {
      double sum[3] = {0, 0, 0};
      int valid = 0;
      for (int dy = 0; dy < 2; ++dy) {
        for (int dx = 0; dx < 2; ++dx) {
          if (!raster.mask.at<uchar>(2 * y + dy, 2 * x + dx)) continue;
          const cv::Vec3b bgr = raster.image.at<cv::Vec3b>(2 * y + dy, 2 * x + dx);
          for (int c = 0; c < 3; ++c) sum[c] += bgr[2 - c];  // bands are R, G, B
          ++valid;
        }
      }
      worst_alpha = std::max(worst_alpha,
                             std::abs(levels[3].at<uchar>(y, x) - static_cast<int>(std::lround(255.0 * valid / 4.0))));
      if (valid == 0) continue;
      for (int c = 0; c < 3; ++c)
        worst_colour =
            std::max(worst_colour, std::abs(levels[c].at<uchar>(y, x) - static_cast<int>(std::lround(sum[c] / valid))));
      ++(valid == 4 ? checked_full : checked_edge);
    }
  }
  std::printf("overview: %d full and %d edge pixels, worst colour error %d, worst alpha error %d\n", checked_full,
              checked_edge, worst_colour, worst_alpha);
  EXPECT_GT(checked_edge, 100);
  EXPECT_LE(worst_alpha, 1);
  // The premultiplied 8-bit average rounds twice: a pixel covered by one of four carries up to 255 / 64 of it.
  EXPECT_LE(worst_colour, 4);
}

TEST(TilesGeoTiff, CogAndKmzOpenWithTheRightBounds) {
  TempDir dir;
  TileWriterConfig config = configFor(dir.path());
  config.write_cog = true;
  config.write_kmz = true;
  config.kmz_max_side_px = 512;  // the tile is 1200 px: the KMZ is downsampled
  GeoTiffTileWriter writer(config);
  const TileRaster raster = makeRaster(1200, 900, 31, true, 500000.0, 4800000.0, 0.05);
  const WrittenTile tile = writer.write(raster, makeMetadata());
  ASSERT_TRUE(tile.ok) << tile.error;
  EXPECT_EQ(tile.cog_path, dir.path() + "/tile_0000.cog.tif");
  EXPECT_EQ(tile.kmz_path, dir.path() + "/tile_0000.kmz");
  EXPECT_EQ(filesIn(dir.path()),
            (std::vector<std::string>{"tile_0000.cog.tif", "tile_0000.kmz", "tile_0000.tfw", "tile_0000.tif"}));

  DatasetPtr tif = openDataset(tile.geotiff_path);
  ASSERT_TRUE(tif);
  EXPECT_GT(tif->GetRasterBand(1)->GetOverviewCount(), 0);  // > 1024 px: overviews
  const char* tif_layout = tif->GetMetadataItem("LAYOUT", "IMAGE_STRUCTURE");
  EXPECT_TRUE(tif_layout == nullptr || std::string(tif_layout) != "COG");  // the COG is a different file

  DatasetPtr cog = openDataset(tile.cog_path);
  ASSERT_TRUE(cog);
  ASSERT_NE(cog->GetMetadataItem("LAYOUT", "IMAGE_STRUCTURE"), nullptr);
  EXPECT_STREQ(cog->GetMetadataItem("LAYOUT", "IMAGE_STRUCTURE"), "COG");
  EXPECT_EQ(cog->GetRasterCount(), 4);
  EXPECT_EQ(epsgOf(cog.get()), 32631);
  double gt_cog[6], gt_tif[6];
  ASSERT_EQ(cog->GetGeoTransform(gt_cog), CE_None);
  ASSERT_EQ(tif->GetGeoTransform(gt_tif), CE_None);
  for (int i = 0; i < 6; ++i) EXPECT_DOUBLE_EQ(gt_cog[i], gt_tif[i]);
  EXPECT_EQ(countDifferent(readBand(cog.get(), 1), readBand(tif.get(), 1)), 0);
  EXPECT_EQ(countDifferent(readBand(cog.get(), 4), raster.mask), 0);

  // The KMZ holds a KML with a LatLonBox, and GDAL opens it in WGS 84 with the tile's bounds.
  const std::string kml_path = "/vsizip/" + tile.kmz_path + "/doc.kml";
  VSIStatBufL stat_buffer;
  ASSERT_EQ(VSIStatL(kml_path.c_str(), &stat_buffer), 0) << "no doc.kml in the KMZ";
  DatasetPtr kmz = openDataset(tile.kmz_path);
  ASSERT_TRUE(kmz) << "GDAL cannot open the KMZ";
  EXPECT_EQ(epsgOf(kmz.get()), 4326);
  double gt_kmz[6];
  ASSERT_EQ(kmz->GetGeoTransform(gt_kmz), CE_None);
  const double west = gt_kmz[0], north = gt_kmz[3];
  const double east = west + kmz->GetRasterXSize() * gt_kmz[1];
  const double south = north + kmz->GetRasterYSize() * gt_kmz[5];
  const double pixel_deg = std::abs(gt_kmz[1]) + std::abs(gt_kmz[5]);
  EXPECT_NEAR(west, tile.west_deg, pixel_deg);
  EXPECT_NEAR(east, tile.east_deg, pixel_deg);
  EXPECT_NEAR(south, tile.south_deg, pixel_deg);
  EXPECT_NEAR(north, tile.north_deg, pixel_deg);
  EXPECT_LE(std::max(kmz->GetRasterXSize(), kmz->GetRasterYSize()), 512 + 1);
  ASSERT_EQ(kmz->GetRasterCount(), 4);
  // No data stays transparent: the left no-data strip (13 px of 1200) has alpha 0 at the KMZ's left edge.
  const cv::Mat kmz_alpha = readBand(kmz.get(), 4);
  EXPECT_EQ(kmz_alpha.at<uchar>(kmz_alpha.rows / 4, 0), 0);
  EXPECT_EQ(kmz_alpha.at<uchar>(kmz_alpha.rows / 4, kmz_alpha.cols / 4), 255);
}

TEST(TilesGeoTiff, AGreyTileHasItsKmzInGreyRgba) {
  // A monochrome camera's tile: grey and alpha, two bands, which GDAL's KML super-overlay driver refuses silently.
  TempDir dir;
  TileWriterConfig config = configFor(dir.path());
  config.write_kmz = true;
  GeoTiffTileWriter writer(config);
  TileRaster raster = makeRaster(400, 300, 31, true, 500000.0, 4800000.0, 0.05);
  cv::cvtColor(raster.image, raster.image, cv::COLOR_BGR2GRAY);
  const WrittenTile tile = writer.write(raster, makeMetadata());
  ASSERT_TRUE(tile.ok) << tile.error;
  DatasetPtr kmz = openDataset(tile.kmz_path);
  ASSERT_TRUE(kmz) << "GDAL cannot open the KMZ";
  ASSERT_EQ(kmz->GetRasterCount(), 4);
  const cv::Mat red = readBand(kmz.get(), 1), green = readBand(kmz.get(), 2), blue = readBand(kmz.get(), 3);
  EXPECT_EQ(cv::norm(red, green, cv::NORM_INF), 0.0);  // grey: the three colour bands are the same
  EXPECT_EQ(cv::norm(red, blue, cv::NORM_INF), 0.0);
  EXPECT_GT(cv::norm(red, cv::NORM_INF), 0.0);
  const cv::Mat alpha = readBand(kmz.get(), 4);
  EXPECT_EQ(alpha.at<uchar>(alpha.rows / 4, 0), 0);  // the no-data strip stays transparent
  EXPECT_EQ(alpha.at<uchar>(alpha.rows / 4, alpha.cols / 4), 255);
}

TEST(TilesGeoTiff, ACompanionThatCannotBeWrittenIsLeftOutAndTheTileIsStillWritten) {
  // A directory in the way of the KMZ's temporary: GDAL cannot create the KMZ. The GeoTIFF (the product) and the
  // COG are still written and committed; the KMZ is reported and leaves no partial file.
  TempDir dir;
  TileWriterConfig config = configFor(dir.path());
  config.write_cog = true;
  config.write_kmz = true;
  GeoTiffTileWriter writer(config);
  const std::string blocker = dir.path() + "/.tile_0000.partial.kmz";
  ASSERT_EQ(::mkdir(blocker.c_str(), 0755), 0);
  const WrittenTile tile = writer.write(makeRaster(400, 300, 31, true, 500000.0, 4800000.0, 0.05), makeMetadata());
  ASSERT_TRUE(tile.ok) << tile.error;
  ASSERT_EQ(tile.companion_errors.size(), 1u);
  EXPECT_EQ(tile.companion_errors[0].rfind("KMZ: ", 0), 0u) << tile.companion_errors[0];
  EXPECT_NE(tile.companion_errors[0].find(".tile_0000.partial.kmz"), std::string::npos) << tile.companion_errors[0];
  EXPECT_TRUE(tile.kmz_path.empty());
  EXPECT_EQ(tile.cog_path, dir.path() + "/tile_0000.cog.tif");
  EXPECT_TRUE(openDataset(tile.geotiff_path)) << "GDAL cannot open the GeoTIFF";
  EXPECT_TRUE(openDataset(tile.cog_path)) << "GDAL cannot open the COG";
  ::rmdir(blocker.c_str());
  EXPECT_EQ(filesIn(dir.path()), (std::vector<std::string>{"tile_0000.cog.tif", "tile_0000.tfw", "tile_0000.tif"}));

  // The next tile, with nothing in the way, has all its files again.
  const WrittenTile next = writer.write(makeRaster(400, 300, 31, true, 500020.0, 4800000.0, 0.05), makeMetadata());
  ASSERT_TRUE(next.ok) << next.error;
  EXPECT_TRUE(next.companion_errors.empty());
  EXPECT_FALSE(next.kmz_path.empty());
}

TEST(TilesGeoTiff, LocalFrameTileHasAnEngineeringCrsInMetresAndNoWgs84Box) {
  TempDir dir;
  TileWriterConfig config = configFor(dir.path());
  config.write_cog = true;
  config.write_kmz = true;  // no KMZ in a local frame: it would need WGS 84
  GeoTiffTileWriter writer(config);
  TileRaster raster = makeRaster(300, 200, 0, true, -12.5, 40.0, 0.02);
  raster.utm_zone = 99;  // ignored in a local frame
  raster.local_frame = "map";
  const WrittenTile tile = writer.write(raster, makeMetadata());
  ASSERT_TRUE(tile.ok) << tile.error;
  EXPECT_EQ(tile.epsg, 0);
  EXPECT_EQ(tile.local_frame, "map");
  EXPECT_TRUE(tile.kmz_path.empty());
  EXPECT_TRUE(std::isnan(tile.west_deg) && std::isnan(tile.north_deg));
  EXPECT_DOUBLE_EQ(tile.min_easting_m, -12.5);
  EXPECT_DOUBLE_EQ(tile.max_easting_m, -12.5 + 300 * 0.02);
  EXPECT_DOUBLE_EQ(tile.min_northing_m, 40.0 - 200 * 0.02);
  EXPECT_EQ(filesIn(dir.path()), (std::vector<std::string>{"tile_0000.cog.tif", "tile_0000.tfw", "tile_0000.tif"}));

  for (const std::string& path : {tile.geotiff_path, tile.cog_path}) {
    DatasetPtr dataset = openDataset(path);
    ASSERT_TRUE(dataset) << path;
    const OGRSpatialReference* srs = dataset->GetSpatialRef();
    ASSERT_NE(srs, nullptr) << path << ": no CRS";
    EXPECT_TRUE(srs->IsLocal()) << path;
    EXPECT_FALSE(srs->IsGeographic() || srs->IsProjected()) << path;
    EXPECT_DOUBLE_EQ(srs->GetLinearUnits(), 1.0) << path;  // metres
    ASSERT_NE(srs->GetName(), nullptr);
    EXPECT_NE(std::string(srs->GetName()).find("'map'"), std::string::npos) << srs->GetName();
    double gt[6];
    ASSERT_EQ(dataset->GetGeoTransform(gt), CE_None);
    EXPECT_DOUBLE_EQ(gt[0], -12.5);
    EXPECT_DOUBLE_EQ(gt[1], 0.02);
    EXPECT_DOUBLE_EQ(gt[3], 40.0);
    EXPECT_DOUBLE_EQ(gt[5], -0.02);
  }
  EXPECT_NE(readFile(tile.world_file_path).find("-12.49"), std::string::npos);  // centre of the top-left pixel
}

TEST(TilesGeoTiff, JpegKeepsTheMaskAsAnInternalMask) {
  TempDir dir;
  TileWriterConfig config = configFor(dir.path());
  config.compression = "JPEG";
  GeoTiffTileWriter writer(config);
  TileRaster raster = makeRaster(256, 192, 31, true, 500000.0, 4800000.0);
  cv::GaussianBlur(raster.image, raster.image, cv::Size(0, 0), 3.0);  // JPEG is for smooth images
  const WrittenTile tile = writer.write(raster, TileMetadata());
  ASSERT_TRUE(tile.ok) << tile.error;
  EXPECT_EQ(filesIn(dir.path()), (std::vector<std::string>{"tile_0000.tfw", "tile_0000.tif"}));  // no .msk
  DatasetPtr dataset = openDataset(tile.geotiff_path);
  ASSERT_TRUE(dataset);
  ASSERT_EQ(dataset->GetRasterCount(), 3);
  EXPECT_STREQ(dataset->GetMetadataItem("COMPRESSION", "IMAGE_STRUCTURE"), "YCbCr JPEG");
  GDALRasterBand* band = dataset->GetRasterBand(1);
  EXPECT_EQ(band->GetMaskFlags(), GMF_PER_DATASET);
  cv::Mat mask(192, 256, CV_8UC1);
  ASSERT_EQ(band->GetMaskBand()->RasterIO(GF_Read, 0, 0, 256, 192, mask.data, 256, 192, GDT_Byte, 0, 0, nullptr),
            CE_None);
  EXPECT_EQ(countDifferent(mask, raster.mask), 0);
  std::vector<cv::Mat> bgr;
  cv::split(raster.image, bgr);
  cv::Mat red_error;
  cv::absdiff(readBand(dataset.get(), 1), bgr[2], red_error);
  EXPECT_LT(cv::mean(red_error, raster.mask)[0], 6.0);  // lossy, but the red band is the red channel
}

TEST(TilesGeoTiff, OverviewsAboveOneThousandPixels) {
  TempDir dir;
  GeoTiffTileWriter writer(configFor(dir.path()));
  const WrittenTile large = writer.write(makeRaster(1100, 300, 31, true, 500000, 4800000), TileMetadata());
  const WrittenTile small = writer.write(makeRaster(1024, 1024, 31, true, 500000, 4800000), TileMetadata());
  ASSERT_TRUE(large.ok && small.ok) << large.error << small.error;
  DatasetPtr large_ds = openDataset(large.geotiff_path);
  DatasetPtr small_ds = openDataset(small.geotiff_path);
  ASSERT_TRUE(large_ds && small_ds);
  GDALRasterBand* band = large_ds->GetRasterBand(1);
  ASSERT_EQ(band->GetOverviewCount(), 3);  // 550, 275 -> 138 <= 256
  EXPECT_EQ(band->GetOverview(0)->GetXSize(), 550);
  EXPECT_EQ(band->GetOverview(2)->GetXSize(), 138);
  EXPECT_EQ(small_ds->GetRasterBand(1)->GetOverviewCount(), 0);
}

TEST(TilesGeoTiff, InvalidConfigurationAndRasterAreReported) {
  TileWriterConfig config;
  config.output_dir = "";
  config.prefix = "../x";
  config.compression = "ZSTD9";
  config.block_size_px = 100;
  config.kmz_max_side_px = 10;
  config.deflate_level = 0;
  const std::string error = config.validate();
  for (const char* field :
       {"output_dir", "prefix", "compression", "deflate_level", "block_size_px", "kmz_max_side_px"}) {
    EXPECT_NE(error.find(field), std::string::npos) << field << " not in: " << error;
  }
  EXPECT_THROW(GeoTiffTileWriter{config}, std::invalid_argument);
  EXPECT_EQ(TileWriterConfig{"/tmp"}.validate(), "");

  TempDir dir;
  GeoTiffTileWriter writer(configFor(dir.path()));
  TileRaster raster = makeRaster(32, 32, 31, true, 500000, 4800000);
  raster.image.convertTo(raster.image, CV_16UC3);
  raster.gsd_m = 0.0;
  raster.utm_zone = 61;
  const WrittenTile tile = writer.write(raster, TileMetadata());
  EXPECT_FALSE(tile.ok);
  for (const char* what : {"image type", "gsd_m", "utm_zone"}) {
    EXPECT_NE(tile.error.find(what), std::string::npos) << what << " not in: " << tile.error;
  }
  EXPECT_TRUE(filesIn(dir.path()).empty());
}

TEST(TilesGeoTiff, WriteTimeOf4000PxRgbDeflate) {
  // Real seabed texture (the Sparus AUV frames, tiled) when available: DEFLATE's speed depends on the content.
  cv::Mat image(4000, 4000, CV_8UC3);
  std::vector<cv::Mat> frames;
  for (int i = 0;; ++i) {
    std::ostringstream name;
    name << exocet_common::testing::sharedDataDir() << "/sparus_auv/frames/frame_" << std::setw(4) << std::setfill('0')
         << i << ".png";
    if (!fs::exists(name.str())) break;
    frames.push_back(cv::imread(name.str(), cv::IMREAD_COLOR));
  }
  std::string content = "Sparus AUV frames";
  if (frames.empty() || frames[0].empty()) {
    cv::randn(image, cv::Scalar::all(120), cv::Scalar::all(40));
    cv::GaussianBlur(image, image, cv::Size(0, 0), 1.5);
    content = "blurred noise";
  } else {
    int k = 0;
    for (int y = 0; y < image.rows; y += frames[0].rows) {
      for (int x = 0; x < image.cols; x += frames[0].cols, ++k) {
        const cv::Mat& frame = frames[k % frames.size()];
        const cv::Rect roi = cv::Rect(x, y, frame.cols, frame.rows) & cv::Rect(0, 0, image.cols, image.rows);
        frame(cv::Rect(0, 0, roi.width, roi.height)).copyTo(image(roi));
      }
    }
  }
  TempDir dir;
  TileRaster raster = makeRaster(16, 16, 31, true, 500000, 4800000);
  raster.image = image;
  raster.mask = patternMask(4000, 4000);
  for (const int level : {1, 6}) {
    TileWriterConfig config = configFor(dir.path());
    config.deflate_level = level;
    GeoTiffTileWriter writer(config);
    const WrittenTile tile = writer.write(raster, TileMetadata());
    ASSERT_TRUE(tile.ok) << tile.error;
    const auto bytes = fs::file_size(tile.geotiff_path);
    std::cout << "[ info     ] 4000x4000 RGB + alpha, DEFLATE level " << level << ", overviews (" << content
              << "): " << tile.write_ms << " ms, " << bytes / 1e6 << " MB\n";
    EXPECT_GT(bytes, 1000u);
  }
}
