/**
 * @file canvas_warp.h
 * @brief (private) One image warped onto a canvas with its blending weight as alpha: the step the live composer and
 * the re-rendering of tiles from placed images share.
 */
#pragma once

#include <array>
#include <string>

#include <Eigen/Core>
#include <opencv2/core.hpp>

namespace exocet_mosaic {
namespace compose {

/// An image warped onto the canvas.
struct CanvasWarp {
  cv::Mat image_alpha;  ///< CV_8UC(channels + 1): colour, then the weight * 255 (0 outside the footprint)
  cv::Rect roi;         ///< where it lies on the canvas (px)
  std::array<Eigen::Vector2d, 4> corners_canvas;  ///< the image's outer corners on the canvas (px)
};

/**
 * @brief Warps `image` (CV_8UC1 or CV_8UC3) with `weight` (CV_32F in [0, 1], same size) by canvas_from_px.
 * @return false, with `problem` set, when the placement is degenerate (a footprint far larger than the image, or not
 * finite).
 */
bool warpOntoCanvas(const cv::Mat& image, const cv::Mat& weight, const cv::Matx33d& canvas_from_px, CanvasWarp* warp,
                    std::string* problem);

}  // namespace compose
}  // namespace exocet_mosaic
