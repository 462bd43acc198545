/**
 * @file geotiff_tile_writer.h
 * @brief Writes a composed mosaic raster as geo-referenced files that a GIS (QGIS) opens at once: a tiled GeoTIFF
 * (GDAL GTiff driver, EPSG of the UTM zone, alpha band for no-data, internal overviews), its `.tfw` world file, and
 * optionally a Cloud Optimized GeoTIFF and a KMZ super-overlay in WGS 84. No ROS in it.
 *
 * Every file is written under a temporary name in the output folder (".<final name>.partial", or
 * ".<prefix>_<NNNN>.partial.kmz" for the KMZ, whose driver needs the extension), fsync'ed, then renamed without ever
 * replacing an existing file (renameat2 RENAME_NOREPLACE): a reader never sees an incomplete file under a final
 * name, and a restart never overwrites a tile. The GeoTIFF is renamed last, so that once it exists its companions do.
 */
#pragma once

#include <string>

#include "exocet_mosaic/tiles/tile_raster.h"

namespace exocet_mosaic {
namespace tiles {

/// Where and how the tiles are written. validate() lists the allowed values.
struct TileWriterConfig {
  std::string output_dir;       ///< existing folder of the tiles (not created), non-empty
  std::string prefix = "tile";  ///< files <prefix>_<NNNN>.tif ...; [A-Za-z0-9_-.], 1..64 characters, not starting '.'
  /// DEFLATE | LZW (both lossless, with PREDICTOR=2) | JPEG (lossy, quality 75; no-data as an internal mask, RGB as
  /// YCbCr) | NONE.
  std::string compression = "DEFLATE";
  /// DEFLATE effort, [1, 9] (GDAL's ZLEVEL; GDAL's own default is 6). 1 by default: on real seabed images (Sparus AUV
  /// frames) level 6 took ~3.7x as long for files only ~6 % smaller, and tiles are written during the dive.
  int deflate_level = 1;
  int block_size_px = 256;       ///< side of the GeoTIFF's internal tiles: a multiple of 16 in [16, 4096]
  bool write_world_file = true;  ///< <name>.tfw beside the GeoTIFF (for GIS that ignore the GeoTIFF keys)
  bool write_cog = false;        ///< <name>.cog.tif: a Cloud Optimized GeoTIFF copy (GDAL COG driver)
  bool write_kmz = false;        ///< <name>.kmz: KML super-overlay (PNG, transparent no-data) in WGS 84
  int kmz_max_side_px = 4096;    ///< the KMZ's raster is downsampled to at most this side, [256, 32768]

  /// Empty if usable, otherwise every bad field with its allowed range, separated by "; ".
  std::string validate() const;
};

/// EPSG code of a UTM zone (326zz north / 327zz south) or of UPS (zone 0: 32661 north / 32761 south), the same as
/// exocet_common::UtmGrid::epsg(). @throws std::invalid_argument when zone is outside [0, 60].
int epsgForUtm(int zone, bool northern);

/// Writes TileRaster's as GeoTIFF tiles with consecutive indices in one folder. Not thread-safe: one writer per
/// folder and prefix.
class GeoTiffTileWriter {
 public:
  /// @throws std::invalid_argument with TileWriterConfig::validate()'s message when the configuration is invalid.
  /// Does not touch the file system (a missing folder is reported by write()).
  explicit GeoTiffTileWriter(const TileWriterConfig& config);

  const TileWriterConfig& config() const { return config_; }

  /// Next free index: the first index none of whose final names (.tif, .tfw, .cog.tif, .kmz, of any version) exists
  /// in output_dir, so that a restart never overwrites a tile.
  int nextIndex() const;

  /**
   * @brief Writes the tile under index nextIndex(): every file under a temporary name, fsync, then rename.
   *
   * Never throws for I/O problems or a bad raster: on any failure it removes its temporaries and returns ok = false
   * with an error naming what failed, the path and the OS / GDAL message; nothing appears under a final name.
   * Overviews (AVERAGE, levels 2, 4, ... down to about one block) are built into the GeoTIFF when its larger side
   * exceeds 1024 px.
   * @param raster  image CV_8UC3 (BGR) or CV_8UC1, mask empty or CV_8UC1 of the same size, gsd_m > 0, zone 0..60
   * @param metadata written as GeoTIFF metadata items and copied into the result
   */
  WrittenTile write(const TileRaster& raster, const TileMetadata& metadata);
  /// As write(), under a given index (a negative one: nextIndex()); fails, writing nothing, when one of its final
  /// names exists (the rename never replaces a file).
  WrittenTile writeAt(const TileRaster& raster, const TileMetadata& metadata, int index);

  /**
   * @brief A new version (>= 2) of tile `index`, drawn again (e.g. its images moved by a pose graph): written as
   * writeAt() does under baseName(index, version), EXOCET_TILE_VERSION in its metadata. The previous version's files
   * are not touched: removeVersion() them once the new one is announced.
   */
  WrittenTile writeVersion(const TileRaster& raster, const TileMetadata& metadata, int index, int version);
  /// Removes the final files of one version of a tile (those that exist); returns how many it removed.
  int removeVersion(int index, int version) const;

  /// Removes the temporaries left in output_dir by a killed writer of this prefix (".<prefix>_*.partial*"); call it
  /// at start-up, when no other writer of this folder and prefix runs. Returns how many files it removed.
  int removeStaleTemporaries() const;
  /// Removes the companions (.tfw, .cog.tif, .kmz) of a tile whose GeoTIFF is missing: a writer killed between the
  /// renames of one tile's files (the GeoTIFF goes last). Call it at start-up, as removeStaleTemporaries(). Returns
  /// how many files it removed.
  int removeIncompleteTiles() const;

  /// Final file names (no folder) of tile `index`: "<prefix>_<NNNN>" + ".tif" / ".tfw" / ".cog.tif" / ".kmz".
  std::string baseName(int index) const;
  /// Of version `version` of tile `index`: baseName(index) for version 1 (or less), "<prefix>_<NNNN>_v<version>" after.
  std::string baseName(int index, int version) const;

 private:
  WrittenTile writeFiles(const TileRaster& raster, const TileMetadata& metadata, int index, int version);
  TileWriterConfig config_;
};

}  // namespace tiles
}  // namespace exocet_mosaic
