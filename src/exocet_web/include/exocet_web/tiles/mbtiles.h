/**
 * @file mbtiles.h
 * @brief Packs a folder of web tiles (<z>/<x>/<y>.png, XYZ) into one MBTiles file (SQLite, MBTiles 1.3: TMS rows),
 * the raster format QGIS, GDAL and most tile servers open as one layer. No ROS in it.
 */
#pragma once

#include <string>

#include "exocet_web/tiles/web_mercator.h"

namespace exocet_web {
namespace tiles {

/// The metadata table of the MBTiles file.
struct MbtilesInfo {
  std::string name = "Exocet mosaic";  ///< the layer's name (e.g. the dive's)
  std::string description;
  LatLonBox bounds;  ///< WGS 84 extent; a box with west >= east is computed from the tiles
};

/// What exportMbtiles() did.
struct MbtilesResult {
  bool ok = false;
  std::string error;  ///< what failed (SQLite's message, the file), when !ok
  int tiles = 0;      ///< tiles packed
  int min_zoom = -1, max_zoom = -1;
};

/**
 * @brief Writes every <z>/<x>/<y>.png of `tiles_dir` into `output_path` (tables metadata and tiles, a unique index
 * on the tile coordinates), under a temporary name first and renamed over any previous file: a reader never sees half
 * an export. Never throws.
 */
MbtilesResult exportMbtiles(const std::string& tiles_dir, const std::string& output_path, const MbtilesInfo& info);

}  // namespace tiles
}  // namespace exocet_web
