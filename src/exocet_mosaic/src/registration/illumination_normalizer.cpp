#include "exocet_mosaic/registration/illumination_normalizer.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <vector>

#include <opencv2/imgproc.hpp>

namespace exocet_mosaic {
namespace registration {

std::string IlluminationNormalizerConfig::validate() const {
  std::string errors;
  const auto check = [&errors](bool ok, const std::string& what) {
    if (!ok) errors += (errors.empty() ? "" : "; ") + what;
  };
  check(level >= 1 && level <= 6, "level must be in [1, 6]");
  check(sigma_level_px >= 0.5 && sigma_level_px <= 20.0, "sigma_level_px must be in [0.5, 20]");
  check(min_contrast_grey >= 0.5 && min_contrast_grey <= 100.0, "min_contrast_grey must be in [0.5, 100]");
  check(min_mean_grey >= 0.0 && min_mean_grey <= 255.0, "min_mean_grey must be in [0, 255]");
  check(min_stddev_grey >= 0.0 && min_stddev_grey <= 128.0, "min_stddev_grey must be in [0, 128]");
  check(output_gain >= 1.0 && output_gain <= 100.0, "output_gain must be in [1, 100]");
  return errors;
}

IlluminationNormalizer::IlluminationNormalizer(const IlluminationNormalizerConfig& config) : config_(config) {
  const std::string error = config_.validate();
  if (!error.empty()) throw std::invalid_argument("illumination normaliser: " + error);
}

cv::Mat IlluminationNormalizer::apply(const cv::Mat& gray) const {
  if (!config_.enabled || gray.empty()) return gray;
  // Mean and mean of squares at the coarse level, each Gaussian-smoothed; sigma from their difference.
  cv::Mat f;
  gray.convertTo(f, CV_32F);
  cv::Mat coarse = f, coarse_sq = f.mul(f);
  for (int l = 0; l < config_.level; ++l) {
    cv::pyrDown(coarse, coarse);
    cv::pyrDown(coarse_sq, coarse_sq);
  }
  cv::GaussianBlur(coarse, coarse, cv::Size(), config_.sigma_level_px, 0.0, cv::BORDER_REFLECT);
  cv::GaussianBlur(coarse_sq, coarse_sq, cv::Size(), config_.sigma_level_px, 0.0, cv::BORDER_REFLECT);
  cv::Mat inv_sigma(coarse.size(), CV_32F);
  const float floor_sq = float(config_.min_contrast_grey * config_.min_contrast_grey);
  for (int r = 0; r < coarse.rows; ++r) {
    const float* m = coarse.ptr<float>(r);
    const float* s = coarse_sq.ptr<float>(r);
    float* o = inv_sigma.ptr<float>(r);
    for (int c = 0; c < coarse.cols; ++c) o[c] = float(config_.output_gain) / std::sqrt(std::max(s[c] - m[c] * m[c], floor_sq));
  }
  cv::Mat fields[2] = {coarse, inv_sigma}, merged, full;
  cv::merge(fields, 2, merged);
  cv::resize(merged, full, gray.size(), 0.0, 0.0, cv::INTER_LINEAR);
  cv::Mat out(gray.size(), CV_8UC1);
  for (int r = 0; r < gray.rows; ++r) {
    const float* in = f.ptr<float>(r);
    const cv::Vec2f* mi = full.ptr<cv::Vec2f>(r);
    uint8_t* o = out.ptr<uint8_t>(r);
    for (int c = 0; c < gray.cols; ++c) o[c] = cv::saturate_cast<uint8_t>(128.0f + (in[c] - mi[c][0]) * mi[c][1]);
  }
  return out;
}

}  // namespace registration
}  // namespace exocet_mosaic
