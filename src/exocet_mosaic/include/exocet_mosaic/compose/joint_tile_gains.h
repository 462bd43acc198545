/**
 * @file joint_tile_gains.h
 * @brief Gains of a whole set of tiles solved together (after the dive, or when a dive's tiles are all drawn again):
 * as OpenCV's stitcher GainCompensator solves its images' gains, one gain per tile and channel minimising the
 * level differences over every overlap at once, with a prior pulling each gain towards 1. The live, incremental
 * TileGainCompensator matches each new tile to those before it; solved jointly, the steps a pass leaves against a
 * later one are shared instead of carried. Works on coarse ground cells, never on pixels. No ROS in it.
 */
#pragma once

#include <array>
#include <map>
#include <string>

#include <opencv2/core.hpp>

#include "exocet_mosaic/tiles/tile_raster.h"

namespace exocet_mosaic {
namespace compose {

/// Parameters of JointTileGains. validate() lists the allowed ranges.
struct JointTileGainsConfig {
  int cell_size_px = 16;            ///< ground cells, in pixels of the first tile added, [4, 128]
  double min_cell_coverage = 0.6;   ///< a cell counts where both tiles cover this much of it, [0.05, 1]
  int min_common_cells = 4;         ///< fewer common cells: the pair is not used, [1, 100000]
  /// Prior 1-sigma of a gain's logarithm against the overlaps' 1-sigma, as a ratio [1e-3, 100]: 1 weighs a tile's
  /// unit gain as much as one pair's measured ratio.
  double prior_weight = 0.05;
  double max_gain = 3.0;  ///< gains clamped to [1 / max_gain, max_gain], [1, 10]
  std::string validate() const;
};

/// Uniform per-channel gains of each tile, solved over all their overlaps.
class JointTileGains {
 public:
  /// @throws std::invalid_argument with config.validate()'s text
  explicit JointTileGains(const JointTileGainsConfig& config = JointTileGainsConfig());
  /// Adds (or replaces) a tile's levels: its cells of the raster as drawn, before any gain. Tiles of another frame
  /// or channel count than the first one's are ignored.
  void add(int tile_index, const tiles::TileRaster& raster);
  /**
   * @brief The gains: per channel, least squares over the pairs of tiles that overlap of log g_a - log g_b = the
   * median over their common cells of log(level_b / level_a), each pair weighted by its common cells, plus the
   * prior towards log g = 0. Tiles without overlap get 1.
   * @return per tile index, the gain of each channel (BGR order; grey: [0])
   */
  std::map<int, std::array<double, 3>> solve() const;
  std::size_t tileCount() const { return cells_.size(); }

 private:
  struct Cells {
    std::int64_t west = 0, north = 0;
    cv::Mat mean;      // CV_32FC(channels)
    cv::Mat coverage;  // CV_32F
  };
  JointTileGainsConfig config_;
  double cell_size_m_ = 0;
  int channels_ = 0;
  std::string frame_;
  std::map<int, Cells> cells_;
};

}  // namespace compose
}  // namespace exocet_mosaic
