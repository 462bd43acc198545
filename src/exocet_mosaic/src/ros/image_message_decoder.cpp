#include "exocet_mosaic/ros/image_message_decoder.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

namespace exocet_mosaic {

std::string decodeCompressedImage(const sensor_msgs::CompressedImage& message, DecodedImage* decoded, DecodeMode mode,
                                  int reduction) {
  decoded->image.release();
  decoded->encoding.clear();
  if (reduction != 1 && reduction != 2 && reduction != 4 && reduction != 8)
    return "image reduction must be 1, 2, 4 or 8, got " + std::to_string(reduction);
  // JPEG's start-of-image marker: the data says what it is, whatever the format field claims.
  const bool jpeg = message.data.size() > 2 && message.data[0] == 0xFF && message.data[1] == 0xD8;
  const bool stored_bayer = message.format.find("bayer_") != std::string::npos;
  int flags =
      mode == DecodeMode::kGreyIfJpeg && jpeg && !stored_bayer ? cv::IMREAD_GRAYSCALE : cv::IMREAD_UNCHANGED;
  if (jpeg && !stored_bayer && reduction > 1) {
    // IMREAD_REDUCED_GRAYSCALE_r = 8 r, IMREAD_REDUCED_COLOR_r = 8 r + 1: grey when asked or stored grey.
    const std::optional<DisplayShape> shape = peekDisplayShape(message);
    const bool grey = mode == DecodeMode::kGreyIfJpeg || (shape && shape->channels == 1);
    flags = 8 * reduction + (grey ? 0 : 1);
  }
  cv::Mat image;
  try {
    image = cv::imdecode(message.data, flags);
  } catch (const cv::Exception&) {
    image.release();
  }
  if (image.empty())
    return "compressed image (format '" + message.format + "', " + std::to_string(message.data.size()) +
           " bytes) cannot be decoded";
  std::string encoding = message.format.substr(0, message.format.find(';'));
  encoding.erase(std::remove(encoding.begin(), encoding.end(), ' '), encoding.end());
  const bool bayer = encoding.rfind("bayer_", 0) == 0 && image.channels() == 1;
  if (!bayer) {
    switch (image.type()) {
      case CV_8UC1:
        encoding = "mono8";
        break;
      case CV_16UC1:
        encoding = "mono16";
        break;
      case CV_8UC3:
        encoding = "bgr8";  // imdecode's order
        break;
      case CV_8UC4:
        encoding = "bgra8";
        break;
      default:
        return "compressed image (format '" + message.format + "') decodes to an unsupported pixel type";
    }
  }
  decoded->image = image;
  decoded->encoding = encoding;
  return "";
}

namespace {

void requireType(const cv::Mat& image, int type, const std::string& encoding) {
  if (image.type() != type)
    throw std::invalid_argument("image of encoding '" + encoding + "' has " + std::to_string(image.channels()) +
                                " channel(s) of " + std::to_string(image.elemSize1() * 8) + " bits");
}

cv::Mat to8Bit(const cv::Mat& image16) {
  double max_value = 0.0;
  cv::minMaxLoc(image16, nullptr, &max_value);
  int shift = 0;
  while (shift < 8 && max_value >= std::ldexp(1.0, 8 + shift)) ++shift;
  cv::Mat out;
  image16.convertTo(out, CV_8U, std::ldexp(1.0, -shift));
  return out;
}

}  // namespace

std::optional<DisplayShape> peekDisplayShape(const sensor_msgs::CompressedImage& message) {
  const std::vector<uint8_t>& d = message.data;
  const bool bayer = message.format.find("bayer_") != std::string::npos;
  auto be16 = [&d](size_t i) { return (int(d[i]) << 8) | int(d[i + 1]); };
  int width = 0, height = 0, stored_channels = 0;
  if (d.size() > 4 && d[0] == 0xFF && d[1] == 0xD8) {
    // JPEG: walk the marker segments to the start of frame (SOF0..SOF15 except DHT C4, JPG C8, DAC CC).
    size_t i = 2;
    while (i + 9 < d.size()) {
      if (d[i] != 0xFF) return std::nullopt;
      const uint8_t marker = d[i + 1];
      if (marker == 0xFF) {  // fill byte
        ++i;
        continue;
      }
      if (marker >= 0xC0 && marker <= 0xCF && marker != 0xC4 && marker != 0xC8 && marker != 0xCC) {
        height = be16(i + 5);
        width = be16(i + 7);
        stored_channels = d[i + 9];
        break;
      }
      if (marker == 0xD9 || marker == 0xDA) return std::nullopt;  // end of image or scan before any frame header
      i += 2 + be16(i + 2);
    }
  } else if (d.size() >= 26 && d[0] == 0x89 && d[1] == 'P' && d[2] == 'N' && d[3] == 'G') {
    // PNG: IHDR is the first chunk: width, height (big endian), bit depth, colour type.
    width = (be16(16) << 16) | be16(18);
    height = (be16(20) << 16) | be16(22);
    const int colour_type = d[25];
    stored_channels = colour_type == 0 ? 1 : (colour_type == 4 ? 2 : 3);
  }
  if (width <= 0 || height <= 0 || stored_channels <= 0) return std::nullopt;
  DisplayShape shape;
  shape.size = cv::Size(width, height);
  shape.channels = stored_channels == 1 && !bayer ? 1 : 3;
  return shape;
}

int displayChannels(const std::string& encoding) { return encoding == "mono8" || encoding == "mono16" ? 1 : 3; }

cv::Mat toDisplayImage(const cv::Mat& image, const std::string& encoding) {
  cv::Mat out;
  if (encoding == "mono8") {
    requireType(image, CV_8UC1, encoding);
    return image.clone();
  }
  if (encoding == "mono16") {
    requireType(image, CV_16UC1, encoding);
    return to8Bit(image);
  }
  if (encoding == "bgr8") {
    requireType(image, CV_8UC3, encoding);
    return image.clone();
  }
  if (encoding == "rgb8") {
    requireType(image, CV_8UC3, encoding);
    cv::cvtColor(image, out, cv::COLOR_RGB2BGR);
    return out;
  }
  if (encoding == "bgra8" || encoding == "rgba8") {
    requireType(image, CV_8UC4, encoding);
    cv::cvtColor(image, out, encoding == "bgra8" ? cv::COLOR_BGRA2BGR : cv::COLOR_RGBA2BGR);
    return out;
  }
  // OpenCV names Bayer patterns by the second row's first two pixels: ROS's rggb is OpenCV's BG.
  static const std::pair<const char*, int> kBayer[] = {{"rggb", cv::COLOR_BayerBG2BGR},
                                                       {"bggr", cv::COLOR_BayerRG2BGR},
                                                       {"gbrg", cv::COLOR_BayerGR2BGR},
                                                       {"grbg", cv::COLOR_BayerGB2BGR}};
  for (const auto& [pattern, code] : kBayer) {
    for (const int bits : {8, 16}) {
      if (encoding != std::string("bayer_") + pattern + std::to_string(bits)) continue;
      requireType(image, bits == 8 ? CV_8UC1 : CV_16UC1, encoding);
      cv::cvtColor(bits == 8 ? image : to8Bit(image), out, code);
      return out;
    }
  }
  throw std::invalid_argument("image encoding '" + encoding +
                              "' is not supported (mono8, mono16, bgr8, rgb8, bgra8, rgba8, bayer_*8, bayer_*16)");
}

}  // namespace exocet_mosaic
