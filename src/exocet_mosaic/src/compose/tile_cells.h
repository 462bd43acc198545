/**
 * @file tile_cells.h
 * @brief (private) A tile's mean levels in coarse cells of the ground: a fixed grid in metres keyed by the cell's
 * easting and northing (floored), so that the cells of different tiles coincide.
 */
#pragma once

#include <cstdint>
#include <string>

#include <opencv2/core.hpp>

#include "exocet_mosaic/tiles/tile_raster.h"

namespace exocet_mosaic {
namespace compose {

/// Cells over the bounding box of a tile's data; row 0 is the northernmost cell.
struct TileCells {
  std::int64_t west = 0;   ///< cell column (floor(easting / cell_size_m)) of column 0
  std::int64_t north = 0;  ///< cell row (floor(northing / cell_size_m)) of row 0; row r is cell row north - r
  cv::Mat mean;            ///< CV_32FC(channels): mean level of the data pixels in the cell
  cv::Mat coverage;        ///< CV_32F: fraction of the cell's area with data, [0, 1]
};

/// The cells of a raster (CV_8UC1 or CV_8UC3, mask as TileRaster); empty mats if it has no data.
TileCells computeTileCells(const tiles::TileRaster& raster, double cell_size_m);

/// Packs mean (x 256) and coverage (x 65535) into CV_16UC(channels + 1), 2 bytes each.
cv::Mat packTileCells(const TileCells& cells);
/// Unpacks packTileCells's mat into cells.mean and cells.coverage (west and north untouched).
void unpackTileCells(const cv::Mat& packed, TileCells* cells);

/// A key of the raster's frame: the local frame's name or the UTM zone and hemisphere.
std::string tileFrameKey(const tiles::TileRaster& raster);

}  // namespace compose
}  // namespace exocet_mosaic
