/**
 * @file illumination_normalizer.h
 * @brief Removes what the water and the lamp add to the seabed's texture before registration: the lamp cone and
 * vignetting (multiplicative, fixed in the image), backscatter (additive, fixed in the image). Both break the
 * brightness constancy the estimators rely on, because the texture moves under them. No ROS in it.
 *
 * Local contrast normalisation: out = 128 + gain * (I - mu) / max(sigma, min_contrast), with mu and sigma the local
 * mean and standard deviation over a wide Gaussian window, computed on a coarse pyramid level and interpolated back
 * (the fields are smooth, and this keeps the cost near one pass over the image).
 */
#pragma once

#include <string>

#include <opencv2/core.hpp>

namespace exocet_mosaic {
namespace registration {

struct IlluminationNormalizerConfig {
  bool enabled = true;
  int level = 3;                  ///< pyramid level where mu and sigma are computed, [1, 6]
  double sigma_level_px = 2.0;    ///< Gaussian window at that level (x 2^level at full resolution), [0.5, 20]
  double min_contrast_grey = 4.0; ///< floor of sigma so that dark, noisy areas are not amplified, [0.5, 100]
  double output_gain = 40.0;      ///< grey levels per local standard deviation in the output, [1, 100]
  /// The camera's image, before normalisation, must reach these, or the pair fails as kTooDark (normalising noise
  /// would otherwise make texture of it).
  double min_mean_grey = 8.0;     ///< [0, 255]
  double min_stddev_grey = 2.0;   ///< [0, 128]
  std::string validate() const;
};

class IlluminationNormalizer {
 public:
  explicit IlluminationNormalizer(const IlluminationNormalizerConfig& config = IlluminationNormalizerConfig());
  /// CV_8UC1 in, CV_8UC1 out (the input itself when disabled).
  cv::Mat apply(const cv::Mat& gray) const;
  const IlluminationNormalizerConfig& config() const { return config_; }

 private:
  IlluminationNormalizerConfig config_;
};

}  // namespace registration
}  // namespace exocet_mosaic
