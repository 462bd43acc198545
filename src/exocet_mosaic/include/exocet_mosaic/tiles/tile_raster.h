/**
 * @file tile_raster.h
 * @brief Plain structs of a mosaic tile: the raster to write (north-up, in one UTM zone or in a local metric frame),
 * its metadata, and the description of the files written. No ROS, no GDAL in it.
 */
#pragma once

#include <limits>
#include <map>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

namespace exocet_mosaic {
namespace tiles {

/// A north-up raster in one UTM zone (or UPS), or in a local metric frame: pixel (col, row) covers easting
/// [E0 + col * gsd, E0 + (col + 1) * gsd] and northing [N0 - (row + 1) * gsd, N0 - row * gsd], i.e. the GDAL
/// geotransform [E0, gsd, 0, N0, 0, -gsd]. In a local frame "easting" and "northing" are its x (east) and y (north).
struct TileRaster {
  cv::Mat image;  ///< CV_8UC3 (BGR, as OpenCV) or CV_8UC1 (grey)
  cv::Mat mask;   ///< CV_8UC1, same size as image: 255 data, 0 no data (nonzero counts as data); empty: all data
  double origin_easting_m = 0.0;    ///< UTM easting of the top-left CORNER of the top-left pixel
  double origin_northing_m = 0.0;   ///< UTM northing of the top-left CORNER of the top-left pixel
  double gsd_m = 0.0;               ///< side of the square pixel (ground sampling distance), > 0
  int utm_zone = 31;                ///< 1..60 for UTM, 0 for UPS
  bool northern_hemisphere = true;  ///< UTM: hemisphere of the northings (false: 10 000 km false northing); UPS: pole
  /// Empty: the raster is in the UTM zone above. Otherwise the name of the local metric frame it is in (a dive whose
  /// navigation is not geo-referenced, e.g. "map"): the GeoTIFF gets an engineering CRS of that name (metres, x east,
  /// y north), EPSG 0, no WGS 84 box and no KMZ; utm_zone is then ignored.
  std::string local_frame;
};

/// What the tile holds, written as GDAL metadata items of the GeoTIFF (TIFFTAG_* where a TIFF tag exists,
/// EXOCET_* otherwise) and repeated in the JSON notification.
struct TileMetadata {
  std::string dive_name;      ///< TIFFTAG_DOCUMENTNAME and EXOCET_DIVE_NAME
  int first_frame = -1;       ///< first image (frame index) composed into the tile, -1: unknown
  int last_frame = -1;        ///< last image composed into the tile, -1: unknown
  double start_time_s = 0.0;  ///< time of the first image (seconds, the dive's clock, e.g. UNIX time)
  double end_time_s = 0.0;    ///< time of the last image (seconds)
  double mean_altitude_m = std::numeric_limits<double>::quiet_NaN();  ///< above the seabed; NaN: unknown (omitted)
  std::string close_reason;         ///< why the tile was closed (e.g. "size", "end_of_dive", "registration_lost")
  std::string software = "Exocet";  ///< TIFFTAG_SOFTWARE
  /// Further items. Keys are written as EXOCET_<KEY> (upper case, characters other than A-Z 0-9 _ as '_') unless
  /// they already start with EXOCET_ or TIFFTAG_; the JSON keeps the keys as given.
  std::map<std::string, std::string> extra;
};

/// The files of one written tile, or why it could not be written (ok = false, error set, no file under a final name).
struct WrittenTile {
  bool ok = false;
  std::string error;         ///< what failed, with the path and the OS / GDAL message (e.g. "No space left on device")
  int index = -1;            ///< tile index NNNN of the names <prefix>_<NNNN>.*
  int version = 1;           ///< 1, then 2, 3... when the tile is drawn again (names <prefix>_<NNNN>_v<version>.*)
  std::string geotiff_path;  ///< <output_dir>/<prefix>_<NNNN>.tif
  std::string world_file_path;  ///< <output_dir>/<prefix>_<NNNN>.tfw, empty when not written
  std::string cog_path;         ///< <output_dir>/<prefix>_<NNNN>.cog.tif, empty when not written
  std::string kmz_path;         ///< <output_dir>/<prefix>_<NNNN>.kmz, empty when not written
  /// Companions (COG, KMZ) that could not be written, each with its error. The tile is still written (ok): the
  /// GeoTIFF is the product, a companion is a convenience, and a tile must not be lost for one.
  std::vector<std::string> companion_errors;
  int epsg = 0;             ///< EPSG code of the GeoTIFF's SRS (326zz / 327zz, UPS 32661 / 32761); 0 in a local frame
  std::string local_frame;  ///< the raster's local frame, empty for UTM (TileRaster::local_frame)
  double min_easting_m = 0.0, min_northing_m = 0.0;  ///< outer corners of the raster in its UTM zone or local frame
  double max_easting_m = 0.0, max_northing_m = 0.0;
  double gsd_m = 0.0;  ///< pixel side (metres)
  /// WGS 84 bounding box of the raster's outline (degrees). Longitudes are continuous across the tile: a tile that
  /// crosses the antimeridian has east_deg > 180. A UPS tile that holds the pole spans [-180, 180]. NaN in a local
  /// frame.
  double west_deg = 0.0, south_deg = 0.0, east_deg = 0.0, north_deg = 0.0;
  int width_px = 0, height_px = 0;
  TileMetadata metadata;
  double write_ms = 0.0;  ///< wall time of write() (milliseconds)
};

}  // namespace tiles
}  // namespace exocet_mosaic
