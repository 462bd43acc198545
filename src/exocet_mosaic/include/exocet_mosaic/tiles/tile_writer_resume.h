/**
 * @file tile_writer_resume.h
 * @brief What a tile writer keeps on disk about its run so that an instance restarted after a crash (SIGKILL, a
 * respawn) carries the same run on in the same folder: a small progress file updated at each tile and every second,
 * the records of the written tiles (tile_revisions.h) read back at their version on disk, and the clean-up of what an
 * interrupted write left behind. No ROS in it.
 */
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "exocet_mosaic/tiles/geotiff_tile_writer.h"
#include "exocet_mosaic/tiles/tile_revisions.h"

namespace exocet_mosaic {
namespace tiles {

/// A run's progress: each instance of the writer saves it; the next instance reads it when it starts.
struct TileWriterProgress {
  int next_frame = 0;  ///< index the next image takes (frames numbered across the run's instances)
  /// Frames received but in no tile on disk yet: the open mosaic, the images waiting for their pose, closed mosaics
  /// not written. What a crash at that moment loses.
  int frames_not_on_disk = 0;
  double newest_stamp_s = 0.0;       ///< stamp of the newest image received (s)
  std::int64_t tiles_written = 0;    ///< by every instance of the run
  std::int64_t images_received = 0;  ///< by every instance of the run
  std::int64_t frames_composed = 0;  ///< by every instance of the run
  std::int64_t frames_lost = 0;      ///< frames lost by the run's crashes (frames_not_on_disk at each)
  int restarts = 0;                  ///< instances that carried the run on after a crash
  /// The instance ended normally (everything it held flushed): nothing was lost, and an instance that receives no
  /// image leaves the run's summary as it is.
  bool finished = false;
};

nlohmann::json tileWriterProgressToJson(const TileWriterProgress& progress);
/// @throws std::invalid_argument naming the missing or bad field.
TileWriterProgress tileWriterProgressFromJson(const nlohmann::json& json);

/// "<output_dir>/.exocet_<prefix>_progress.json"
std::string tileWriterProgressPath(const std::string& output_dir, const std::string& prefix);

/// How far before the newest image of an interrupted run the first image may be stamped and the run still be carried
/// on (s): images in flight at the crash.
constexpr double kContinuationBackToleranceS = 1.0;

/**
 * @brief Why the run `previous` left in the folder must not be carried on by an instance whose first image is stamped
 * `first_image_stamp_s`; empty when it may (whether that instance ended normally or not: a writer that stopped mid-bag
 * and was started again carries the same run on). A run whose images are stamped later than the first image by more
 * than kContinuationBackToleranceS was another replay (a bag played again from its start); one whose newest image is
 * more than `max_gap_s` older was another dive.
 */
std::string continuationRefusal(const TileWriterProgress& previous, double first_image_stamp_s, double max_gap_s);

/// The records of the tiles an interrupted run wrote, as loadKeptTiles() found them.
struct KeptTiles {
  std::vector<TileRecord> records;    ///< by index, each at the version on disk
  int unreadable = 0;                 ///< records left out: not readable, or their tile is gone
  int versions_removed = 0;           ///< older versions an interrupted redraw left beside the newer one
  std::vector<std::string> problems;  ///< what was left out and why, one line each
};

/**
 * @brief Reads the records "<prefix>_NNNN.json" of `records_dir` (the writer's .exocet_images) and checks each
 * against the tiles in the writer's folder: a record follows its tile's newest complete version on disk (a redraw
 * killed after writing version K + 1 but before removing K, or before saving the record), the older version's files
 * are removed; a record whose tile is gone is left out.
 */
KeptTiles loadKeptTiles(const std::string& records_dir, const GeoTiffTileWriter& writer);

/// Removes the temporaries ("*.partial*") a killed writer left in `folder` (e.g. the kept images' folder); returns
/// how many it removed.
int removeTemporariesIn(const std::string& folder);

/// The graph corrections the tile writer saves ("stamp_s,east_m,north_m" CSV). @param left_out pairs left out (not
/// finite or not in time order), may be null. @throws std::invalid_argument naming the file and the bad line.
PositionCorrectionTrack readPositionCorrections(const std::string& path, int* left_out);

}  // namespace tiles
}  // namespace exocet_mosaic
