/**
 * @file tile_mosaic_vrt.h
 * @brief One GDAL virtual mosaic (VRT) over the current version of every tile of a folder: a GIS opens that one layer
 * and, on reload, sees the tiles drawn again (their file names change with their version). No ROS in it.
 */
#pragma once

#include <string>
#include <vector>

namespace exocet_mosaic {
namespace tiles {

/**
 * @brief Writes `vrt_path` (GDALBuildVRT, the newest tile on top where they overlap: the list's order) over the
 * GeoTIFFs `geotiff_paths`, atomically (temporary file, then rename), with paths relative to the VRT's folder.
 * @return empty on success, otherwise what failed (GDAL's message)
 */
std::string writeTileMosaicVrt(const std::string& vrt_path, const std::vector<std::string>& geotiff_paths);

}  // namespace tiles
}  // namespace exocet_mosaic
