/**
 * @file image_reduction.h
 * @brief Composing an image at a fraction of its resolution: the reduced image's pixel frame, the intrinsics of a
 * reduced camera, reducing an image by block averaging, and the choice of the factor from the ground sample
 * distances. No ROS in it.
 *
 * A reduction r (1, 2, 4 or 8) keeps floor(w / r) x floor(h / r) pixels; reduced pixel (x, y) is the mean of the
 * r x r full pixels whose centres are r x + 0..r-1: its centre is at full px r x + (r - 1) / 2. This is also what
 * libjpeg's scaled decoding (OpenCV's IMREAD_REDUCED_*) gives, up to the partial last block it adds when r does not
 * divide the size, which reduceImage() crops.
 */
#pragma once

#include <opencv2/core.hpp>

namespace exocet_mosaic {
namespace compose {

/// True for 1, 2, 4 and 8.
bool isImageReduction(int reduction);

/// floor(size / reduction).
cv::Size reducedImageSize(const cv::Size& full_size, int reduction);

/// Reduced px -> full px: [r 0 (r-1)/2; 0 r (r-1)/2; 0 0 1].
cv::Matx33d fullFromReducedPx(int reduction);

/**
 * @brief The image at 1/reduction of full_size: an image of full_size is block-averaged (INTER_AREA on the whole
 * blocks); an image already reduced (between floor and ceil of full_size / reduction, a scaled JPEG decode) is cropped
 * to reducedImageSize(). Empty for any other size. With reduction 1 the image itself (not copied).
 */
cv::Mat reduceImage(const cv::Mat& image, const cv::Size& full_size, int reduction);

/**
 * @brief The reduction to compose images at: the largest power of two up to max_reduction with
 * native_gsd_m x r <= tile_gsd_m. `current` (0: none yet) is kept while it stays within a 10 % band (native x current
 * <= 1.1 tile, and native x 2 current > 0.9 tile when 2 current is allowed), so that an altitude that hovers at a bound
 * does not switch it back and forth. 1 when either GSD is not positive or finite.
 */
int chooseImageReduction(double native_gsd_m, double tile_gsd_m, int max_reduction, int current);

}  // namespace compose
}  // namespace exocet_mosaic
