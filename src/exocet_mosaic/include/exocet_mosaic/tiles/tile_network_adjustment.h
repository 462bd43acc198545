/**
 * @file tile_network_adjustment.h
 * @brief After the dive: moves the written tiles so that overlapping ones agree, the return passes with the outbound
 * ones. The live tiles are placed by the live fused track, whose error between passes (USBL) is several centimetres:
 * two passes over the same seabed show it as a seam of 5-15 px. Here every pair of overlapping tiles is registered
 * in its overlap (phase correlation of band-passed patches, refined by resampling), and one similarity per tile
 * (translation, rotation and scale about its centre: the live placement fits each tile's own) is solved by least
 * squares: the patches' offsets (tight) against each tile's navigation position (its 1-sigma,
 * EXOCET_POSITION_SIGMA_M) and a weak prior on rotation and scale, so that the network as a whole stays where the
 * navigation put it. The adjusted tiles are resampled north-up at the same ground sample distance and written by
 * GeoTiffTileWriter under the same names (world file, overviews, the live metadata plus EXOCET_ADJUSTMENT_*) in another
 * folder; the live tiles are kept. No ROS in it.
 */
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <utility>
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
  double patch_sigma_px = 0.5;       ///< 1-sigma of one patch_px patch's offset (smaller patches: more), (0, 100]
  /// Prior 1-sigma of a tile's rotation (rad) and scale change (fraction), (0, 1]: weak, the overlaps decide. Live
  /// tiles of a turning dive (the sample lawnmower) differ in scale by up to 6 % in their overlaps: 0.01 held them
  /// back (consecutive tiles 2.2 px after, 0.9 px with 0.1; the PAL bench dive's 0.45 px either way).
  double rotation_scale_sigma = 0.1;
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
  /// The adjustment, a point p of the tile goes to p + shift + [scale -rotation; rotation scale] (p - centre).
  Eigen::Vector2d centre_en_m = Eigen::Vector2d::Zero();
  Eigen::Vector2d shift_en_m = Eigen::Vector2d::Zero();
  double rotation_rad = 0.0;
  double scale_change = 0.0;
  /// Where the adjustment moves p (UTM, m).
  Eigen::Vector2d moved(const Eigen::Vector2d& p) const {
    const Eigen::Vector2d d = p - centre_en_m;
    return p + shift_en_m + Eigen::Vector2d(scale_change * d.x() - rotation_rad * d.y(),
                                            rotation_rad * d.x() + scale_change * d.y());
  }
};

/// One patch of an overlap: at centre_en_m (as tile a places it), b's content lies offset_en_m from a's.
struct PatchOffset {
  Eigen::Vector2d centre_en_m = Eigen::Vector2d::Zero();
  Eigen::Vector2d offset_en_m = Eigen::Vector2d::Zero();
  int patch_px = 0;
};

/// The measured disagreement of two overlapping tiles: b's content lies offset_en_m from a's (b minus a).
struct TilePairOffset {
  int a = -1, b = -1;                ///< indices into the tiles
  Eigen::Vector2d offset_en_m = Eigen::Vector2d::Zero();
  int patches = 0;                   ///< patches that agreed
  int patch_px = 0;                  ///< their side (smaller in a narrow overlap)
  double spread_px = 0.0;            ///< median distance of the patches' offsets from their median
  std::vector<PatchOffset> patch_offsets;  ///< the agreeing patches
  /// After the adjustment (b minus a), the largest over the patches.
  Eigen::Vector2d residual_en_m = Eigen::Vector2d::Zero();
};

/// What adjustTiles() did.
struct TileAdjustmentResult {
  bool ok = false;
  std::string error;                 ///< what failed, naming the file
  std::vector<AdjustedTile> tiles;
  std::vector<TilePairOffset> pairs;  ///< the measured pairs
  std::vector<std::string> written;   ///< paths of the adjusted GeoTIFFs
};

/// The tiles of a folder as the tile writer names them (<prefix>_NNNN.tif, or the highest <prefix>_NNNN_v<K>.tif of a
/// tile drawn again; not the .cog.tif copies), sorted; empty when there are none or the folder cannot be read (*error
/// says why, if given).
std::vector<std::string> listTiles(const std::string& folder, std::string* error = nullptr);

/**
 * @brief The pairs an earlier measureAndSolve measured, by the paths of their two files, so that the next one reads
 * and measures only the pairs with a new file. Exact for the tile writer's folders: a tile drawn again is written
 * under a new name (its version is in it), and a file is never rewritten under its name. Holds the pairs of the last
 * call's tiles only. For one TileAdjustmentConfig. Not thread-safe.
 */
class TilePairCache {
 public:
  std::size_t size() const { return pairs_.size(); }
  std::int64_t measured() const { return measured_; }  ///< pairs measured (or found not measurable) over the calls
  std::int64_t reused() const { return reused_; }      ///< pairs taken from the cache over the calls

 private:
  friend TileAdjustmentResult measureAndSolve(const std::vector<std::string>&, const TileAdjustmentConfig&,
                                              TilePairCache*);
  /// (path a, path b) -> the pair (indices a, b unset), or nullopt when the two do not give a measurement.
  std::map<std::pair<std::string, std::string>, std::optional<TilePairOffset>> pairs_;
  std::int64_t measured_ = 0, reused_ = 0;
};

/**
 * @brief Reads the tiles (GeoTIFFs written by GeoTiffTileWriter: colour or grey bands and an alpha band), measures
 * every overlapping pair of the same EPSG and GSD, and solves one similarity per tile.
 * @param paths  the live GeoTIFFs
 * @param cache  if given, the pairs of files it measured before are taken from it, and it keeps this call's pairs
 */
TileAdjustmentResult measureAndSolve(const std::vector<std::string>& paths, const TileAdjustmentConfig& config,
                                     TilePairCache* cache = nullptr);

/**
 * @brief Writes the adjusted tiles into output_dir (an existing folder other than theirs): each tile resampled
 * (bilinear, alpha-weighted) north-up on a grid of the same GSD that holds all its moved pixels, under the same name
 * (<prefix>_NNNN), with the same compression, its world file and overviews; metadata: the live tile's plus
 * EXOCET_ADJUSTMENT_E_M, _N_M, _ROTATION_RAD, _SCALE. Nothing is overwritten (error). Sets result->written, or
 * ok = false and error.
 */
void writeAdjustedTiles(const std::string& output_dir, TileAdjustmentResult* result);

}  // namespace tiles
}  // namespace exocet_mosaic
