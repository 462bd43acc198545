/**
 * @file image_gain_window.h
 * @brief Which written tiles a live image-gain solve takes, so that its size does not grow with the dive: the most
 * recent tiles are solved, the older tiles that overlap them lend the gains they were drawn with as anchors
 * (compose::ImageGains::solve with fixed gains), and the rest stay as drawn. Also which tiles' image levels to keep
 * in memory (the most recently used) and which to let go (read back from the kept images when a tile is used again).
 * No ROS in it.
 */
#pragma once

#include <array>
#include <cstddef>
#include <list>
#include <map>
#include <vector>

#include "exocet_mosaic/tiles/tile_revisions.h"

namespace exocet_mosaic {
namespace tiles {

/// Tiles of one gain solve.
struct GainWindow {
  std::vector<int> solved;   ///< tile indices whose images' gains are solved, increasing
  std::vector<int> anchors;  ///< older tiles overlapping them: their images' gains are fixed as drawn, increasing
};

/// The ground box (UTM, m) of a tile's images as its current version draws them: min E, min N, max E, max N; all NaN
/// for a tile without images.
std::array<double, 4> tileImagesBox(const TileRecord& record);

/**
 * @brief The `solved_tiles` tiles of highest index are solved; every other tile whose images' box overlaps the box of
 * one of them is an anchor. `solved_tiles` 0: every tile is solved, none is an anchor (a solve of the whole dive).
 */
GainWindow gainWindow(const std::map<int, TileRecord>& records, int solved_tiles);

/// Tiles whose image levels are in memory, most recently used first; the least recently used let go beyond a bound.
class TileLevelsCache {
 public:
  /// @param max_tiles tiles kept, >= 1
  explicit TileLevelsCache(std::size_t max_tiles) : max_tiles_(max_tiles < 1 ? 1 : max_tiles) {}
  /// Marks the tiles as used now. @return the tiles let go (least recently used beyond the bound), whose levels the
  /// caller drops
  std::vector<int> use(const std::vector<int>& tiles);
  std::size_t size() const { return order_.size(); }
  bool contains(int tile) const { return where_.count(tile) > 0; }

 private:
  std::size_t max_tiles_;
  std::list<int> order_;  ///< most recent first
  std::map<int, std::list<int>::iterator> where_;
};

}  // namespace tiles
}  // namespace exocet_mosaic
