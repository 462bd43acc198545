/**
 * @file gray_converter.h
 * @brief Camera images of any common encoding to the 8-bit grey images the registration works on. No ROS in it.
 */
#pragma once

#include <string>

#include <opencv2/core.hpp>

namespace exocet_mosaic {
namespace registration {

/**
 * Converts images named by their sensor_msgs encoding to CV_8UC1. Supported: mono8, mono16, bgr8, rgb8, bgra8, rgba8,
 * bayer_rggb8, bayer_bggr8, bayer_gbrg8, bayer_grbg8 and their 16-bit bayer forms. 16-bit images are scaled by a
 * power of two chosen on the first 16-bit image (from its brightest pixel, so that a 10- or 12-bit camera in a
 * 16-bit container is not rendered black) and kept afterwards: a frame-to-frame change of scale would look like a
 * lighting change.
 */
class GrayConverter {
 public:
  /// Whether `encoding` is one of the supported encodings.
  static bool supports(const std::string& encoding);
  /// The supported encodings, comma-separated, for error messages.
  static std::string supportedList();

  /// The result owns its pixels (never a view of `image`), so it may outlive a message buffer.
  /// @throws std::invalid_argument naming the encoding (unsupported) or the mismatch (image type vs encoding).
  cv::Mat convert(const cv::Mat& image, const std::string& encoding);

  /// Forgets the 16-bit scale.
  void reset() { mono16_shift_ = -1; }

 private:
  int mono16_shift_ = -1;
};

}  // namespace registration
}  // namespace exocet_mosaic
