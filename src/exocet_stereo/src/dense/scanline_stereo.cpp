// Scanline optimisation (exact 1D Viterbi per scanline) and its semi-global multi-direction variant.
#include <algorithm>
#include <cmath>
#include <vector>

#include "exocet_stereo/dense/methods.h"
#include "exocet_stereo/dense/post_processing.h"

namespace exocet_stereo {
namespace dense {
namespace {

// Large-jump penalty between neighbours p and q: weakened across grey-level steps, where depth edges usually are.
inline float largePenalty(const DenseStereoConfig& config, int grey_p, int grey_q) {
  const float p2 = static_cast<float>(config.penalty_large);
  return std::abs(grey_p - grey_q) > config.contrast_threshold
             ? std::max(static_cast<float>(config.penalty_small), p2 / static_cast<float>(config.contrast_factor))
             : p2;
}

// One step of the SO/SGM recursion: out(d) = cost(d) + min(prev(d), prev(d+-1) + p1, min prev + p2) - min prev.
inline void aggregateStep(const float* cost, const float* prev, int labels, float p1, float p2, float* out) {
  const float prev_min = *std::min_element(prev, prev + labels);
  const float jump = prev_min + p2;
  for (int d = 0; d < labels; ++d) {
    float best = prev[d];
    if (d > 0) best = std::min(best, prev[d - 1] + p1);
    if (d + 1 < labels) best = std::min(best, prev[d + 1] + p1);
    best = std::min(best, jump);
    out[d] = cost[d] + best - prev_min;
  }
}

// Sum into `total` the path costs along direction (dx, dy).
void aggregateDirection(const CostVolume& volume, const cv::Mat& gray, const DenseStereoConfig& config, int dx, int dy,
                        CostVolume* total) {
  const int rows = volume.rows, cols = volume.cols, labels = volume.labels;
  const float p1 = static_cast<float>(config.penalty_small);
  std::vector<float> previous_row(static_cast<size_t>(cols) * labels), current_row(previous_row.size());
  for (int i = 0; i < rows; ++i) {
    const int y = dy >= 0 ? i : rows - 1 - i;
    const uint8_t* grey = gray.ptr<uint8_t>(y);
    const uint8_t* grey_prev = (y - dy >= 0 && y - dy < rows) ? gray.ptr<uint8_t>(y - dy) : nullptr;
    for (int j = 0; j < cols; ++j) {
      const int x = dx >= 0 ? j : cols - 1 - j;
      const int xp = x - dx, yp = y - dy;
      const float* cost = volume.at(y, x);
      float* out = current_row.data() + static_cast<size_t>(x) * labels;
      if (xp < 0 || xp >= cols || yp < 0 || yp >= rows) {
        std::copy(cost, cost + labels, out);
      } else {
        const float* prev = (dy == 0 ? current_row.data() : previous_row.data()) + static_cast<size_t>(xp) * labels;
        const int grey_q = dy == 0 ? grey[xp] : grey_prev[xp];
        aggregateStep(cost, prev, labels, p1, largePenalty(config, grey[x], grey_q), out);
      }
      float* sum = total->at(y, x);
      for (int d = 0; d < labels; ++d) sum[d] += out[d];
    }
    std::swap(previous_row, current_row);
  }
}

// Exact minimum of data + smoothness along each row (Viterbi forward pass, then backtracking).
cv::Mat scanlineOptimise(const CostVolume& volume, const cv::Mat& gray, const DenseStereoConfig& config) {
  const int rows = volume.rows, cols = volume.cols, labels = volume.labels;
  const float p1 = static_cast<float>(config.penalty_small);
  cv::Mat disparity(rows, cols, CV_32F);
  std::vector<float> path(static_cast<size_t>(cols) * labels);
  for (int y = 0; y < rows; ++y) {
    const uint8_t* grey = gray.ptr<uint8_t>(y);
    std::copy(volume.at(y, 0), volume.at(y, 0) + labels, path.begin());
    for (int x = 1; x < cols; ++x)
      aggregateStep(volume.at(y, x), &path[static_cast<size_t>(x - 1) * labels], labels, p1,
                    largePenalty(config, grey[x], grey[x - 1]), &path[static_cast<size_t>(x) * labels]);
    float* out = disparity.ptr<float>(y);
    const float* last = &path[static_cast<size_t>(cols - 1) * labels];
    int next = static_cast<int>(std::min_element(last, last + labels) - last);
    out[cols - 1] = static_cast<float>(next);
    for (int x = cols - 2; x >= 0; --x) {
      const float* l = &path[static_cast<size_t>(x) * labels];
      const float p2 = largePenalty(config, grey[x + 1], grey[x]);
      int best = next;
      float best_value = l[next];
      for (int d = 0; d < labels; ++d) {
        const int step = std::abs(d - next);
        const float value = l[d] + (step == 0 ? 0.0f : step == 1 ? p1 : p2);
        if (value < best_value) {
          best_value = value;
          best = d;
        }
      }
      out[x] = static_cast<float>(best);
      next = best;
    }
  }
  return disparity;
}

}  // namespace

cv::Mat ScanlineStereo::solve(const CostVolume& volume, const cv::Mat& gray) const {
  if (!semi_global_) {
    cv::Mat disparity = scanlineOptimise(volume, gray, config_);
    if (config_.subpixel) refineSubpixel(volume, &disparity);
    return disparity;
  }
  static const int kDirections[8][2] = {{1, 0}, {-1, 0}, {0, 1}, {0, -1}, {1, 1}, {-1, 1}, {1, -1}, {-1, -1}};
  CostVolume total(volume.rows, volume.cols, volume.labels, 0.0f);
  for (int i = 0; i < config_.sgm_paths; ++i)
    aggregateDirection(volume, gray, config_, kDirections[i][0], kDirections[i][1], &total);
  return winnerTakeAll(total, config_.subpixel);
}

}  // namespace dense
}  // namespace exocet_stereo
