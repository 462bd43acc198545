/**
 * @file tile_json.h
 * @brief The JSON text of a written tile (one object, UTF-8), shared by the UDP notification and any log. The fields
 * are documented in config/tiles/UDP_NOTIFICATION.md.
 */
#pragma once

#include <string>

#include "exocet_mosaic/tiles/tile_raster.h"

namespace exocet_mosaic {
namespace tiles {

/// Version of the JSON layout ("version" field); raised when a field changes meaning or disappears.
constexpr int kTileJsonVersion = 1;

/**
 * @brief One JSON object describing `tile` (type "exocet_tile"): index, paths (null when not written), EPSG, UTM and
 * WGS 84 bounds, gsd, size, metadata (frames, times, altitude, close reason, extra), write time, ok and error.
 * @param tile the result of GeoTiffTileWriter::write (also a failed one: ok false, error set)
 * @return compact JSON on one line, no trailing newline; non-finite numbers as null; bytes that are not valid UTF-8
 * (e.g. a Latin-1 file name) as U+FFFD, so that the text is always valid UTF-8
 */
std::string tileToJson(const WrittenTile& tile);

/// `value` in the shortest form that reads back to the same double ("0.05", "6252000.5", "1e-07"), as GDAL metadata
/// and command arguments take it; "null" when not finite. Locale-independent.
std::string jsonNumber(double value);

}  // namespace tiles
}  // namespace exocet_mosaic
