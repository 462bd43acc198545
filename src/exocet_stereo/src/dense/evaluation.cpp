// Middlebury v2 bad-pixel evaluation.
#include "exocet_stereo/dense/evaluation.h"

#include <cmath>
#include <fstream>
#include <limits>
#include <stdexcept>

#include <opencv2/imgcodecs.hpp>

namespace exocet_stereo {
namespace dense {
namespace {

cv::Mat readImage(const std::string& path, int flags) {
  cv::Mat image = cv::imread(path, flags);
  if (image.empty()) throw std::runtime_error("cannot read image " + path);
  return image;
}

}  // namespace

cv::Mat readScaledDisparityPng(const std::string& path, double scale, bool zero_is_unknown) {
  if (!(scale > 0.0)) throw std::invalid_argument("disparity scale must be > 0");
  cv::Mat raw = readImage(path, cv::IMREAD_ANYDEPTH | cv::IMREAD_GRAYSCALE);
  cv::Mat disparity;
  raw.convertTo(disparity, CV_32F, 1.0 / scale);
  if (zero_is_unknown) disparity.setTo(std::numeric_limits<float>::quiet_NaN(), raw == 0);
  return disparity;
}

MiddleburyScene loadMiddleburyScene(const std::string& directory) {
  MiddleburyScene scene;
  const std::string dir = directory.empty() || directory.back() == '/' ? directory : directory + "/";
  const size_t slash = directory.find_last_not_of('/');
  const std::string trimmed = directory.substr(0, slash + 1);
  scene.name = trimmed.substr(trimmed.find_last_of('/') + 1);
  std::ifstream info(dir + "info.txt");
  if (!(info >> scene.scale >> scene.max_disparity_px) || scene.scale <= 0 || scene.max_disparity_px <= 0)
    throw std::runtime_error("cannot read scale and max disparity from " + dir + "info.txt");
  scene.left = readImage(dir + "imL.png", cv::IMREAD_COLOR);
  scene.right = readImage(dir + "imR.png", cv::IMREAD_COLOR);
  scene.ground_truth_px = readScaledDisparityPng(dir + "groundtruth.png", scene.scale, false);
  scene.nonocc = readImage(dir + "nonocc.png", cv::IMREAD_GRAYSCALE);
  scene.all = readImage(dir + "all.png", cv::IMREAD_GRAYSCALE);
  scene.disc = readImage(dir + "disc.png", cv::IMREAD_GRAYSCALE);
  for (const cv::Mat* m : {&scene.right, &scene.ground_truth_px, &scene.nonocc, &scene.all, &scene.disc})
    if (m->size() != scene.left.size()) throw std::runtime_error("image sizes differ in " + dir);
  return scene;
}

double badPixelPercent(const cv::Mat& disparity_px, const cv::Mat& ground_truth_px, const cv::Mat& mask,
                       double threshold_px) {
  if (disparity_px.type() != CV_32F || ground_truth_px.type() != CV_32F || mask.type() != CV_8U)
    throw std::invalid_argument("badPixelPercent: disparity and ground truth must be CV_32F, mask CV_8U");
  if (disparity_px.size() != ground_truth_px.size() || mask.size() != ground_truth_px.size())
    throw std::invalid_argument("badPixelPercent: disparity, ground truth and mask sizes differ");
  long evaluated = 0, bad = 0;
  for (int y = 0; y < mask.rows; ++y) {
    const uint8_t* m = mask.ptr<uint8_t>(y);
    const float* d = disparity_px.ptr<float>(y);
    const float* g = ground_truth_px.ptr<float>(y);
    for (int x = 0; x < mask.cols; ++x) {
      if (m[x] != 255) continue;
      ++evaluated;
      if (!std::isfinite(d[x]) || std::fabs(d[x] - g[x]) > threshold_px) ++bad;
    }
  }
  return evaluated > 0 ? 100.0 * bad / evaluated : 0.0;
}

BadPixelRates evaluateDisparity(const cv::Mat& disparity_px, const MiddleburyScene& scene, double threshold_px) {
  BadPixelRates rates;
  rates.nonocc = badPixelPercent(disparity_px, scene.ground_truth_px, scene.nonocc, threshold_px);
  rates.all = badPixelPercent(disparity_px, scene.ground_truth_px, scene.all, threshold_px);
  rates.disc = badPixelPercent(disparity_px, scene.ground_truth_px, scene.disc, threshold_px);
  return rates;
}

}  // namespace dense
}  // namespace exocet_stereo
