// dense_stereo: left disparity of a rectified pair with one of the dense methods, written as PFM (+ optional PNG).
#include <cmath>
#include <iostream>
#include <string>

#include <opencv2/imgcodecs.hpp>

#include "exocet_stereo/dense/dense_stereo.h"
#include "exocet_stereo/io/pfm.h"

namespace {

int usage(const std::string& error) {
  if (!error.empty()) std::cerr << "dense_stereo: " << error << "\n";
  std::cerr << "usage: dense_stereo --method ssd|dp|so|sgm|gc|bd|sgbm|pm --left L.png --right R.png --max-disparity N\n"
               "                    --output D.pfm [--png vis.png]\n"
               "  L/R: rectified 8-bit images (grey or colour) of the same size; N in [1, 512] and < width - 1.\n"
               "  D.pfm: left disparity (x_right = x_left - d), inf where unknown; vis.png: d * 255 / N, 0 unknown.\n";
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace exocet_stereo;
  std::string method, left_path, right_path, output_path, png_path;
  int max_disparity = -1;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--help" || arg == "-h") return usage(""), 0;
    if (i + 1 >= argc) return usage("option " + arg + " needs a value");
    const std::string value = argv[++i];
    if (arg == "--method")
      method = value;
    else if (arg == "--left")
      left_path = value;
    else if (arg == "--right")
      right_path = value;
    else if (arg == "--output")
      output_path = value;
    else if (arg == "--png")
      png_path = value;
    else if (arg == "--max-disparity") {
      try {
        size_t used = 0;
        max_disparity = std::stoi(value, &used);
        if (used != value.size()) throw std::invalid_argument(value);
      } catch (const std::exception&) {
        return usage("--max-disparity must be an integer, got '" + value + "'");
      }
    } else {
      return usage("unknown option " + arg);
    }
  }
  if (method.empty() || left_path.empty() || right_path.empty() || output_path.empty() || max_disparity < 0)
    return usage("--method, --left, --right, --max-disparity and --output are required");
  const cv::Mat left = cv::imread(left_path, cv::IMREAD_UNCHANGED);
  const cv::Mat right = cv::imread(right_path, cv::IMREAD_UNCHANGED);
  if (left.empty()) return usage("cannot read left image " + left_path);
  if (right.empty()) return usage("cannot read right image " + right_path);
  cv::Mat disparity;
  try {
    auto matcher = dense::createDenseStereo(method, dense::defaultConfigFor(method, max_disparity));
    const std::string image_error = matcher->checkImages(left, right);
    if (!image_error.empty()) return usage(image_error);
    disparity = matcher->compute(left, right);
  } catch (const std::invalid_argument& e) {
    return usage(e.what());
  }
  try {
    io::writePfm(output_path, disparity);
    if (!png_path.empty()) {
      cv::Mat vis(disparity.size(), CV_8U);
      for (int y = 0; y < disparity.rows; ++y)
        for (int x = 0; x < disparity.cols; ++x) {
          const float d = disparity.at<float>(y, x);
          vis.at<uint8_t>(y, x) = std::isfinite(d) ? cv::saturate_cast<uint8_t>(d * 255.0f / max_disparity) : 0;
        }
      if (!cv::imwrite(png_path, vis)) throw std::runtime_error("cannot write " + png_path);
    }
  } catch (const std::exception& e) {
    std::cerr << "dense_stereo: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
