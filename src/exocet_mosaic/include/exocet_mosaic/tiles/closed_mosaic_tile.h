/**
 * @file closed_mosaic_tile.h
 * @brief What a closed mosaic becomes on disk: its raster and the tile metadata both writers (tile_writer_node and
 * mosaic_video) give GeoTiffTileWriter. No ROS in it.
 */
#pragma once

#include <string>

#include "exocet_mosaic/compose/mosaic_composer.h"
#include "exocet_mosaic/tiles/tile_raster.h"

namespace exocet_mosaic {
namespace tiles {

/// The mosaic's raster in UTM zone `utm_zone` (hemisphere `northern`), or in the local frame `local_frame` when it is
/// not empty.
TileRaster tileRaster(const compose::ClosedMosaic& mosaic, int utm_zone, bool northern,
                      const std::string& local_frame);

/// The tile's metadata: frames, times, mean camera height, why it closed, and in `extra` the frames composed, the
/// position's 1-sigma and the blending used.
TileMetadata tileMetadata(const compose::ClosedMosaic& mosaic, const std::string& dive_name);

}  // namespace tiles
}  // namespace exocet_mosaic
