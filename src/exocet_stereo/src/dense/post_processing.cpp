// Winner-take-all, sub-pixel fit, left-right check, hole filling and median shared by every method.
#include "exocet_stereo/dense/post_processing.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <utility>
#include <vector>

#include <opencv2/imgproc.hpp>

namespace exocet_stereo {
namespace dense {
namespace {
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
}  // namespace

float parabolaOffset(float c_minus, float c0, float c_plus) {
  const float curvature = c_minus + c_plus - 2.0f * c0;
  if (!(curvature > 1e-6f)) return 0.0f;
  const float offset = 0.5f * (c_minus - c_plus) / curvature;
  return std::max(-0.5f, std::min(0.5f, offset));
}

cv::Mat winnerTakeAll(const CostVolume& volume, bool subpixel) {
  cv::Mat disparity(volume.rows, volume.cols, CV_32F);
  for (int y = 0; y < volume.rows; ++y) {
    float* out = disparity.ptr<float>(y);
    for (int x = 0; x < volume.cols; ++x) {
      const float* cost = volume.at(y, x);
      const int best = static_cast<int>(std::min_element(cost, cost + volume.labels) - cost);
      float d = static_cast<float>(best);
      if (subpixel && best > 0 && best < volume.labels - 1)
        d += parabolaOffset(cost[best - 1], cost[best], cost[best + 1]);
      out[x] = d;
    }
  }
  return disparity;
}

void refineSubpixel(const CostVolume& volume, cv::Mat* disparity) {
  for (int y = 0; y < volume.rows; ++y) {
    float* row = disparity->ptr<float>(y);
    for (int x = 0; x < volume.cols; ++x) {
      if (!std::isfinite(row[x])) continue;
      const int d = static_cast<int>(std::lround(row[x]));
      if (d <= 0 || d >= volume.labels - 1) continue;
      const float* cost = volume.at(y, x);
      // Only refine at a local minimum of the cost, otherwise the parabola says nothing about this label.
      if (cost[d] <= cost[d - 1] && cost[d] <= cost[d + 1])
        row[x] = d + parabolaOffset(cost[d - 1], cost[d], cost[d + 1]);
    }
  }
}

cv::Mat leftRightCheck(const cv::Mat& disparity_left, const cv::Mat& disparity_right, double tolerance_px) {
  cv::Mat checked = disparity_left.clone();
  const float tolerance = static_cast<float>(tolerance_px);
  for (int y = 0; y < checked.rows; ++y) {
    float* row = checked.ptr<float>(y);
    const float* right_row = disparity_right.ptr<float>(y);
    for (int x = 0; x < checked.cols; ++x) {
      const float d = row[x];
      if (!std::isfinite(d)) {
        row[x] = kNaN;
        continue;
      }
      const int xr = static_cast<int>(std::lround(x - d));
      if (xr < 0 || xr >= checked.cols || !std::isfinite(right_row[xr]) || std::fabs(right_row[xr] - d) > tolerance)
        row[x] = kNaN;
    }
  }
  return checked;
}

cv::Mat classifyInvalidPixels(const cv::Mat& checked, const cv::Mat& disparity_left, const cv::Mat& disparity_right,
                              double tolerance_px) {
  if (checked.type() != CV_32F || disparity_left.type() != CV_32F || disparity_right.type() != CV_32F ||
      checked.size() != disparity_left.size() || checked.size() != disparity_right.size())
    throw std::invalid_argument("classifyInvalidPixels: checked, left and right disparities must be CV_32F, one size");
  const float tolerance = static_cast<float>(tolerance_px);
  cv::Mat classes(checked.size(), CV_8U, cv::Scalar(kPixelValid));
  for (int y = 0; y < checked.rows; ++y) {
    const float* valid = checked.ptr<float>(y);
    const float* left = disparity_left.ptr<float>(y);
    const float* right = disparity_right.ptr<float>(y);
    uint8_t* out = classes.ptr<uint8_t>(y);
    for (int x = 0; x < checked.cols; ++x) {
      if (std::isfinite(valid[x])) continue;
      const float d = left[x];
      const long match = std::isfinite(d) ? std::lround(x - d) : -1;
      bool occluded = match < 0;
      // p's match or right pixels left of it whose surface lies in front of p's and reaches p: they hide p's point.
      for (int q = static_cast<int>(std::min<long>(match, checked.cols - 1)); !occluded && q >= 0; --q)
        occluded = std::isfinite(right[q]) && right[q] > d + tolerance && q + right[q] >= x - 1.0f;
      out[x] = occluded ? kPixelOccluded : kPixelMismatch;
    }
  }
  return classes;
}

cv::Mat fillHoles(const cv::Mat& disparity) {
  cv::Mat filled = disparity.clone();
  std::vector<int> unfilled_rows;
  for (int y = 0; y < filled.rows; ++y) {
    float* row = filled.ptr<float>(y);
    int x = 0;
    bool any_valid = false;
    while (x < filled.cols) {
      if (std::isfinite(row[x])) {
        any_valid = true;
        ++x;
        continue;
      }
      const int start = x;
      while (x < filled.cols && !std::isfinite(row[x])) ++x;
      const float left = start > 0 ? row[start - 1] : std::numeric_limits<float>::infinity();
      const float right = x < filled.cols ? row[x] : std::numeric_limits<float>::infinity();
      const float value = std::min(left, right);  // background: the farther (smaller disparity) side
      if (std::isfinite(value)) std::fill(row + start, row + x, value);
    }
    if (!any_valid) unfilled_rows.push_back(y);
  }
  // Rows without any valid pixel: copy the nearest row that has one.
  if (!unfilled_rows.empty() && static_cast<int>(unfilled_rows.size()) < filled.rows) {
    for (int y : unfilled_rows) {
      for (int offset = 1; offset < filled.rows; ++offset) {
        const int candidates[2] = {y - offset, y + offset};
        bool done = false;
        for (int c : candidates) {
          if (c < 0 || c >= filled.rows) continue;
          if (std::find(unfilled_rows.begin(), unfilled_rows.end(), c) != unfilled_rows.end()) continue;
          filled.row(c).copyTo(filled.row(y));
          done = true;
          break;
        }
        if (done) break;
      }
    }
  }
  return filled;
}

cv::Mat weightedMedianFill(const cv::Mat& filled, const cv::Mat& holes, const cv::Mat& guide, int radius_px,
                           double color_sigma) {
  cv::Mat out = filled.clone();
  if (radius_px <= 0) return out;
  const int channels = guide.channels();
  // Weight table over the L1 colour distance (0 .. 255 * channels).
  std::vector<float> color_weight(255 * channels + 1);
  for (size_t i = 0; i < color_weight.size(); ++i)
    color_weight[i] = static_cast<float>(std::exp(-static_cast<double>(i) / (color_sigma * channels)));
  std::vector<std::pair<float, float>> samples;  // (disparity, weight)
  for (int y = 0; y < filled.rows; ++y) {
    const uint8_t* hole_row = holes.ptr<uint8_t>(y);
    for (int x = 0; x < filled.cols; ++x) {
      if (!hole_row[x]) continue;
      const uint8_t* centre = guide.ptr<uint8_t>(y) + x * channels;
      samples.clear();
      float total = 0.0f;
      // Symmetric about (x, y) even at the border, so that a linear surface gives back its own value.
      const int radius_y = std::min({radius_px, y, filled.rows - 1 - y});
      const int radius_x = std::min({radius_px, x, filled.cols - 1 - x});
      for (int v = y - radius_y; v <= y + radius_y; ++v) {
        const float* d_row = filled.ptr<float>(v);
        const uint8_t* g_row = guide.ptr<uint8_t>(v);
        const uint8_t* h_row = holes.ptr<uint8_t>(v);
        for (int u = x - radius_x; u <= x + radius_x; ++u) {
          if (!std::isfinite(d_row[u])) continue;
          int distance = 0;
          for (int c = 0; c < channels; ++c) distance += std::abs(g_row[u * channels + c] - centre[c]);
          const float w = color_weight[distance] * (h_row[u] ? 1.0f : 2.0f);
          samples.emplace_back(d_row[u], w);
          total += w;
        }
      }
      if (samples.empty()) continue;
      std::sort(samples.begin(), samples.end());
      float cumulative = 0.0f;
      for (const auto& sample : samples) {
        cumulative += sample.second;
        if (cumulative >= 0.5f * total) {
          out.at<float>(y, x) = sample.first;
          break;
        }
      }
    }
  }
  return out;
}

cv::Mat medianFilterValid(const cv::Mat& disparity, int radius_px) {
  if (radius_px <= 0) return disparity.clone();
  const bool all_finite = cv::checkRange(disparity, true, nullptr, -1e30, 1e30);
  if (all_finite && radius_px <= 2) {
    cv::Mat out;
    cv::medianBlur(disparity, out, 2 * radius_px + 1);  // fast path: CV_32F supports 3x3 and 5x5
    return out;
  }
  cv::Mat out = disparity.clone();
  std::vector<float> values;
  for (int y = 0; y < disparity.rows; ++y) {
    for (int x = 0; x < disparity.cols; ++x) {
      if (!std::isfinite(disparity.at<float>(y, x))) continue;
      values.clear();
      for (int v = std::max(0, y - radius_px); v <= std::min(disparity.rows - 1, y + radius_px); ++v) {
        const float* row = disparity.ptr<float>(v);
        for (int u = std::max(0, x - radius_px); u <= std::min(disparity.cols - 1, x + radius_px); ++u)
          if (std::isfinite(row[u])) values.push_back(row[u]);
      }
      std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
      out.at<float>(y, x) = values[values.size() / 2];
    }
  }
  return out;
}

}  // namespace dense
}  // namespace exocet_stereo
