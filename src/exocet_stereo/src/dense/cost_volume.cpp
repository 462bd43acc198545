// Census + colour + gradient matching cost volume.
#include "exocet_stereo/dense/cost_volume.h"

#include <algorithm>
#include <cmath>
#include <cstdint>

#include <opencv2/imgproc.hpp>

namespace exocet_stereo {
namespace dense {
namespace {

// Census signature: one bit per window pixel darker than the centre (centre skipped), borders replicated.
std::vector<uint64_t> censusTransform(const cv::Mat& gray, int radius) {
  cv::Mat padded;
  cv::copyMakeBorder(gray, padded, radius, radius, radius, radius, cv::BORDER_REPLICATE);
  std::vector<uint64_t> census(static_cast<size_t>(gray.rows) * gray.cols, 0);
  for (int y = 0; y < gray.rows; ++y) {
    for (int x = 0; x < gray.cols; ++x) {
      const uint8_t centre = padded.at<uint8_t>(y + radius, x + radius);
      uint64_t bits = 0;
      for (int dy = -radius; dy <= radius; ++dy) {
        const uint8_t* row = padded.ptr<uint8_t>(y + radius + dy) + x + radius;
        for (int dx = -radius; dx <= radius; ++dx) {
          if (dx == 0 && dy == 0) continue;
          bits = (bits << 1) | (row[dx] < centre ? 1u : 0u);
        }
      }
      census[static_cast<size_t>(y) * gray.cols + x] = bits;
    }
  }
  return census;
}

cv::Mat horizontalGradient(const cv::Mat& gray) {
  cv::Mat gradient;
  cv::Sobel(gray, gradient, CV_32F, 1, 0, 1, 0.5, 0.0, cv::BORDER_REPLICATE);  // (I(x+1) - I(x-1)) / 2
  return gradient;
}

}  // namespace

cv::Mat toGray(const cv::Mat& image) {
  if (image.channels() == 1) return image;
  cv::Mat gray;
  cv::cvtColor(image, gray, cv::COLOR_BGR2GRAY);
  return gray;
}

CostVolume buildCostVolume(const cv::Mat& left, const cv::Mat& right, const DenseStereoConfig& config) {
  const int rows = left.rows, cols = left.cols, labels = config.labelCount();
  const int radius = config.census_radius_px;
  const int census_bits = (2 * radius + 1) * (2 * radius + 1) - 1;
  const float max_cost =
      static_cast<float>(config.census_weight * census_bits + config.color_weight * config.color_truncation +
                         config.gradient_weight * config.gradient_truncation);
  CostVolume volume(rows, cols, labels, max_cost);
  volume.max_cost = max_cost;

  const cv::Mat gray_left = toGray(left), gray_right = toGray(right);
  const std::vector<uint64_t> census_left = censusTransform(gray_left, radius);
  const std::vector<uint64_t> census_right = censusTransform(gray_right, radius);
  const cv::Mat grad_left = horizontalGradient(gray_left), grad_right = horizontalGradient(gray_right);
  const int channels = left.channels();
  const float census_w = static_cast<float>(config.census_weight);
  const float color_w = static_cast<float>(config.color_weight) / channels;  // mean over channels
  const float color_t = static_cast<float>(config.color_truncation) * channels;
  const float grad_w = static_cast<float>(config.gradient_weight);
  const float grad_t = static_cast<float>(config.gradient_truncation);

  for (int y = 0; y < rows; ++y) {
    const uint8_t* l_row = left.ptr<uint8_t>(y);
    const uint8_t* r_row = right.ptr<uint8_t>(y);
    const float* gl_row = grad_left.ptr<float>(y);
    const float* gr_row = grad_right.ptr<float>(y);
    const uint64_t* cl_row = census_left.data() + static_cast<size_t>(y) * cols;
    const uint64_t* cr_row = census_right.data() + static_cast<size_t>(y) * cols;
    for (int x = 0; x < cols; ++x) {
      float* cost = volume.at(y, x);
      const int d_end = std::min(labels - 1, x);
      for (int d = 0; d <= d_end; ++d) {
        const int xr = x - d;
        int color_sum = 0;
        for (int c = 0; c < channels; ++c) color_sum += std::abs(l_row[x * channels + c] - r_row[xr * channels + c]);
        const float color = std::min(static_cast<float>(color_sum), color_t);
        const float grad = std::min(std::fabs(gl_row[x] - gr_row[xr]), grad_t);
        const int hamming = __builtin_popcountll(cl_row[x] ^ cr_row[xr]);
        cost[d] = census_w * hamming + color_w * color + grad_w * grad;
      }
    }
  }
  return volume;
}

CostVolume rightViewVolume(const CostVolume& left_volume) {
  CostVolume right(left_volume.rows, left_volume.cols, left_volume.labels, left_volume.max_cost);
  right.max_cost = left_volume.max_cost;
  for (int y = 0; y < right.rows; ++y) {
    for (int x = 0; x < right.cols; ++x) {
      float* cost = right.at(y, x);
      const int d_end = std::min(right.labels - 1, right.cols - 1 - x);
      for (int d = 0; d <= d_end; ++d) cost[d] = left_volume.at(y, x + d)[d];
    }
  }
  return right;
}

void boxAggregate(CostVolume* volume, int radius_px) {
  if (radius_px <= 0) return;
  const int labels = volume->labels;
  // One slice at a time: the [y][x][d] layout keeps per-pixel costs contiguous for the optimisers.
  cv::Mat slice(volume->rows, volume->cols, CV_32F), filtered;
  const cv::Size window(2 * radius_px + 1, 2 * radius_px + 1);
  for (int d = 0; d < labels; ++d) {
    for (int y = 0; y < volume->rows; ++y) {
      float* row = slice.ptr<float>(y);
      for (int x = 0; x < volume->cols; ++x) row[x] = volume->at(y, x)[d];
    }
    cv::boxFilter(slice, filtered, CV_32F, window, cv::Point(-1, -1), true, cv::BORDER_REPLICATE);
    for (int y = 0; y < volume->rows; ++y) {
      const float* row = filtered.ptr<float>(y);
      for (int x = 0; x < volume->cols; ++x) volume->at(y, x)[d] = row[x];
    }
  }
}

}  // namespace dense
}  // namespace exocet_stereo
