// A tile writer's run carried over restarts (tiles/tile_writer_resume.h): the progress file, the rule that decides
// whether a run is carried on, the records read back at the version on disk, the clean-up after a kill; and a writer
// killed at random moments of a stream of tiles leaves only complete tiles under final names, with no index skipped.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <gdal_priv.h>
#include <opencv2/core.hpp>

#include "exocet_common/json_file.h"
#include "exocet_common/testing/temp_dir.h"
#include "exocet_mosaic/tiles/geotiff_tile_writer.h"
#include "exocet_mosaic/tiles/tile_writer_resume.h"

namespace {

namespace fs = std::filesystem;
using namespace exocet_mosaic::tiles;
using TempDir = exocet_common::testing::TempDir;

TileWriterConfig configFor(const std::string& folder) {
  TileWriterConfig config;
  config.output_dir = folder;
  return config;
}

TileRaster smallRaster(int side_px = 32) {
  TileRaster raster;
  raster.image.create(side_px, side_px, CV_8UC3);
  cv::randu(raster.image, 0, 256);
  raster.gsd_m = 0.01;
  raster.origin_easting_m = 500000;
  raster.origin_northing_m = 4800000;
  raster.utm_zone = 31;
  return raster;
}

TileRecord recordOf(int index, int version) {
  TileRecord record;
  record.index = index;
  record.version = version;
  record.gsd_m = 0.01;
  record.utm_zone = 31;
  RecordedImage image;
  image.frame = 10 * index;
  image.stamp_s = 1000.0 + index;
  image.file = recordedImageName("tile", image.stamp_s);
  image.width_px = image.height_px = 32;
  record.images.push_back(image);
  return record;
}

void saveRecord(const std::string& folder, const GeoTiffTileWriter& writer, const TileRecord& record) {
  exocet_common::writeJsonFileAtomically(folder + "/" + writer.baseName(record.index) + ".json",
                                         tileRecordToJson(record));
}

std::set<std::string> filesIn(const std::string& folder) {
  std::set<std::string> names;
  for (const auto& entry : fs::directory_iterator(folder)) names.insert(entry.path().filename().string());
  return names;
}

}  // namespace

TEST(TilesResume, ProgressReadsBackAndBadFilesAreRefused) {
  TileWriterProgress p;
  p.next_frame = 421;
  p.frames_not_on_disk = 37;
  p.newest_stamp_s = 1780300842.4;
  p.tiles_written = 3;
  p.images_received = 419;
  p.frames_composed = 70;
  p.frames_lost = 12;
  p.restarts = 2;
  p.finished = true;
  const TileWriterProgress back = tileWriterProgressFromJson(tileWriterProgressToJson(p));
  EXPECT_EQ(back.next_frame, 421);
  EXPECT_EQ(back.frames_not_on_disk, 37);
  EXPECT_DOUBLE_EQ(back.newest_stamp_s, 1780300842.4);
  EXPECT_EQ(back.tiles_written, 3);
  EXPECT_EQ(back.images_received, 419);
  EXPECT_EQ(back.frames_composed, 70);
  EXPECT_EQ(back.frames_lost, 12);
  EXPECT_EQ(back.restarts, 2);
  EXPECT_TRUE(back.finished);

  nlohmann::json missing = tileWriterProgressToJson(p);
  missing.erase("next_frame");
  try {
    tileWriterProgressFromJson(missing);
    ADD_FAILURE() << "a progress without next_frame was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("next_frame"), std::string::npos) << e.what();
  }
  nlohmann::json negative = tileWriterProgressToJson(p);
  negative["frames_not_on_disk"] = -3;
  EXPECT_THROW(tileWriterProgressFromJson(negative), std::invalid_argument);
  EXPECT_THROW(tileWriterProgressFromJson(nlohmann::json::array()), std::invalid_argument);
  EXPECT_EQ(tileWriterProgressPath("/data/tiles", "dive"), "/data/tiles/.exocet_dive_progress.json");
}

TEST(TilesResume, ARunIsCarriedOnWhenTheImagesContinueItsStamps) {
  TileWriterProgress previous;
  previous.newest_stamp_s = 5000.0;
  EXPECT_EQ(continuationRefusal(previous, 5003.0, 600.0), "") << "a restart: the next images";
  EXPECT_EQ(continuationRefusal(previous, 4999.5, 600.0), "") << "an image in flight at the crash";
  previous.finished = true;
  EXPECT_EQ(continuationRefusal(previous, 5003.0, 600.0), "") << "a writer that ended mid-bag and was started again";
  const std::string replayed = continuationRefusal(previous, 4100.0, 600.0);
  EXPECT_NE(replayed.find("before"), std::string::npos) << replayed;
  const std::string later = continuationRefusal(previous, 9000.0, 600.0);
  EXPECT_NE(later.find("another dive"), std::string::npos) << later;
  EXPECT_NE(continuationRefusal(previous, std::nan(""), 600.0), "");
}

TEST(TilesResume, RecordsFollowTheNewestCompleteVersionOnDisk) {
  TempDir dir;
  const std::string records_dir = dir.path() + "/.exocet_images";
  fs::create_directories(records_dir);
  GeoTiffTileWriter writer(configFor(dir.path()));
  for (int index = 0; index < 3; ++index) ASSERT_TRUE(writer.write(smallRaster(), TileMetadata()).ok);
  // Tile 1: redrawn as version 2, killed before version 1 was removed and before its record was saved.
  ASSERT_TRUE(writer.writeVersion(smallRaster(), TileMetadata(), 1, 2).ok);
  // Tile 2: redrawn as version 2, version 1 removed, killed before its record was saved.
  ASSERT_TRUE(writer.writeVersion(smallRaster(), TileMetadata(), 2, 2).ok);
  ASSERT_EQ(writer.removeVersion(2, 1), 2);
  for (int index = 0; index < 4; ++index) saveRecord(records_dir, writer, recordOf(index, 1));  // 3: its tile is gone
  { std::ofstream(records_dir + "/tile_0009.json") << "{ not json"; }
  { std::ofstream(records_dir + "/other_0000.json") << "{}"; }  // another prefix: not ours

  const KeptTiles kept = loadKeptTiles(records_dir, writer);
  ASSERT_EQ(kept.records.size(), 3u);
  EXPECT_EQ(kept.records[0].index, 0);
  EXPECT_EQ(kept.records[0].version, 1);
  EXPECT_EQ(kept.records[1].index, 1);
  EXPECT_EQ(kept.records[1].version, 2);
  EXPECT_EQ(kept.records[2].index, 2);
  EXPECT_EQ(kept.records[2].version, 2);
  EXPECT_EQ(kept.records[1].images.size(), 1u);
  EXPECT_EQ(kept.unreadable, 2) << "tile 3 is gone, tile 9's record is not JSON";
  EXPECT_EQ(kept.versions_removed, 1);
  EXPECT_EQ(kept.problems.size(), 2u);
  const std::set<std::string> left = filesIn(dir.path());
  EXPECT_TRUE(left.count("tile_0001_v2.tif") && !left.count("tile_0001.tif")) << "the older version goes";
  EXPECT_TRUE(left.count("tile_0000.tif") && left.count("tile_0002_v2.tif"));
  EXPECT_EQ(writer.nextIndex(), 3);
}

TEST(TilesResume, CompanionsOfAnUnrenamedGeoTiffAndTemporariesAreRemoved) {
  TempDir dir;
  GeoTiffTileWriter writer(configFor(dir.path()));
  ASSERT_TRUE(writer.write(smallRaster(), TileMetadata()).ok);
  // A kill between the renames of tile 1 (the GeoTIFF goes last): its world file is there, its GeoTIFF is not.
  { std::ofstream(dir.path() + "/tile_0001.tfw") << "0.01\n0\n0\n-0.01\n500000\n4800000\n"; }
  { std::ofstream(dir.path() + "/tile_0002_v3.kmz") << "x"; }
  { std::ofstream(dir.path() + "/tile_notes.tfw") << "x"; }  // not a tile name: left alone
  EXPECT_EQ(writer.nextIndex(), 3) << "the orphans hold indices 1 and 2";
  EXPECT_EQ(writer.removeIncompleteTiles(), 2);
  EXPECT_EQ(writer.nextIndex(), 1) << "no index skipped";
  EXPECT_EQ(filesIn(dir.path()), (std::set<std::string>{"tile_0000.tfw", "tile_0000.tif", "tile_notes.tfw"}));
  EXPECT_EQ(writer.removeIncompleteTiles(), 0);

  const std::string images = dir.path() + "/.exocet_images";
  fs::create_directories(images);
  { std::ofstream(images + "/.tile_1000000000000.jpg.partial-123") << "x"; }
  { std::ofstream(images + "/.tile_0001.json.partial-123") << "x"; }
  { std::ofstream(images + "/tile_1000000000000.jpg") << "x"; }
  EXPECT_EQ(removeTemporariesIn(images), 2);
  EXPECT_EQ(filesIn(images), (std::set<std::string>{"tile_1000000000000.jpg"}));
}

TEST(TilesResume, GraphCorrectionsReadBack) {
  TempDir dir;
  const std::string path = dir.file("graph_corrections.csv");
  { std::ofstream(path) << "stamp_s,east_m,north_m\n10.5,0.1,-0.2\n11.0,0.3,0.4\n10.9,1,1\n"; }
  int left_out = -1;
  const PositionCorrectionTrack track = readPositionCorrections(path, &left_out);
  EXPECT_EQ(track.size(), 2u);
  EXPECT_EQ(left_out, 1) << "out of time order";
  EXPECT_NEAR(track.at(10.75).x(), 0.2, 1e-12);
  { std::ofstream(path) << "time,e,n\n"; }
  EXPECT_THROW(readPositionCorrections(path, nullptr), std::invalid_argument);
  EXPECT_THROW(readPositionCorrections(dir.file("missing.csv"), nullptr), std::invalid_argument);
}

// A writer killed at random moments of a stream of tiles, restarted each time as the node restarts it: every file
// under a final name is a complete tile (GDAL reads it, its world file beside it), and the indices run without a gap.
TEST(TilesResume, WriterKilledAtRandomMomentsLeavesOnlyCompleteTilesAndNoIndexGap) {
  TempDir dir;
  std::mt19937 random(7);
  std::uniform_int_distribution<int> delay_ms(5, 400);
  int kills = 0;
  for (int round = 0; round < 8; ++round) {
    {
      // What the node does at start-up.
      GeoTiffTileWriter writer(configFor(dir.path()));
      writer.removeStaleTemporaries();
      writer.removeIncompleteTiles();
    }
    const pid_t child = ::fork();
    ASSERT_GE(child, 0);
    if (child == 0) {
      GeoTiffTileWriter writer(configFor(dir.path()));
      for (int i = 0; i < 1000; ++i)
        if (!writer.write(smallRaster(700), TileMetadata()).ok) ::_exit(1);
      ::_exit(0);
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(delay_ms(random)));
    ::kill(child, SIGKILL);
    int status = 0;
    ::waitpid(child, &status, 0);
    kills += WIFSIGNALED(status) ? 1 : 0;
  }
  EXPECT_EQ(kills, 8);
  GeoTiffTileWriter writer(configFor(dir.path()));
  writer.removeStaleTemporaries();
  writer.removeIncompleteTiles();
  GDALAllRegister();
  const std::set<std::string> files = filesIn(dir.path());
  int tiles = 0;
  for (int index = 0;; ++index) {
    const std::string base = writer.baseName(index);
    if (!files.count(base + ".tif")) break;
    ++tiles;
    EXPECT_TRUE(files.count(base + ".tfw")) << base;
    GDALDataset* dataset = static_cast<GDALDataset*>(GDALOpen(dir.file(base + ".tif").c_str(), GA_ReadOnly));
    ASSERT_NE(dataset, nullptr) << base;
    EXPECT_EQ(dataset->GetRasterXSize(), 700);
    cv::Mat band(700, 700, CV_8UC1);
    EXPECT_EQ(dataset->GetRasterBand(1)->RasterIO(GF_Read, 0, 0, 700, 700, band.data, 700, 700, GDT_Byte, 0, 0),
              CE_None)
        << base;
    GDALClose(dataset);
  }
  EXPECT_GE(tiles, 1);
  // Nothing else: no partial file, no orphan, no index after a gap.
  EXPECT_EQ(files.size(), static_cast<std::size_t>(2 * tiles));
  EXPECT_EQ(writer.nextIndex(), tiles);
  std::cout << "[ info     ] " << kills << " kills, " << tiles << " complete tiles" << std::endl;
}
