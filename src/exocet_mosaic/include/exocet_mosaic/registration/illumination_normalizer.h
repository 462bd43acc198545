/**
 * @file illumination_normalizer.h
 * @brief Removes what the water and the lamp add to the seabed's texture before registration: the lamp cone and
 * vignetting (multiplicative, fixed in the image), backscatter (additive, fixed in the image). Both break the
 * brightness constancy the estimators rely on, because the texture moves under them. No ROS in it.
 *
 * Local contrast normalisation: out = 128 + gain * (I - mu) / max(sigma, min_contrast), with mu and sigma the local
 * mean and standard deviation over a wide Gaussian window. The fields are smooth, so they are computed on blocks of
 * 2^level pixels (mu from the pixels, sigma from the half-resolution image, whose finest texture and noise are
 * averaged out), blurred there, and interpolated back in the pass that writes the output: two passes over the
 * image in all.
 */
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

namespace exocet_mosaic {
namespace registration {

struct IlluminationNormalizerConfig {
  bool enabled = true;
  int level = 4;                   ///< mu and sigma are computed on blocks of 2^level pixels, [1, 6]
  double sigma_level_px = 1.0;     ///< Gaussian window in blocks (x 2^level at full resolution: 16 px), [0.5, 20]
  double min_contrast_grey = 4.0;  ///< floor of sigma so that dark, noisy areas are not amplified, [0.5, 100]
  double output_gain = 40.0;       ///< grey levels per local standard deviation in the output, [1, 100]
  /// The camera's image, before normalisation, must reach these, or the pair fails as kTooDark (normalising noise
  /// would otherwise make texture of it). Measured on a quarter-resolution image (means of 4 x 4 pixels), where
  /// the sensor noise does not pass for contrast.
  double min_mean_grey = 8.0;    ///< [0, 255]
  double min_stddev_grey = 2.0;  ///< [0, 128]
  std::string validate() const;
};

/// Brightness of an image before normalisation, over its means of 4 x 4 pixels (the whole image when smaller).
struct InputStatistics {
  double mean_grey = 0.0;
  double stddev_grey = 0.0;
};

/// Not thread-safe: an instance keeps its scratch buffers from image to image.
class IlluminationNormalizer {
 public:
  /// @throws std::invalid_argument naming the bad field of `config`.
  explicit IlluminationNormalizer(const IlluminationNormalizerConfig& config = IlluminationNormalizerConfig());
  /// CV_8UC1 in, a new CV_8UC1 image out (the input itself when disabled, or when it is not CV_8UC1).
  cv::Mat apply(const cv::Mat& gray);
  /**
   * The same into `out`, whose buffer is reused when it already has the size (so that a caller that keeps `out`
   * allocates nothing per image), and the input's statistics (measured in the same pass, also when disabled).
   * An empty or non-CV_8UC1 input is passed through as it is (statistics zero), for the registrar to report.
   */
  void apply(const cv::Mat& gray, cv::Mat* out, InputStatistics* statistics = nullptr);
  const IlluminationNormalizerConfig& config() const { return config_; }

 private:
  /// The block sums of the pixels and of the squared half-resolution pixels, and `statistics`.
  void measure(const cv::Mat& gray, InputStatistics* statistics);
  /// Blurred mean and contrast of the blocks, as the fields out = gain * I + offset.
  void computeFields();
  /// One row of the fields interpolated to every column of the image.
  void expandRow(int coarse_row, float* gain, float* offset) const;

  IlluminationNormalizerConfig config_;
  // Scratch, kept from image to image.
  std::vector<uint16_t> half_, previous_half_, column_sum_;
  std::vector<uint32_t> column_sum_sq_;
  cv::Mat block_mean_, block_mean_sq_, gain_, offset_;  // CV_32F, one value per block
  std::vector<int> expand_run_;
  std::vector<float> expand_wx_, rows_;
  int expand_width_ = -1, expand_blocks_ = -1;
};

}  // namespace registration
}  // namespace exocet_mosaic
