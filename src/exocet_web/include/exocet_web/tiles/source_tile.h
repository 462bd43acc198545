/**
 * @file source_tile.h
 * @brief The GeoTIFF mosaic tiles the web tiles are cut from, as exocet_mosaic's tile writer names and writes them
 * (<prefix>_<NNNN>.tif, <prefix>_<NNNN>_v<K>.tif once drawn again; colour or grey bands and an alpha band, or an
 * internal no-data mask; EXOCET_* metadata items). Read with GDAL. No ROS in it.
 */
#pragma once

#include <array>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "exocet_web/tiles/web_mercator.h"

namespace exocet_web {
namespace tiles {

/// One GeoTIFF tile as the cutter sees it.
struct SourceTile {
  std::string key;   ///< "<prefix>_<NNNN>": the same for every version of a tile; the compositing order
  int index = -1;    ///< NNNN
  int version = 1;   ///< K of <prefix>_<NNNN>_v<K>.tif, 1 without the suffix
  std::string path;  ///< absolute path of the GeoTIFF
  int64_t file_size_bytes = 0;
  int64_t mtime_ns = 0;  ///< modification time (ns since the epoch): with the size, tells a rewritten file
  int epsg = 0;          ///< EPSG code of the raster's CRS
  int width_px = 0, height_px = 0;
  double gsd_m = 0.0;    ///< pixel side in the raster's CRS (metres)
  MercatorBox bounds;    ///< EPSG:3857 box of the raster's outline
  LatLonBox latlon_box;  ///< WGS 84 box of the outline
  /// The raster's four corners (top-left, top-right, bottom-right, bottom-left) as {latitude, longitude} degrees.
  std::array<std::array<double, 2>, 4> corners_deg{};
  double centre_latitude_deg = 0.0;
  /// GDAL metadata items EXOCET_* of the file, the prefix removed and the key in lower case ("tile_index",
  /// "start_time_s", "frames_composed", "position_sigma_m", ...).
  std::map<std::string, std::string> metadata;
};

/**
 * @brief Splits a tile writer's GeoTIFF name "<prefix>_<NNNN>.tif" or "<prefix>_<NNNN>_v<K>.tif" (NNNN: 4 digits or
 * more; not a ".cog.tif" copy, not a hidden or temporary file).
 * @return false when `file_name` is not such a name
 */
bool parseTileFileName(const std::string& file_name, std::string* key, int* index, int* version);

/// The newest version of every tile in `folder` (parseTileFileName names, regular files), sorted by key; empty when
/// there is none or the folder cannot be read (*error says why, if given).
std::vector<std::string> listSourceTiles(const std::string& folder, std::string* error = nullptr);

/**
 * @brief Opens `path` with GDAL and describes it. Never throws.
 * @return "" on success; otherwise why it cannot be used (not readable by GDAL, not named as a tile, a CRS without a
 * geodetic datum such as a dive's local frame, no geotransform, a rotated raster), naming the file
 */
std::string readSourceTile(const std::string& path, SourceTile* tile);

}  // namespace tiles
}  // namespace exocet_web
