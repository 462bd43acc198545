/**
 * @file post_processing.h
 * @brief Winner-take-all, sub-pixel refinement and the post-processing shared by every dense method.
 */
#pragma once

#include <cstdint>

#include <opencv2/core.hpp>

#include "exocet_stereo/dense/cost_volume.h"

namespace exocet_stereo {
namespace dense {

/// Offset in (-0.5, 0.5) of the minimum of the parabola through (-1, c_minus), (0, c0), (1, c_plus); 0 if flat.
float parabolaOffset(float c_minus, float c0, float c_plus);

/// Disparity (CV_32F) of the lowest cost per pixel; with subpixel, refined by parabolaOffset on the neighbours.
cv::Mat winnerTakeAll(const CostVolume& volume, bool subpixel);

/// Refine integer labels (CV_32F holding integers, NaN allowed) by a parabola on `volume` around each label.
void refineSubpixel(const CostVolume& volume, cv::Mat* disparity);

/**
 * @brief Left-right consistency: a left pixel keeps its disparity d only if the right pixel x - d (rounded) has a
 *        disparity within tolerance_px of d. Others become NaN (occlusions and mismatches).
 */
cv::Mat leftRightCheck(const cv::Mat& disparity_left, const cv::Mat& disparity_right, double tolerance_px);

/// Why a left pixel has no disparity after the checks (values of classifyInvalidPixels()).
enum InvalidPixelClass : uint8_t {
  kPixelValid = 0,     ///< kept its disparity
  kPixelOccluded = 1,  ///< hidden from the right view by a surface in front (or matched outside it)
  kPixelMismatch = 2,  ///< visible in both views, but one of the two disparities is wrong
};

/**
 * @brief Occlusion or mismatch for every invalid (NaN) pixel of `checked` (the left map after leftRightCheck() or any
 *        later invalidation), after Hirschmueller's SGM: with d the raw left disparity at p = (x, y), p is OCCLUDED if
 *        x - d falls outside the right image, or if p's match x - d (rounded) or some right pixel q left of it holds a
 *        surface in FRONT of p's (disparity_right(q) > d + tolerance_px) that reaches p in the left view
 *        (q + disparity_right(q) >= x - 1): that surface hides p's point from the right camera. Otherwise p is a
 *        MISMATCH (e.g. the right map is wrong at x - d although p's surface is visible there).
 * @return CV_8U map of InvalidPixelClass (kPixelValid where `checked` is finite).
 * @throws std::invalid_argument if the three maps are not CV_32F of one size.
 */
cv::Mat classifyInvalidPixels(const cv::Mat& checked, const cv::Mat& disparity_left, const cv::Mat& disparity_right,
                              double tolerance_px);

/**
 * @brief Fill NaN pixels: per row, with the lower of the nearest valid disparities to the left and right (occluded
 *        pixels belong to the background), then any remaining column-wise. A map with no valid pixel stays NaN.
 */
cv::Mat fillHoles(const cv::Mat& disparity);

/**
 * @brief Re-estimate the pixels flagged in `holes` (CV_8U, non-zero) of a filled disparity map by a weighted median of
 *        their (2r+1)^2 neighbourhood, each neighbour weighted by colour similarity exp(-|I_p - I_q|_1 / sigma) and
 *        counted double if it was not a hole. Recovers thin foreground structures that background filling erases.
 *        Where the image border cuts the window, the window shrinks to stay symmetric about the pixel: a window that
 *        reaches further to one side is biased on a slanted surface by up to radius x slope (Teddy's floor at the
 *        bottom border, 0.9 px per row, took the disparity of rows ~8 above: 7 px off).
 */
cv::Mat weightedMedianFill(const cv::Mat& filled, const cv::Mat& holes, const cv::Mat& guide, int radius_px,
                           double color_sigma);

/// Median over the valid pixels of a (2r+1)^2 window (NaN stays NaN; r = 0 returns a copy).
cv::Mat medianFilterValid(const cv::Mat& disparity, int radius_px);

}  // namespace dense
}  // namespace exocet_stereo
