#include "exocet_mosaic/compose/feather_weights.h"

#include <algorithm>
#include <cmath>

namespace exocet_mosaic {
namespace compose {

cv::Mat FeatherWeights::compute(const cv::Size& size, double power) {
  cv::Mat w(size, CV_32F);
  // Distance of the pixel centre to the image border (the border is half a pixel outside the outer centres), over
  // half the smaller side: 1 on the centre line, -> 0 at the border, so that overlapping images fade into each other.
  const double half = 0.5 * std::min(size.width, size.height);
  for (int y = 0; y < size.height; ++y) {
    float* row = w.ptr<float>(y);
    const double dy = std::min(y + 0.5, size.height - y - 0.5);
    for (int x = 0; x < size.width; ++x) {
      const double d = std::min(dy, std::min(x + 0.5, size.width - x - 0.5)) / half;
      row[x] = static_cast<float>(power == 1.0 ? std::min(d, 1.0) : std::pow(std::min(d, 1.0), power));
    }
  }
  return w;
}

const cv::Mat& FeatherWeights::get(const cv::Size& size, double power) {
  if (weights_.empty() || size != size_ || power != power_) {
    weights_ = compute(size, power);
    size_ = size;
    power_ = power;
  }
  return weights_;
}

}  // namespace compose
}  // namespace exocet_mosaic
