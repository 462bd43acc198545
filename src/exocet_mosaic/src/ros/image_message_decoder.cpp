#include "exocet_mosaic/ros/image_message_decoder.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

namespace exocet_mosaic {

std::string decodeCompressedImage(const sensor_msgs::CompressedImage& message, DecodedImage* decoded) {
  decoded->image.release();
  decoded->encoding.clear();
  cv::Mat image;
  try {
    image = cv::imdecode(message.data, cv::IMREAD_UNCHANGED);
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
