/**
 * @file tile_network_adjustment.h
 * @brief After the dive: moves the written tiles so that overlapping ones agree, the return passes with the outbound
 * ones. The live tiles are placed by the live fused track, whose error between passes (USBL) is several centimetres:
 * two passes over the same seabed show it as a seam of 5-15 px. Here every pair of overlapping tiles is registered
 * in its overlap (phase correlation of patches, median), and one translation per tile is solved by least squares:
 * the pairs' offsets (tight) against each tile's navigation position (its 1-sigma, EXOCET_POSITION_SIGMA_M), so that
 * the network as a whole stays where the navigation put it. The adjusted tiles are copies (same pixels, overviews and
 * metadata) with the moved georeference, their world files and EXOCET_ADJUSTMENT_E_M / _N_M; the live tiles are kept.
 * No ROS in it.
 */
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

namespace exocet_mosaic {
namespace tiles {

/// Parameters of the adjustment. validate() lists the allowed ranges.
struct TileAdjustmentConfig {
  int patch_px = 256;                ///< side of the correlated patches, a power of two in [32, 1024]
  int min_patches = 2;               ///< patches a pair needs to be measured, [1, 1000]
  double min_response = 0.1;         ///< phase correlation peak a patch needs, [0, 1]
  double max_patch_spread_px = 2.0;  ///< patches further than this from their median are outliers, (0, 100]
  double pair_sigma_px = 0.5;        ///< 1-sigma of an offset measured on two patch_px patches, (0, 100]
  /// A tile without EXOCET_POSITION_SIGMA_M gets this navigation 1-sigma (m), (0, 1000].
  double default_position_sigma_m = 0.1;
  /// Empty if usable, otherwise every bad field with its allowed range, separated by "; ".
  std::string validate() const;
};

/// One tile as read from its GeoTIFF.
struct AdjustedTile {
  std::string path;                  ///< the live GeoTIFF
  int epsg = 0;
  double gsd_m = 0.0;
  double origin_easting_m = 0.0;     ///< top-left corner, as written
  double origin_northing_m = 0.0;
  int width_px = 0, height_px = 0;
  double position_sigma_m = 0.0;     ///< navigation 1-sigma of its placement
  Eigen::Vector2d shift_en_m = Eigen::Vector2d::Zero();  ///< the adjustment: add to the origin
};

/// The measured disagreement of two overlapping tiles: b's content lies offset_en_m from a's (b minus a).
struct TilePairOffset {
  int a = -1, b = -1;                ///< indices into the tiles
  Eigen::Vector2d offset_en_m = Eigen::Vector2d::Zero();
  int patches = 0;                   ///< patches that agreed
  int patch_px = 0;                  ///< their side (smaller in a narrow overlap)
  double spread_px = 0.0;            ///< median distance of the patches' offsets from their median
  Eigen::Vector2d residual_en_m = Eigen::Vector2d::Zero();  ///< after the adjustment (b minus a)
};

/// What adjustTiles() did.
struct TileAdjustmentResult {
  bool ok = false;
  std::string error;                 ///< what failed, naming the file
  std::vector<AdjustedTile> tiles;
  std::vector<TilePairOffset> pairs;  ///< the measured pairs
  std::vector<std::string> written;   ///< paths of the adjusted GeoTIFFs
};

/**
 * @brief Reads the tiles (GeoTIFFs written by GeoTiffTileWriter: colour or grey bands and an alpha band), measures
 * every overlapping pair of the same EPSG and GSD, and solves one translation per tile.
 * @param paths  the live GeoTIFFs
 */
TileAdjustmentResult measureAndSolve(const std::vector<std::string>& paths, const TileAdjustmentConfig& config);

/**
 * @brief Writes the adjusted copies of result's tiles into output_dir (an existing folder other than theirs): the
 * same file name, the moved georeference, a world file beside each. Each file is written under a temporary name and
 * renamed; an existing file is not overwritten (error). Sets result->written, or ok = false and error.
 */
void writeAdjustedTiles(const std::string& output_dir, TileAdjustmentResult* result);

}  // namespace tiles
}  // namespace exocet_mosaic
