/**
 * @file feather_weights.h
 * @brief Feather blending weights of an image: distance to the image border, normalised to 1 at the centre line,
 * raised to a power. Computed once per image size and power (cached), as the weights of every image are the same.
 */
#pragma once

#include <opencv2/core.hpp>

namespace exocet_mosaic {
namespace compose {

/// Caches the feather weights of one image size and power.
class FeatherWeights {
 public:
  /**
   * @brief The weights of an image of this size: CV_32F, (min distance of the pixel centre to the image border
   * / half the smaller side)^power, in (0, 1]. Recomputed only when size or power change.
   * @param size image size (px); @param power exponent, > 0 (larger: narrower transitions between images).
   */
  const cv::Mat& get(const cv::Size& size, double power);

  /// Computes the weights without caching.
  static cv::Mat compute(const cv::Size& size, double power);

 private:
  cv::Mat weights_;
  cv::Size size_;
  double power_ = -1.0;
};

}  // namespace compose
}  // namespace exocet_mosaic
