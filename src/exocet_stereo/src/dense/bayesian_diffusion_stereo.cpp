// Bayesian diffusion of the disparity probability volume (after Scharstein & Szeliski 1998).
#include <algorithm>
#include <cmath>
#include <vector>

#include "exocet_stereo/dense/methods.h"
#include "exocet_stereo/dense/post_processing.h"

namespace exocet_stereo {
namespace dense {

cv::Mat BayesianDiffusionStereo::solve(const CostVolume& volume, const cv::Mat& gray) const {
  const int rows = volume.rows, cols = volume.cols, labels = volume.labels;
  const size_t cells = volume.data.size();
  const float temperature = static_cast<float>(config_.bd_temperature);
  const float outlier = static_cast<float>(config_.bd_outlier_probability) / labels;
  const float weight = static_cast<float>(config_.bd_neighbour_weight);

  // Data likelihood per pixel, normalised over disparities.
  std::vector<float> likelihood(cells);
  for (int p = 0; p < rows * cols; ++p) {
    const float* cost = volume.data.data() + static_cast<size_t>(p) * labels;
    float* out = likelihood.data() + static_cast<size_t>(p) * labels;
    const float best = *std::min_element(cost, cost + labels);
    float sum = 0.0f;
    for (int d = 0; d < labels; ++d) sum += out[d] = std::exp(-(cost[d] - best) / temperature);
    for (int d = 0; d < labels; ++d) out[d] /= sum;
  }
  std::vector<float> belief = likelihood, next(cells), message(labels);

  static const int kNeighbours[4][2] = {{1, 0}, {-1, 0}, {0, 1}, {0, -1}};
  for (int iteration = 0; iteration < config_.bd_iterations; ++iteration) {
    for (int y = 0; y < rows; ++y) {
      const uint8_t* grey = gray.ptr<uint8_t>(y);
      for (int x = 0; x < cols; ++x) {
        float* out = next.data() + (static_cast<size_t>(y) * cols + x) * labels;
        std::copy_n(likelihood.data() + (static_cast<size_t>(y) * cols + x) * labels, labels, out);
        for (const auto& n : kNeighbours) {
          const int xn = x + n[0], yn = y + n[1];
          if (xn < 0 || xn >= cols || yn < 0 || yn >= rows) continue;
          const float* b = belief.data() + (static_cast<size_t>(yn) * cols + xn) * labels;
          // Weaker coupling across grey-level steps, where disparity edges usually are.
          const float w = std::abs(grey[x] - gray.ptr<uint8_t>(yn)[xn]) > config_.contrast_threshold
                              ? weight / static_cast<float>(config_.contrast_factor)
                              : weight;
          // Neighbour's distribution diffused by the prior: same disparity, half weight at +-1, outlier floor.
          float sum = 0.0f;
          for (int d = 0; d < labels; ++d) {
            float m = b[d];
            if (d > 0) m += 0.5f * b[d - 1];
            if (d + 1 < labels) m += 0.5f * b[d + 1];
            message[d] = m;
            sum += m;
          }
          const float scale = labels / sum;  // mean 1 over disparities
          for (int d = 0; d < labels; ++d) out[d] *= (1.0f - w) + w * (message[d] * scale + outlier * labels);
        }
        float sum = 0.0f;
        for (int d = 0; d < labels; ++d) sum += out[d];
        const float inverse = sum > 0.0f ? 1.0f / sum : 0.0f;
        for (int d = 0; d < labels; ++d) out[d] = sum > 0.0f ? out[d] * inverse : 1.0f / labels;
      }
    }
    std::swap(belief, next);
  }

  cv::Mat disparity(rows, cols, CV_32F);
  for (int p = 0; p < rows * cols; ++p) {
    const float* b = belief.data() + static_cast<size_t>(p) * labels;
    disparity.at<float>(p / cols, p % cols) = static_cast<float>(std::max_element(b, b + labels) - b);
  }
  if (config_.subpixel) refineSubpixel(volume, &disparity);
  return disparity;
}

}  // namespace dense
}  // namespace exocet_stereo
