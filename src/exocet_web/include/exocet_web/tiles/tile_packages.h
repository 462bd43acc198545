/**
 * @file tile_packages.h
 * @brief Packs a folder of web tiles (<z>/<x>/<y>.png, XYZ) into one file for a GIS: a GeoPackage (OGC 12-128r,
 * tiles in EPSG:3857, every level; what QGIS opens, through GDAL), or an MBTiles file (MBTiles 1.3, TMS rows; tile
 * servers and mobile map apps; GDAL, hence QGIS, refuses MBTiles beyond level 22, which the millimetre levels of a
 * seabed mosaic are). Both are SQLite databases written with sqlite3 directly, the PNG files copied as they are. No
 * ROS in it.
 */
#pragma once

#include <string>

#include "exocet_web/tiles/web_mercator.h"

namespace exocet_web {
namespace tiles {

/// The description of the package.
struct TilePackageInfo {
  std::string name = "Exocet mosaic";  ///< the layer's name (e.g. the dive's)
  std::string description;
  LatLonBox bounds;  ///< WGS 84 extent; a box with west >= east is computed from the tiles
};

/// What an export did.
struct TilePackageResult {
  bool ok = false;
  std::string error;  ///< what failed (SQLite's message, the file), when !ok
  int tiles = 0;      ///< tiles packed
  int min_zoom = -1, max_zoom = -1;
};

/**
 * @brief Writes every <z>/<x>/<y>.png of `tiles_dir` into the MBTiles `output_path` (tables metadata and tiles, a
 * unique index on the tile coordinates), under a temporary name first and renamed over any previous file: a reader
 * never sees half an export. Never throws.
 */
TilePackageResult exportMbtiles(const std::string& tiles_dir, const std::string& output_path,
                                const TilePackageInfo& info);

/**
 * @brief Writes every <z>/<x>/<y>.png of `tiles_dir` into the GeoPackage `output_path`: one tile pyramid (table
 * "mosaic") on a tile matrix set in EPSG:3857 aligned with the web tiles of the coarsest level (so the raster GDAL
 * makes of it covers the survey, not the world), a tile matrix per level, the PNG files as they are. Atomic as
 * exportMbtiles(). Never throws.
 */
TilePackageResult exportGeoPackage(const std::string& tiles_dir, const std::string& output_path,
                                   const TilePackageInfo& info);

}  // namespace tiles
}  // namespace exocet_web
