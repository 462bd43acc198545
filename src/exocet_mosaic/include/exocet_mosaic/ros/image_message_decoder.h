/**
 * @file image_message_decoder.h
 * @brief sensor_msgs images (raw or compressed) to OpenCV matrices, with the encoding they carry, and to the 8-bit
 * colour (BGR) or grey images that the mosaic is made of.
 */
#pragma once

#include <optional>
#include <string>

#include <sensor_msgs/CompressedImage.h>
#include <opencv2/core.hpp>

namespace exocet_mosaic {

/// An image decoded from a message, with its sensor_msgs encoding ("bgr8", "mono8", "bayer_rggb8", ...).
struct DecodedImage {
  cv::Mat image;
  std::string encoding;
};

/// What the caller needs of a compressed image.
enum class DecodeMode {
  kAsStored,  ///< the stored channels (colour stays colour)
  /// Grey is enough: a colour JPEG decodes only its luminance (libjpeg skips chroma upsampling and colour
  /// conversion: about twice as fast), "mono8". PNG and Bayer images decode as stored.
  kGreyIfJpeg,
};

/**
 * Decodes a CompressedImage (JPEG or PNG). The format field starts with the original encoding ("bgr8; jpeg
 * compressed bgr8"); a Bayer image compressed losslessly decodes to one channel and keeps its Bayer encoding.
 * @param reduction 1, 2, 4 or 8: a JPEG that is not Bayer decodes at 1/reduction of its size, rounded up (libjpeg's
 * scaled decoding: fewer pixels to convert and upsample, the entropy decoding stays); other images at full size.
 * @return an empty string, or what is wrong with the message (the image is then empty).
 */
std::string decodeCompressedImage(const sensor_msgs::CompressedImage& message, DecodedImage* decoded,
                                  DecodeMode mode = DecodeMode::kAsStored, int reduction = 1);

/// Size and channels of the image toDisplayImage() would make of a compressed message, read from the JPEG or PNG
/// header without decoding the pixels. Empty if the header cannot be read.
struct DisplayShape {
  cv::Size size;
  int channels = 0;  ///< 1 (mono8, mono16) or 3 (colour, Bayer)
};
std::optional<DisplayShape> peekDisplayShape(const sensor_msgs::CompressedImage& message);
/// Channels of toDisplayImage()'s image for a sensor_msgs encoding: 1 for mono8 and mono16, 3 for the others.
int displayChannels(const std::string& encoding);

/**
 * An 8-bit image for display and mosaics: CV_8UC3 BGR for colour and Bayer encodings, CV_8UC1 for mono8 and mono16
 * (16-bit scaled by its brightest power of two, so a 12-bit camera is not rendered black).
 * @throws std::invalid_argument naming the unsupported encoding or the mismatch between encoding and pixel type.
 */
cv::Mat toDisplayImage(const cv::Mat& image, const std::string& encoding);

}  // namespace exocet_mosaic
