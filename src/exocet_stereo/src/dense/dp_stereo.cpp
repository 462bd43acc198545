// Dynamic programming per scanline with an explicit occlusion model (ordering constraint).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include "exocet_stereo/dense/methods.h"
#include "exocet_stereo/dense/post_processing.h"

namespace exocet_stereo {
namespace dense {

// States at pixel x with path disparity d: M (x matched to x - d) and O (x visible only in the left image). Moves:
//   M(x-1, d) or O(x-1, d)          -> M(x, d)   (same disparity; O -> M closes a left occlusion)
//   M/O(x-1, d')  with d' > d       -> M(x, d)   (disparity drops: d' - d right pixels unseen, each costs occlusion)
//   M/O(x-1, d - 1)                 -> O(x, d)   (each left-occluded pixel raises the path disparity by one, so the
//                                                 foreground after it is reached with a consistent geometry)
cv::Mat DpStereo::solve(const CostVolume& volume, const cv::Mat& /*gray*/) const {
  const int rows = volume.rows, cols = volume.cols, labels = volume.labels;
  const float occlusion = static_cast<float>(config_.occlusion_cost);
  const float vertical = static_cast<float>(config_.dp_vertical_weight);
  constexpr float kInf = std::numeric_limits<float>::infinity();
  cv::Mat disparity(rows, cols, CV_32F, cv::Scalar(std::numeric_limits<float>::quiet_NaN()));
  std::vector<float> m_prev(labels), o_prev(labels), m_cur(labels), o_cur(labels), best(labels), jump(labels);
  std::vector<int> best_from(labels), jump_from(labels);
  // Back-pointers: for M, the previous state encoded as 2 * d' + (1 if O); for O, 1 if the previous state was O.
  std::vector<int16_t> back_m(static_cast<size_t>(cols) * labels);
  std::vector<uint8_t> back_o(static_cast<size_t>(cols) * labels);
  std::vector<float> previous_line(cols, std::numeric_limits<float>::quiet_NaN());

  for (int y = 0; y < rows; ++y) {
    for (int d = 0; d < labels; ++d) {
      m_prev[d] = volume.at(y, 0)[d];
      o_prev[d] = occlusion;
    }
    for (int x = 1; x < cols; ++x) {
      for (int d = 0; d < labels; ++d) {
        const bool from_o = o_prev[d] < m_prev[d];
        best[d] = from_o ? o_prev[d] : m_prev[d];
        best_from[d] = 2 * d + (from_o ? 1 : 0);
      }
      // jump(d) = min over d' > d of best(d') + occlusion * (d' - d), computed from the top down.
      jump[labels - 1] = kInf;
      jump_from[labels - 1] = -1;
      for (int d = labels - 2; d >= 0; --d) {
        const float via_next = best[d + 1] + occlusion, via_jump = jump[d + 1] + occlusion;
        jump[d] = std::min(via_next, via_jump);
        jump_from[d] = via_next <= via_jump ? best_from[d + 1] : jump_from[d + 1];
      }
      const float* cost = volume.at(y, x);
      const float above = previous_line[x];
      for (int d = 0; d < labels; ++d) {
        float data = cost[d];
        if (vertical > 0.0f && std::isfinite(above)) data += vertical * std::min(std::fabs(d - above), 3.0f);
        const bool use_jump = jump[d] < best[d];
        m_cur[d] = data + (use_jump ? jump[d] : best[d]);
        back_m[static_cast<size_t>(x) * labels + d] = static_cast<int16_t>(use_jump ? jump_from[d] : best_from[d]);
        if (d == 0) {
          o_cur[d] = kInf;
          back_o[static_cast<size_t>(x) * labels] = 0;
        } else {
          const bool o_from_o = o_prev[d - 1] < m_prev[d - 1];
          o_cur[d] = occlusion + (o_from_o ? o_prev[d - 1] : m_prev[d - 1]);
          back_o[static_cast<size_t>(x) * labels + d] = o_from_o ? 1 : 0;
        }
      }
      std::swap(m_prev, m_cur);
      std::swap(o_prev, o_cur);
    }
    // Backtrack from the best final state.
    int d = 0;
    bool occluded = false;
    float best_final = kInf;
    for (int k = 0; k < labels; ++k) {
      if (m_prev[k] < best_final) {
        best_final = m_prev[k];
        d = k;
        occluded = false;
      }
      if (o_prev[k] < best_final) {
        best_final = o_prev[k];
        d = k;
        occluded = true;
      }
    }
    float* out = disparity.ptr<float>(y);
    for (int x = cols - 1; x >= 1; --x) {
      if (occluded) {
        occluded = back_o[static_cast<size_t>(x) * labels + d] != 0;
        d -= 1;
      } else {
        out[x] = static_cast<float>(d);
        const int from = back_m[static_cast<size_t>(x) * labels + d];
        d = from / 2;
        occluded = (from % 2) != 0;
      }
    }
    if (!occluded) out[0] = static_cast<float>(d);
    const float* line = disparity.ptr<float>(y);
    std::copy(line, line + cols, previous_line.begin());
  }
  if (config_.subpixel) refineSubpixel(volume, &disparity);
  return disparity;
}

}  // namespace dense
}  // namespace exocet_stereo
