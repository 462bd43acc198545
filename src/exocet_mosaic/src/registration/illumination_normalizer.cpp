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
  // The fields are smooth, so everything but the last pass runs on reduced images: the mean from the 8-bit
  // pyramid, the mean of squares from the half-resolution level (the finest texture's share of the variance is
  // lost alike everywhere, which only rescales the output).
  cv::Mat half, coarse8;
  cv::pyrDown(gray, half);
  coarse8 = half;
  for (int l = 1; l < config_.level; ++l) cv::pyrDown(coarse8, coarse8);
  cv::Mat half_f, coarse_sq, mean;
  half.convertTo(half_f, CV_32F);
  coarse_sq = half_f.mul(half_f);
  for (int l = 1; l < config_.level; ++l) cv::pyrDown(coarse_sq, coarse_sq);
  coarse8.convertTo(mean, CV_32F);
  cv::GaussianBlur(mean, mean, cv::Size(), config_.sigma_level_px, 0.0, cv::BORDER_REFLECT);
  cv::GaussianBlur(coarse_sq, coarse_sq, cv::Size(), config_.sigma_level_px, 0.0, cv::BORDER_REFLECT);
  cv::Mat inv_sigma(mean.size(), CV_32F);
  const float floor_sq = float(config_.min_contrast_grey * config_.min_contrast_grey);
  for (int r = 0; r < mean.rows; ++r) {
    const float* m = mean.ptr<float>(r);
    const float* q = coarse_sq.ptr<float>(r);
    float* o = inv_sigma.ptr<float>(r);
    for (int c = 0; c < mean.cols; ++c)
      o[c] = float(config_.output_gain) / std::sqrt(std::max(q[c] - m[c] * m[c], floor_sq));
  }

  // Bilinear interpolation of the two coarse fields back to full resolution, fused with the normalisation: per row
  // the two coarse rows are blended once, then each pixel blends two columns.
  const int cw = mean.cols, ch = mean.rows;
  const float scale_x = float(cw) / float(gray.cols), scale_y = float(ch) / float(gray.rows);
  std::vector<int> x0(gray.cols);
  std::vector<float> wx(gray.cols);
  for (int x = 0; x < gray.cols; ++x) {
    const float cx = std::min(std::max((x + 0.5f) * scale_x - 0.5f, 0.0f), float(cw - 1));
    x0[x] = std::min(int(cx), std::max(cw - 2, 0));
    wx[x] = cw > 1 ? cx - float(x0[x]) : 0.0f;
  }
  std::vector<float> row_mean(cw + 1), row_gain(cw + 1);
  cv::Mat out(gray.size(), CV_8UC1);
  for (int y = 0; y < gray.rows; ++y) {
    const float cy = std::min(std::max((y + 0.5f) * scale_y - 0.5f, 0.0f), float(ch - 1));
    const int y0 = std::min(int(cy), std::max(ch - 2, 0));
    const int y1 = std::min(y0 + 1, ch - 1);
    const float wy = ch > 1 ? cy - float(y0) : 0.0f;
    const float *m0 = mean.ptr<float>(y0), *m1 = mean.ptr<float>(y1);
    const float *g0 = inv_sigma.ptr<float>(y0), *g1 = inv_sigma.ptr<float>(y1);
    for (int c = 0; c < cw; ++c) {
      row_mean[c] = m0[c] + wy * (m1[c] - m0[c]);
      row_gain[c] = g0[c] + wy * (g1[c] - g0[c]);
    }
    row_mean[cw] = row_mean[cw - 1];
    row_gain[cw] = row_gain[cw - 1];
    const uint8_t* in = gray.ptr<uint8_t>(y);
    uint8_t* o = out.ptr<uint8_t>(y);
    for (int x = 0; x < gray.cols; ++x) {
      const int i = x0[x];
      const float w = wx[x];
      const float mu = row_mean[i] + w * (row_mean[i + 1] - row_mean[i]);
      const float gain = row_gain[i] + w * (row_gain[i + 1] - row_gain[i]);
      o[x] = cv::saturate_cast<uint8_t>(128.0f + (float(in[x]) - mu) * gain);
    }
  }
  return out;
}

}  // namespace registration
}  // namespace exocet_mosaic
