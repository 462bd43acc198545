/**
 * @file image_seabed.h
 * @brief A user-supplied seabed image (mosaic, orthophoto, photo of a test tank floor) as a SeabedTexture.
 */
#pragma once

#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "exocet_mosaic/sim/seabed_texture.h"

namespace exocet_mosaic {
namespace sim {

/**
 * @brief A seabed image georeferenced like a map.
 *
 * Convention: square pixels of pixel_size_m; the image's centre is at world (center_x_m, center_y_m); columns go
 * east and rows go SOUTH (the top row is the northern edge), as the image is seen on screen with north up. So the
 * image covers x in center_x_m +- width * pixel_size_m / 2 and y in center_y_m +- height * pixel_size_m / 2, and
 * pixel (col c, row r) is centred on (x_min + (c + 0.5) * pixel, y_max - (r + 0.5) * pixel).
 *
 * Pixel values v (8 or 16 bits, grey, BGR or BGRA as read by OpenCV; alpha ignored) are decoded to linear albedo
 * (v / v_max)^decode_gamma. Level 0 has texel = pixel_size_m, level L texel = pixel_size_m * 2^L and is the exact
 * 2x2 mean of level L-1 (areas beyond the image count as the image's mean colour), so the levels agree in the
 * mean. Outside the image, patches hold the image's mean colour; covers() lets the caller reject a trajectory
 * that leaves the image. Patches follow TexturePatch (rows go north): the image is flipped.
 *
 * Memory: level 0 keeps the file's 8 or 16-bit pixels (3 or 6 bytes each), the coarser levels ~4 bytes per
 * pixel of level 0 in float. albedoPatch() only reads: concurrent calls are safe.
 */
class ImageSeabed final : public SeabedTexture {
 public:
  /**
   * @param path image file (any format cv::imread reads)
   * @param pixel_size_m side of one pixel on the seabed (metres), > 0
   * @param center_x_m, center_y_m world position of the image centre (metres, x east, y north)
   * @param decode_gamma exponent from pixel value to linear albedo (2.2 for an sRGB-like image, 1 for linear)
   * @throws std::invalid_argument naming the parameter if pixel_size_m <= 0, decode_gamma <= 0 or one is not
   *         finite; std::runtime_error with the path and the reason if the file cannot be read or decoded.
   */
  ImageSeabed(const std::string& path, double pixel_size_m, double center_x_m = 0.0, double center_y_m = 0.0,
              double decode_gamma = 2.2);

  double baseTexelSize_m() const override { return pixel_size_m_; }
  /// The level at which the whole image is one texel.
  int maxLevel() const override { return static_cast<int>(levels_.size()); }
  /// Throws std::out_of_range for a level outside [0, maxLevel()], std::invalid_argument for an empty or
  /// non-finite area or a patch above 64 Mtexels.
  TexturePatch<cv::Vec3f> albedoPatch(int level, const WorldRect& area) override;

  /// True if `area` lies entirely on the image.
  bool covers(const WorldRect& area) const;
  /// The world rectangle covered by the image.
  WorldRect bounds() const;
  /// Mean linear albedo of the image (R, G, B): the colour outside it.
  cv::Vec3f meanAlbedo() const { return mean_; }
  int widthPixels() const { return base_.cols; }
  int heightPixels() const { return base_.rows; }

 private:
  /// Linear albedo of level-0 pixel (c, r) in the flipped image (row 0 = south).
  cv::Vec3f basePixel(int c, int r) const;

  double pixel_size_m_;
  double x_min_m_, y_min_m_;                 // south-west corner of the image
  cv::Mat base_;                             // level 0: CV_8UC3 or CV_16UC3, R G B, row 0 = southern edge
  std::vector<float> lut_;                   // pixel value -> linear albedo
  std::vector<cv::Mat_<cv::Vec3f>> levels_;  // levels 1..maxLevel()
  cv::Vec3f mean_;
};

}  // namespace sim
}  // namespace exocet_mosaic
