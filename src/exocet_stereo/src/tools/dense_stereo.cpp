// dense_stereo: left disparity of a rectified pair with one of the dense methods, written as PFM (+ optional PNG).
#include <cmath>
#include <iostream>
#include <string>

#include <opencv2/imgcodecs.hpp>

#include "exocet_common/command_line.h"
#include "exocet_stereo/dense/dense_stereo.h"
#include "exocet_stereo/io/pfm.h"

namespace {

int badInput(const std::string& error) {
  std::cerr << "dense_stereo: " << error << "\n";
  return exocet_common::kExitBadInput;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace exocet_stereo;
  std::string method, left_path, right_path, output_path, png_path;
  int max_disparity = -1;
  CLI::App app(
      "dense_stereo: left disparity of a rectified pair with one of the dense methods, written as PFM (and "
      "optionally PNG).",
      "dense_stereo");
  app.add_option("--method", method, "dense stereo method")
      ->required()
      ->check(CLI::IsMember(dense::denseStereoMethods()));
  app.add_option("--left", left_path, "rectified left image, 8-bit grey or colour")
      ->type_name("L.png")
      ->required()
      ->check(CLI::ExistingFile);
  app.add_option("--right", right_path, "rectified right image, same size and type as the left")
      ->type_name("R.png")
      ->required()
      ->check(CLI::ExistingFile);
  app.add_option("--max-disparity", max_disparity, "disparity range (pixels), in [1, 512] and < width - 1")
      ->type_name("N")
      ->required()
      ->check(CLI::Range(1, 512));
  app.add_option("--output", output_path, "left disparity (x_right = x_left - d), inf where unknown")
      ->type_name("D.pfm")
      ->required();
  app.add_option("--png", png_path, "also a visualisation: d * 255 / N, 0 where unknown")->type_name("vis.png");
  if (const auto exit_status = exocet_common::parseCommandLine(app, argc, argv)) return *exit_status;
  const cv::Mat left = cv::imread(left_path, cv::IMREAD_UNCHANGED);
  const cv::Mat right = cv::imread(right_path, cv::IMREAD_UNCHANGED);
  if (left.empty()) return badInput("cannot read left image " + left_path);
  if (right.empty()) return badInput("cannot read right image " + right_path);
  cv::Mat disparity;
  try {
    auto matcher = dense::createDenseStereo(method, dense::defaultConfigFor(method, max_disparity));
    const std::string image_error = matcher->checkImages(left, right);
    if (!image_error.empty()) return badInput(image_error);
    disparity = matcher->compute(left, right);
  } catch (const std::invalid_argument& e) {
    return badInput(e.what());
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
