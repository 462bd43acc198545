/**
 * @file web_tile_cutter.h
 * @brief Cuts GeoTIFF mosaic tiles into web tiles (XYZ, EPSG:3857, 256 x 256 PNG with alpha) incrementally: a new or
 * re-rendered GeoTIFF re-cuts only the web tiles its outline touches. No ROS in it.
 *
 * The finest level (max zoom) is cut with GDAL's warper (GDALWarp, bilinear, the GeoTIFF's alpha band or mask as
 * no-data, its overviews when coarser) from every GeoTIFF that covers the web tile, composited in key order
 * (<prefix>_<NNNN>: the tile written last on top, as exocet_mosaic's <prefix>_mosaic.vrt), alpha respected. A new
 * GeoTIFF whose key comes after every other (tiles written in order, the usual case) is only drawn over the web
 * tiles already cut; a new version of a tile, or one that goes under others, composites the area again. Each
 * coarser level is made from its four children (alpha-weighted 2 x 2 average) down to the min zoom, the level at
 * which the whole survey fits in one tile's width (lowered as the survey grows) unless configured. Files are
 * <output_dir>/<z>/<x>/<y>.png, each written under a temporary name and renamed: a web server never reads half a
 * tile. A web tile with no data is not written (and removed when it had some before).
 */
#pragma once

#include <functional>
#include <map>
#include <set>

#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "exocet_web/tiles/source_tile.h"
#include "exocet_web/tiles/web_mercator.h"

namespace exocet_web {
namespace tiles {

/// How the web tiles are cut. validate() lists the allowed values.
struct CutterConfig {
  std::string output_dir;  ///< folder of the web tiles (<z>/<x>/<y>.png), created when missing
  /// Finest level, [1, 30]; -1: the native level of the first GeoTIFF (nativeZoom of its gsd at its latitude).
  int max_zoom = -1;
  /// Coarsest level, [0, max_zoom]; -1: the level at which the survey fits in one tile, lowered as it grows.
  int min_zoom = -1;
  int png_compression = 3;              ///< zlib level of the PNG files, [0, 9] (speed against size)
  int block_tiles = 16;                 ///< web tiles per side warped at once, [1, 64] (memory: (256 n)^2 x 4 bytes)
  std::string resampling = "bilinear";  ///< near | bilinear | cubic | lanczos | average (GDAL's -r)

  /// Empty if usable; otherwise every bad field with its allowed range, "; "-separated.
  std::string validate() const;
};

/// What one update did.
struct CutReport {
  bool ok = false;
  std::string error;            ///< what failed (GDAL's message, the file), when !ok
  std::vector<TileId> written;  ///< web tiles (re)written, every level
  std::vector<TileId> removed;  ///< web tiles deleted (no data left)
  /// Keys of other GeoTIFFs that could not be opened (e.g. a version replaced on disk before its message came):
  /// left out of the composite; the caller re-reads their folder.
  std::vector<std::string> unreadable;
  int sources_warped = 0;  ///< GeoTIFF warps done (one per GeoTIFF and block of web tiles)
  double warp_ms = 0.0;    ///< time in GDAL's warper
  double total_ms = 0.0;   ///< wall time of the update
};

/// Called once the finest level of an update is on disk, before its coarser levels are built: `finest` holds the
/// finest-level web tiles written or removed so far (the report's other fields are not final yet).
using FinestLevelCallback = std::function<void(const CutReport& finest)>;

/// Not thread-safe: one thread cuts. The web tiles may be read meanwhile (renamed into place).
class WebTileCutter {
 public:
  /// @throws std::invalid_argument with CutterConfig::validate()'s message
  explicit WebTileCutter(const CutterConfig& config);

  const CutterConfig& config() const { return config_; }

  /**
   * @brief Takes over the web tiles a previous run cut from `sources` at levels [min_zoom, max_zoom] (files already
   * in output_dir, listed by scanning it): nothing is cut. Replaces every source and tile known so far.
   */
  void adopt(const std::vector<SourceTile>& sources, int min_zoom, int max_zoom);

  /**
   * @brief Adds a GeoTIFF, or replaces the one of the same key (a new version): re-cuts the web tiles of the union of
   * its old and new outlines at the max zoom, then their parents. The first source sets the max zoom when automatic.
   * @param on_finest_level when set, called between the finest level and its parents: a page showing the finest
   * level can fetch its web tiles while the coarser levels are being built. The returned report lists every level.
   */
  CutReport update(const SourceTile& source, const FinestLevelCallback& on_finest_level = FinestLevelCallback());

  /// Removes the GeoTIFF of `key` and re-cuts the web tiles of its outline (those left without data are deleted).
  CutReport remove(const std::string& key);

  /// The sources in compositing order (key order: the last on top).
  std::vector<SourceTile> sources() const;
  const SourceTile* source(const std::string& key) const;
  /// -1 until the first source when automatic.
  int maxZoom() const { return max_zoom_; }
  int minZoom() const { return min_zoom_; }
  /// Every web tile on disk, all levels.
  const std::set<TileId>& tiles() const { return tiles_; }
  /// EPSG:3857 box of every source.
  MercatorBox surveyBounds() const;
  /// Path of a web tile's file.
  std::string tilePath(const TileId& tile) const;

 private:
  /// Cuts the area again; `only_key`: draw that source over the web tiles as they are (a new tile on top).
  CutReport recut(const MercatorBox& dirty, const std::string& only_key = std::string(),
                  const FinestLevelCallback& on_finest_level = FinestLevelCallback());
  void cutFinestLevel(const TileRange& range, const std::string& only_key, CutReport* report);
  void buildParents(std::set<TileId> children, int down_to_zoom, CutReport* report);
  void buildParent(const TileId& parent, CutReport* report);
  void lowerMinZoom(CutReport* report);
  /// Writes a 256 x 256 BGRA tile (or removes its file when it holds no data).
  void store(const TileId& tile, const void* bgra, size_t step_bytes, CutReport* report);

  CutterConfig config_;
  int max_zoom_ = -1;
  int min_zoom_ = -1;
  std::map<std::string, SourceTile> sources_;  // key order = compositing order
  std::set<TileId> tiles_;
  std::map<TileId, cv::Mat> fresh_;  // tiles written by the update under way, for their parents
};

}  // namespace tiles
}  // namespace exocet_web
