#include "exocet_mosaic/registration/gray_converter.h"

#include <algorithm>
#include <stdexcept>
#include <vector>

#include <opencv2/imgproc.hpp>

namespace exocet_mosaic {
namespace registration {
namespace {

struct EncodingInfo {
  const char* name;
  int cv_type;
  int code;  ///< cvtColor code to grey, -1 when already grey
};

// ROS names a Bayer pattern by its first row (rggb), OpenCV by the second row's first two pixels: rggb is BayerBG.
const std::vector<EncodingInfo>& encodings() {
  static const std::vector<EncodingInfo> table = {
      {"mono8", CV_8UC1, -1},
      {"mono16", CV_16UC1, -1},
      {"bgr8", CV_8UC3, cv::COLOR_BGR2GRAY},
      {"rgb8", CV_8UC3, cv::COLOR_RGB2GRAY},
      {"bgra8", CV_8UC4, cv::COLOR_BGRA2GRAY},
      {"rgba8", CV_8UC4, cv::COLOR_RGBA2GRAY},
      {"bayer_rggb8", CV_8UC1, cv::COLOR_BayerBG2GRAY},
      {"bayer_bggr8", CV_8UC1, cv::COLOR_BayerRG2GRAY},
      {"bayer_gbrg8", CV_8UC1, cv::COLOR_BayerGR2GRAY},
      {"bayer_grbg8", CV_8UC1, cv::COLOR_BayerGB2GRAY},
      {"bayer_rggb16", CV_16UC1, cv::COLOR_BayerBG2GRAY},
      {"bayer_bggr16", CV_16UC1, cv::COLOR_BayerRG2GRAY},
      {"bayer_gbrg16", CV_16UC1, cv::COLOR_BayerGR2GRAY},
      {"bayer_grbg16", CV_16UC1, cv::COLOR_BayerGB2GRAY},
  };
  return table;
}

const EncodingInfo* find(const std::string& encoding) {
  for (const EncodingInfo& e : encodings())
    if (encoding == e.name) return &e;
  return nullptr;
}

}  // namespace

bool GrayConverter::supports(const std::string& encoding) { return find(encoding) != nullptr; }

std::string GrayConverter::supportedList() {
  std::string list;
  for (const EncodingInfo& e : encodings()) list += (list.empty() ? "" : ", ") + std::string(e.name);
  return list;
}

cv::Mat GrayConverter::convert(const cv::Mat& image, const std::string& encoding) {
  const EncodingInfo* info = find(encoding);
  if (!info)
    throw std::invalid_argument("image encoding '" + encoding + "' is not supported; supported: " + supportedList());
  if (image.empty()) throw std::invalid_argument("empty image");
  if (image.type() != info->cv_type)
    throw std::invalid_argument("image data does not match encoding '" + encoding + "' (" +
                                std::to_string(image.channels()) + " channels, depth code " +
                                std::to_string(image.depth()) + ")");
  cv::Mat gray;
  if (info->code >= 0) {
    if (image.depth() == CV_16U) {
      cv::Mat gray16;
      cv::cvtColor(image, gray16, info->code);
      gray = gray16;
    } else {
      cv::cvtColor(image, gray, info->code);
    }
  } else {
    gray = image.depth() == CV_8U ? image.clone() : image;  // the result owns its data (see the header)
  }
  if (gray.depth() == CV_16U) {
    if (mono16_shift_ < 0) {
      double max_value = 0.0;
      cv::minMaxLoc(gray, nullptr, &max_value);
      int bits = 8;
      while (bits < 16 && max_value >= double(1 << bits)) ++bits;
      mono16_shift_ = bits - 8;
    }
    cv::Mat out;
    gray.convertTo(out, CV_8U, 1.0 / double(1 << mono16_shift_));
    return out;
  }
  return gray;
}

}  // namespace registration
}  // namespace exocet_mosaic
