/**
 * @file evaluation.h
 * @brief Middlebury v2 bad-pixel evaluation of a disparity map.
 */
#pragma once

#include <string>

#include <opencv2/core.hpp>

namespace exocet_stereo {
namespace dense {

/// A Middlebury v2 scene folder: imL.png imR.png groundtruth.png nonocc.png all.png disc.png info.txt.
struct MiddleburyScene {
  std::string name;
  cv::Mat left, right;        ///< 8-bit as stored (colour for the four v2 scenes)
  cv::Mat ground_truth_px;    ///< CV_32F disparity (value / scale), 0 where unknown
  cv::Mat nonocc, all, disc;  ///< CV_8U masks, 255 = evaluated
  int scale = 1;              ///< groundtruth.png value per pixel of disparity
  int max_disparity_px = 0;   ///< from info.txt
};

/// Load a scene folder. @throws std::runtime_error naming the missing or unreadable file.
MiddleburyScene loadMiddleburyScene(const std::string& directory);

/// Bad-pixel percentages over the three masks.
struct BadPixelRates {
  double nonocc = 0.0;
  double all = 0.0;
  double disc = 0.0;
};

/**
 * @brief Percentage of mask pixels (mask == 255) with |d - d_gt| > threshold_px; non-finite estimates count as bad.
 * @throws std::invalid_argument if sizes or types disagree (disparity CV_32F, mask CV_8U).
 */
double badPixelPercent(const cv::Mat& disparity_px, const cv::Mat& ground_truth_px, const cv::Mat& mask,
                       double threshold_px = 1.0);

/// badPixelPercent over nonocc, all and disc.
BadPixelRates evaluateDisparity(const cv::Mat& disparity_px, const MiddleburyScene& scene, double threshold_px = 1.0);

/// Disparity of an 8/16-bit PNG stored as value / scale (0 = unknown -> NaN when zero_is_unknown). @throws
/// runtime_error.
cv::Mat readScaledDisparityPng(const std::string& path, double scale, bool zero_is_unknown);

}  // namespace dense
}  // namespace exocet_stereo
