/**
 * @file cost_volume.h
 * @brief Matching-cost volume shared by the volume-based methods (dp, so, sgm, gc, bd).
 *
 * Cost of left pixel (x, y) at disparity d (right pixel x - d):
 *   census_weight * Hamming(census_L, census_R) + color_weight * min(mean |I_L - I_R|, color_truncation)
 *   + gradient_weight * min(|gx_L - gx_R|, gradient_truncation).
 * Census is robust to the radiometric differences between the two cameras; colour and gradient disambiguate
 * repetitive census patterns (the AD-census idea). Matches falling outside the right image get the maximum cost.
 */
#pragma once

#include <vector>

#include <opencv2/core.hpp>

#include "exocet_stereo/dense/dense_stereo.h"

namespace exocet_stereo {
namespace dense {

/// rows x cols x labels costs, label fastest ([y][x][d]), so one pixel's costs are contiguous.
struct CostVolume {
  int rows = 0;
  int cols = 0;
  int labels = 0;
  float max_cost = 0.0f;  ///< cost given to impossible matches (outside the other image)
  std::vector<float> data;

  CostVolume() = default;
  CostVolume(int rows_, int cols_, int labels_, float fill)
      : rows(rows_), cols(cols_), labels(labels_), data(static_cast<size_t>(rows_) * cols_ * labels_, fill) {}
  float* at(int y, int x) { return data.data() + (static_cast<size_t>(y) * cols + x) * labels; }
  const float* at(int y, int x) const { return data.data() + (static_cast<size_t>(y) * cols + x) * labels; }
};

/// Left-view cost volume of a rectified pair (CV_8UC1 or CV_8UC3, checked by DenseStereo::checkImages).
CostVolume buildCostVolume(const cv::Mat& left, const cv::Mat& right, const DenseStereoConfig& config);

/// Right-view volume of the same costs: C_R(y, x, d) = C_L(y, x + d, d) (max_cost outside the left image).
CostVolume rightViewVolume(const CostVolume& left_volume);

/// Box-filter every disparity slice with a (2r+1)^2 window (mean; borders replicated). r = 0 leaves it as is.
void boxAggregate(CostVolume* volume, int radius_px);

/// Grey image (CV_8U) of an 8-bit grey or BGR image.
cv::Mat toGray(const cv::Mat& image);

}  // namespace dense
}  // namespace exocet_stereo
