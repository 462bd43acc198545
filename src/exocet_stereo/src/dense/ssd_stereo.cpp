// Shiftable-window SSD: box-filtered squared differences, min filter over shifted windows, winner-take-all.
#include <algorithm>
#include <cfloat>
#include <cmath>
#include <limits>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "exocet_stereo/dense/methods.h"
#include "exocet_stereo/dense/post_processing.h"

namespace exocet_stereo {
namespace dense {
namespace {

// Same parabola as parabolaOffset(), inlined in the per-pixel loop.
inline float parabola(float c_minus, float c0, float c_plus) {
  const float curvature = c_minus + c_plus - 2.0f * c0;
  if (!(curvature > 1e-6f)) return 0.0f;
  return std::max(-0.5f, std::min(0.5f, 0.5f * (c_minus - c_plus) / curvature));
}

// Winner-take-all over planar slices (slices[d] is rows x cols, indexed by the LEFT pixel). The right view reads the
// same slices sheared: C_R(x, d) = C_L(x + d, d). Whole-image OpenCV compare/min/setTo are vectorised.
cv::Mat planarWinnerTakeAll(const std::vector<cv::Mat>& slices, bool right_view, bool subpixel) {
  const int labels = static_cast<int>(slices.size());
  const int rows = slices[0].rows, cols = slices[0].cols;
  cv::Mat best_cost(rows, cols, CV_32F, cv::Scalar(FLT_MAX)), best_label(rows, cols, CV_32S, cv::Scalar(-1)), better;
  for (int d = 0; d < labels; ++d) {
    const int shift = right_view ? d : 0;
    const cv::Rect view(0, 0, cols - shift, rows);
    const cv::Mat cost = slices[d](cv::Rect(shift, 0, cols - shift, rows));
    cv::Mat best = best_cost(view), label = best_label(view);
    cv::compare(cost, best, better, cv::CMP_LT);
    label.setTo(d, better);
    cv::min(cost, best, best);
  }
  cv::Mat disparity(rows, cols, CV_32F);
  for (int y = 0; y < rows; ++y) {
    const int* label = best_label.ptr<int>(y);
    const float* best = best_cost.ptr<float>(y);
    float* out = disparity.ptr<float>(y);
    for (int x = 0; x < cols; ++x) {
      const int d = label[x];
      if (d < 0) {
        out[x] = std::numeric_limits<float>::quiet_NaN();
        continue;
      }
      out[x] = static_cast<float>(d);
      const int column = right_view ? x + d : x;
      if (subpixel && d > 0 && d < labels - 1 && (!right_view || column + 1 < cols))
        out[x] += parabola(slices[d - 1].ptr<float>(y)[right_view ? column - 1 : column], best[x],
                           slices[d + 1].ptr<float>(y)[right_view ? column + 1 : column]);
    }
  }
  return disparity;
}

}  // namespace

void SsdStereo::computeRaw(const cv::Mat& left, const cv::Mat& right, cv::Mat* disparity_left,
                           cv::Mat* disparity_right) const {
  const int labels = config_.labelCount();
  const int rows = left.rows, cols = left.cols, channels = left.channels();
  const int window = 2 * config_.window_radius_px + 1;
  std::vector<cv::Mat> slices(labels);
  cv::Mat squared(rows, cols, CV_32F), boxed;
  std::vector<int> squared_bytes(static_cast<size_t>(cols) * channels);
  const cv::Mat kernel = cv::getStructuringElement(cv::MORPH_RECT, cv::Size(window, window));
  for (int d = 0; d < labels; ++d) {
    const int offset = d * channels, row_values = cols * channels;
    for (int y = 0; y < rows; ++y) {
      const uint8_t* l_row = left.ptr<uint8_t>(y);
      const uint8_t* r_row = right.ptr<uint8_t>(y);
      // Contiguous byte loops (vectorised); left pixels beyond the right image use its first column.
      for (int i = 0; i < std::min(offset, row_values); ++i) {
        const int diff = l_row[i] - r_row[i % channels];
        squared_bytes[i] = diff * diff;
      }
      for (int i = offset; i < row_values; ++i) {
        const int diff = l_row[i] - r_row[i - offset];
        squared_bytes[i] = diff * diff;
      }
      float* out = squared.ptr<float>(y);
      if (channels == 3) {
        for (int x = 0; x < cols; ++x)
          out[x] = static_cast<float>(squared_bytes[3 * x] + squared_bytes[3 * x + 1] + squared_bytes[3 * x + 2]);
      } else {
        for (int x = 0; x < cols; ++x) out[x] = static_cast<float>(squared_bytes[x]);
      }
    }
    // Integral-style running sums inside boxFilter; normalisation is irrelevant to the arg-min.
    cv::boxFilter(squared, boxed, CV_32F, cv::Size(window, window), cv::Point(-1, -1), false, cv::BORDER_REPLICATE);
    // Shiftable window: the best of all windows that contain the pixel = min filter of the window costs.
    cv::erode(boxed, slices[d], kernel, cv::Point(-1, -1), 1, cv::BORDER_REPLICATE);
  }
  *disparity_left = planarWinnerTakeAll(slices, false, config_.subpixel);
  if (disparity_right) *disparity_right = planarWinnerTakeAll(slices, true, config_.subpixel);
}

}  // namespace dense
}  // namespace exocet_stereo
