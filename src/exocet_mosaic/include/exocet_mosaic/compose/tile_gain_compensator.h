/**
 * @file tile_gain_compensator.h
 * @brief Live gain compensation between overlapping tiles (as OpenCV's stitcher GainCompensator does between images,
 * but incrementally): each new tile gets per-channel gains that make its overlap with the tiles already written match
 * them, with a prior pulling the gains towards 1 so that they cannot drift far over a dive. What has been written is
 * kept as coarse cells of the ground only (a few bytes per cell), not as pixels. No ROS in it.
 *
 * Use, per tile, in one thread: gains = estimate(raw, index) (or gainsOf(index) when tile index is re-rendered),
 * corrected = apply(raw, gains), write corrected, record(index, corrected, gains).
 */
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <map>
#include <optional>
#include <string>

#include <opencv2/core.hpp>

#include "exocet_mosaic/tiles/tile_raster.h"

namespace exocet_mosaic {
namespace compose {

/// Parameters of TileGainCompensator. validate() lists the allowed ranges.
struct TileGainConfig {
  /// Side of the ground cells (px of the FIRST tile seen), [4, 128]. The cells are a fixed grid in metres (this times
  /// the first tile's GSD) keyed by UTM (or local-frame) cell, so that the cells of different tiles coincide.
  int cell_size_px = 16;
  /// A cell takes part when at least this fraction of its area has data in the new tile and in the written ones,
  /// [0.05, 1]: cells cut by a tile's border mix different seabed in the two tiles.
  double min_cell_coverage = 0.6;
  /// Fewer common cells than this: no overlap (see TileGains::from_overlap), [1, 100000].
  int min_common_cells = 4;
  /// Weight of the prior gain 1 relative to the overlap's evidence, [0, 10]: the gain fitted on the overlap is pulled
  /// to (g + prior_weight) / (1 + prior_weight). 0: no prior (the gains follow the chain of overlaps wherever it
  /// drifts).
  double prior_weight = 0.1;
  /// Gains are clamped to [1 / max_gain, max_gain], [1, 10].
  double max_gain = 3.0;
  /// Huber threshold in robust sigmas (1.4826 x the median absolute residual of the cells, at least 1 grey level),
  /// [0.5, 100]; cells beyond 3 x this are dropped (lighting artefacts, content not yet aligned). 100: plain least
  /// squares in effect.
  double huber_k = 2.0;
  /// Seam ramp (cells), [0, 1000]: the overlap's cells get the fitted gain WITHOUT the prior (no step at the seam)
  /// and the gain eases (raised cosine) to the prior-pulled gain over this distance from them. 0: one uniform
  /// gain, the prior-pulled one, over the whole tile (its seam keeps prior_weight / (1 + prior_weight) of the step).
  double seam_ramp_cells = 12.0;
  /// Folder where the records beyond cells_in_memory_tiles (the least recently recorded) are written out, their cells
  /// and ramp read back when a new tile overlaps them or their gains are asked for: memory does not grow with the
  /// dive. Empty: every record stays in memory. A record that cannot be written stays in memory (spillFailures()).
  std::string cells_folder;
  int cells_in_memory_tiles = 16;  ///< records whose cells stay in memory with cells_folder, [1, 100000]

  /// Empty if usable, otherwise every bad field with its allowed range, separated by "; ".
  std::string validate() const;
};

/**
 * @brief The correction of one tile. Model, per channel c: corrected = saturate(g_c(x) * raw), no offset (lighting
 * and exposure differences are multiplicative; an offset would be poorly determined by small overlaps). g_c(x) =
 * far_gain[c] + ramp(x) * (gain[c] - far_gain[c]), ramp 1 on the overlap's cells and easing to 0 away from them;
 * without a ramp (empty) g_c = far_gain[c] everywhere.
 */
struct TileGains {
  int channels = 1;                         ///< 1 (grey) or 3 (BGR); the gains of channel c are at [c]
  std::array<double, 3> gain{1, 1, 1};      ///< on the overlap
  std::array<double, 3> far_gain{1, 1, 1};  ///< away from the overlap (the prior-pulled gain); everywhere if no ramp
  bool from_overlap = false;  ///< false: no overlap, the gains are the last recorded tile's far gains (or 1)
  int common_cells = 0;       ///< cells the new tile shares with the written ones
  int inlier_cells = 0;       ///< of those, the cells the robust fit kept in every channel
  /// Mean-level difference raw tile - written tiles over the common cells (luma, grey levels) before and after the
  /// correction; 0 without overlap.
  double step_before_grey = 0.0;
  double step_after_grey = 0.0;

  /// The seam ramp over the tile's cells (CV_8U, 255 = 1: gain, 0: far_gain; row 0 the northernmost cell), empty:
  /// uniform far_gain.
  cv::Mat ramp;
  std::int64_t ramp_cell_west = 0;   ///< cell column (easting / cell_size_m, floored) of the ramp's column 0
  std::int64_t ramp_cell_north = 0;  ///< cell row (northing / cell_size_m, floored) of the ramp's row 0
  double cell_size_m = 0.0;          ///< side of the cells the ramp is on
};

/**
 * @brief The gain per channel that TileGainCompensator::apply() multiplies the pixel at ground point (east_m,
 * north_m) by (the raster's frame, m): far_gain blended towards gain by the ramp, bilinear between cell centres as
 * apply() samples it, the border cells beyond the ramp; far_gain without a ramp. Channels beyond gains.channels are 1.
 */
std::array<double, 3> gainAt(const TileGains& gains, double east_m, double north_m);

/**
 * @brief Live gain compensation between tiles. Keeps per recorded tile (by index) its cells' corrected mean levels
 * and coverage (uint16 each) and its gains with their seam ramp (1 byte per cell): 2 x (channels + 1) + 1 bytes per
 * cell over the bounding box of the tile's data, e.g. 9 KB for a 512 x 512 px BGR tile with 16 px cells, 37 KB for
 * 1024 x 1024, 210 KB for a 3500 x 1700 px PAL tile (memoryBytes()): memory grows by that per tile, never with
 * pixels, unless TileGainConfig::cells_folder takes the older records out of memory. Not thread-safe: call it from
 * one thread (the tile writer's).
 *
 * All tiles must share one frame (UTM zone and hemisphere, or local frame): tiles of another frame than the first
 * one seen, or of another channel count, have no overlap with the records.
 */
class TileGainCompensator {
 public:
  /// Throws std::invalid_argument with config.validate()'s text.
  explicit TileGainCompensator(const TileGainConfig& config = TileGainConfig());

  const TileGainConfig& config() const { return config_; }

  /**
   * @brief Gains for a new tile (raw, uncorrected) so that its overlap with the recorded tiles (other than
   * tile_index itself) matches them: per channel, robust (Huber IRLS, trimmed) weighted least squares of
   * gain * raw cell mean = written cell mean over the common cells, weight = the smaller coverage, then the prior (see
   * TileGainConfig::prior_weight) and the clamp. Without overlap: the far gains of the last recorded tile (a pass's
   * consecutive tiles share its lighting, so that is the best guess of the camera's current level) pulled once more
   * by the prior, or 1 if nothing was recorded. Does not change the records.
   */
  TileGains estimate(const tiles::TileRaster& raster, int tile_index) const;

  /// The raster corrected by gains (CV_8U, saturating; mask and geo-reference unchanged). Throws
  /// std::invalid_argument if the channel counts differ.
  static tiles::TileRaster apply(const tiles::TileRaster& raster, const TileGains& gains);

  /**
   * @brief Records a written tile: its cells (from the CORRECTED raster) and gains. Recording an index again
   * (a re-rendered version) replaces its record. The first tile recorded fixes the cell grid (and the frame).
   */
  void record(int tile_index, const tiles::TileRaster& corrected, const TileGains& gains);

  /// The gains recorded for tile_index (to re-render it consistently), nullopt if none.
  std::optional<TileGains> gainsOf(int tile_index) const;

  /// Forgets a tile; false if it was not recorded.
  bool forget(int tile_index);
  void clear();

  std::size_t tileCount() const { return records_.size(); }
  /// Bytes held in memory by the records (cells and ramps; not those written out).
  std::size_t memoryBytes() const;
  /// Records whose cells and ramp are written out to config().cells_folder.
  std::size_t spilledCount() const;
  /// Records that could not be written out (kept in memory), and written-out records that could not be read back
  /// (left out of that estimate, or their gains without a ramp).
  std::int64_t spillFailures() const { return spill_failures_; }
  std::int64_t readFailures() const { return read_failures_; }
  /// Side of the cells (m), 0 before the first tile.
  double cellSizeM() const { return cell_size_m_; }

 private:
  struct Record {
    std::int64_t cell_west = 0, cell_north = 0;  // cell column / row of cells(0, 0)
    cv::Mat cells;                               // CV_16UC(channels + 1): mean * 256 per channel, then coverage * 65535
    TileGains gains;
    std::uint64_t sequence = 0;  // order of recording, for the no-overlap guess
    int cell_rows = 0, cell_cols = 0, cell_channels = 0;  // of cells, also when written out
    std::string file;  // where cells and gains.ramp are written out (both empty in memory then); empty: in memory
  };
  /// Writes the oldest records in memory out until at most cells_in_memory_tiles remain (with cells_folder).
  void spillBeyondLimit();
  /// Reads a written-out record's cells and ramp; false (counted) if the file does not read back.
  bool readBack(const Record& record, cv::Mat* cells, cv::Mat* ramp) const;
  void removeFile(const Record& record) const;

  TileGainConfig config_;
  double cell_size_m_ = 0.0;  // fixed by the first record
  std::string frame_;         // of the first record: tiles of another frame have no overlap
  std::map<int, Record> records_;
  std::uint64_t next_sequence_ = 0;
  std::int64_t spill_failures_ = 0;
  mutable std::int64_t read_failures_ = 0;
};

}  // namespace compose
}  // namespace exocet_mosaic
