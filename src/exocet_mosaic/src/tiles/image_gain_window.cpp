#include "exocet_mosaic/tiles/image_gain_window.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace exocet_mosaic {
namespace tiles {

std::array<double, 4> tileImagesBox(const TileRecord& record) {
  constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  double min_e = std::numeric_limits<double>::infinity(), min_n = min_e, max_e = -min_e, max_n = -min_e;
  for (const RecordedImage& image : record.images) {
    const double w = image.width_px, h = image.height_px;
    for (const auto& [u, v] : {std::array<double, 2>{0, 0}, {w, 0}, {w, h}, {0, h}}) {
      const cv::Vec3d g = record.adjustment * (image.ground_from_px * cv::Vec3d(u, v, 1.0));
      if (!(std::abs(g[2]) > 1e-12)) continue;
      const double e = g[0] / g[2] + record.ground_origin_en_m.x(), n = g[1] / g[2] + record.ground_origin_en_m.y();
      if (!std::isfinite(e) || !std::isfinite(n)) continue;
      min_e = std::min(min_e, e);
      max_e = std::max(max_e, e);
      min_n = std::min(min_n, n);
      max_n = std::max(max_n, n);
    }
  }
  if (!(max_e >= min_e)) return {kNaN, kNaN, kNaN, kNaN};
  return {min_e, min_n, max_e, max_n};
}

GainWindow gainWindow(const std::map<int, TileRecord>& records, int solved_tiles) {
  GainWindow window;
  if (solved_tiles <= 0 || static_cast<std::size_t>(solved_tiles) >= records.size()) {
    for (const auto& [index, record] : records) window.solved.push_back(index);
    return window;
  }
  auto first_solved = records.end();
  std::advance(first_solved, -solved_tiles);
  std::vector<std::array<double, 4>> boxes;
  for (auto it = first_solved; it != records.end(); ++it) {
    window.solved.push_back(it->first);
    const auto box = tileImagesBox(it->second);
    if (std::isfinite(box[0])) boxes.push_back(box);
  }
  for (auto it = records.begin(); it != first_solved; ++it) {
    const auto box = tileImagesBox(it->second);
    if (!std::isfinite(box[0])) continue;
    const bool overlaps = std::any_of(boxes.begin(), boxes.end(), [&](const std::array<double, 4>& b) {
      return box[0] < b[2] && b[0] < box[2] && box[1] < b[3] && b[1] < box[3];
    });
    if (overlaps) window.anchors.push_back(it->first);
  }
  return window;
}

std::vector<int> TileLevelsCache::use(const std::vector<int>& tiles) {
  for (const int tile : tiles) {
    const auto found = where_.find(tile);
    if (found != where_.end()) order_.erase(found->second);
    order_.push_front(tile);
    where_[tile] = order_.begin();
  }
  std::vector<int> let_go;
  while (order_.size() > max_tiles_) {
    let_go.push_back(order_.back());
    where_.erase(order_.back());
    order_.pop_back();
  }
  return let_go;
}

}  // namespace tiles
}  // namespace exocet_mosaic
