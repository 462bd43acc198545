/**
 * @file multiband_blend.h
 * @brief (private) Multi-band blending (cv::detail::MultiBandBlender) of the key frames kept for a mosaic, at close.
 */
#pragma once

#include <vector>

#include <opencv2/core.hpp>

namespace exocet_mosaic {
namespace compose {

/// A key frame warped onto the canvas: image and feather weight over roi (canvas px).
struct WarpedFrame {
  cv::Mat image;   ///< CV_8UC1 or CV_8UC3
  cv::Mat weight;  ///< CV_32F, 0 outside the footprint
  cv::Rect roi;
};

/**
 * @brief Blends the frames over region. Each canvas pixel is given to the frame of largest feather weight (seams
 * half way between image centres, so overlaps are not averaged and cannot ghost), then the multi-band blender hides
 * the seams (low frequencies blended over wide transitions, high frequencies over narrow ones).
 * @param image output CV_8UC(channels); @param mask output CV_8UC1.
 */
void blendMultiband(const std::vector<WarpedFrame>& frames, const cv::Rect& region, int bands, int channels,
                    cv::Mat* image, cv::Mat* mask);

}  // namespace compose
}  // namespace exocet_mosaic
