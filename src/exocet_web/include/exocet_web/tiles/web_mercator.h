/**
 * @file web_mercator.h
 * @brief The XYZ tile grid of web maps (Leaflet, OpenStreetMap, "slippy map"): spherical Mercator (EPSG:3857)
 * metres, 256-pixel tiles, x from the antimeridian eastwards, y from the north edge (85.05 deg N) southwards. No ROS,
 * no GDAL in it.
 */
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace exocet_web {
namespace tiles {

/// Side of a web tile (pixels).
constexpr int kTileSize_px = 256;
/// Half the side of the EPSG:3857 square (metres): pi * 6378137.
constexpr double kMercatorHalfSide_m = 20037508.342789244;
/// Latitude of the square's north and south edges (degrees).
constexpr double kMercatorMaxLatitude_deg = 85.0511287798066;
/// Deepest zoom level handled (a 30-level tile is 3.7 cm at the equator; int indices up to 2^30).
constexpr int kMaxZoom = 30;

/// One web tile: zoom level z, column x in [0, 2^z), row y in [0, 2^z) counted from the north.
struct TileId {
  int z = 0;
  int x = 0;
  int y = 0;
  bool operator==(const TileId& o) const { return z == o.z && x == o.x && y == o.y; }
  bool operator!=(const TileId& o) const { return !(*this == o); }
  bool operator<(const TileId& o) const {
    if (z != o.z) return z < o.z;
    if (x != o.x) return x < o.x;
    return y < o.y;
  }
  /// "z/x/y".
  std::string path() const;
};

/// A box in EPSG:3857 metres (x east, y north).
struct MercatorBox {
  double min_x_m = 0.0;
  double min_y_m = 0.0;
  double max_x_m = 0.0;
  double max_y_m = 0.0;
  bool empty() const { return !(max_x_m > min_x_m && max_y_m > min_y_m); }
  /// The smallest box holding both (an empty box is ignored).
  MercatorBox unitedWith(const MercatorBox& other) const;
  /// Whether the interiors overlap (boxes that only touch do not).
  bool intersects(const MercatorBox& other) const;
  MercatorBox intersection(const MercatorBox& other) const;
};

/// A box in WGS 84 degrees.
struct LatLonBox {
  double west_deg = 0.0;
  double south_deg = 0.0;
  double east_deg = 0.0;
  double north_deg = 0.0;
};

/// Inclusive range of columns and rows of one zoom level.
struct TileRange {
  int z = 0;
  int min_x = 0, max_x = -1;
  int min_y = 0, max_y = -1;
  bool empty() const { return max_x < min_x || max_y < min_y; }
  int64_t count() const { return empty() ? 0 : int64_t(max_x - min_x + 1) * int64_t(max_y - min_y + 1); }
  std::vector<TileId> tiles() const;
};

/// EPSG:3857 x (metres) of a longitude (degrees, any value: not wrapped).
double mercatorX_m(double longitude_deg);
/// EPSG:3857 y (metres) of a latitude (degrees), clamped to +-kMercatorMaxLatitude_deg.
double mercatorY_m(double latitude_deg);
double longitudeFromMercatorX_deg(double x_m);
double latitudeFromMercatorY_deg(double y_m);

/// Side of a pixel of zoom level z in EPSG:3857 metres (true ground size: times cos(latitude)).
double resolution_m_per_px(int z);
/// Ground size of a pixel of zoom level z at a latitude (metres).
double groundResolution_m_per_px(int z, double latitude_deg);

/// EPSG:3857 box of a tile.
MercatorBox tileBounds(const TileId& tile);
/// WGS 84 box of a tile.
LatLonBox tileLatLonBounds(const TileId& tile);

/**
 * @brief The tiles of level z whose interior overlaps `box` (a box that only touches a tile's edge does not take
 * it), clamped to the level's grid. Empty range for an empty box.
 * @throws std::invalid_argument when z is outside [0, kMaxZoom]
 */
TileRange tilesCovering(const MercatorBox& box, int z);

/// The tile of level `tile.z - 1` holding `tile` (tile itself at level 0).
TileId parentOf(const TileId& tile);

/**
 * @brief The zoom level whose pixel is nearest (in ratio) to a ground sample distance at a latitude: the finest
 * level a GeoTIFF of that gsd is cut at, without inventing detail by more than a factor sqrt(2).
 * @param gsd_m ground sample distance (metres), > 0
 * @return a level in [0, kMaxZoom]
 * @throws std::invalid_argument for gsd_m <= 0 or not finite, or a latitude outside (-90, 90)
 */
int nativeZoom(double gsd_m, double latitude_deg);

/**
 * @brief The finest level at which `box` fits in one tile's width and height (it then covers at most 2 x 2 tiles),
 * at most max_zoom: the coarsest level worth cutting for a survey of that extent.
 */
int zoomFittingBox(const MercatorBox& box, int max_zoom);

}  // namespace tiles
}  // namespace exocet_web
