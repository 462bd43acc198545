/**
 * @file lighting_corrector.h
 * @brief Lighting correction: the lamp cone and the lens vignetting are fixed in IMAGE coordinates while the seabed
 * moves under the camera, so the average of many images is the illumination field (times the seabed's mean
 * reflectance). The field is estimated from the images themselves (running average of a downsampled image per
 * channel, strongly low-passed, robust to dark frames) and divided out (gain = target level / field, clamped).
 * No ROS in it.
 */
#pragma once

#include <string>

#include <opencv2/core.hpp>

namespace exocet_mosaic {
namespace compose {

/// Parameters of the lighting correction. validate() lists the allowed ranges.
struct LightingConfig {
  bool enabled = true;     ///< correct the images before composing them
  int warmup_frames = 25;  ///< images averaged before the field is used, [1, 100000]
  /// Sigma of the Gaussian low-pass of the field, as a fraction of the image's larger side, [0, 1]: smooths out the
  /// seabed texture that the average has not yet cancelled (the lamp cone is much smoother).
  double blur_fraction = 0.06;
  int working_width_px = 64;  ///< width of the downsampled field, [8, 1024]
  /// Time constant of the running average after the warm-up (images), [1, 10000000]: lets the field follow slow
  /// changes (altitude changes the cone's footprint) while averaging the texture out.
  int memory_frames = 500;
  double max_gain = 4.0;  ///< gains are clamped to [1 / max_gain, max_gain], [1, 100]
  /// Grey level the field is brought to, [0, 255]; 0: the field's own peak per channel (the image as lit at the
  /// cone's centre, colour balance of the lamp kept).
  double target_level = 0.0;
  /// An image darker on average than this fraction of the field's mean (lamps off, turbidity, the camera in the
  /// water column) does not update the field, [0, 1].
  double min_relative_brightness = 0.3;
  /// The composer feeds the field every image it decodes anyway (key frames, a mosaic's first image) and decodes one
  /// more when none came for this many images, [1, 1000]: images 1/25 s apart are near duplicates, and decoding an
  /// image that is not composed is the composer's main cost for it. 25: one a second at 25 images/s while hovering.
  int sample_interval_frames = 25;

  /// Empty if usable, otherwise every bad field with its allowed range, separated by "; ".
  std::string validate() const;
};

/**
 * @brief Estimates the illumination field from the images and divides it out. The field lives at a working
 * resolution: it fits every image whose working-resolution size and channel count are its own, i.e. the camera's
 * images at full resolution and reduced (image_reduction.h) alike.
 */
class LightingCorrector {
 public:
  /// Throws std::invalid_argument with config.validate()'s text.
  explicit LightingCorrector(const LightingConfig& config = LightingConfig());

  /// Changes the parameters; the field is kept unless the working width changed.
  void setConfig(const LightingConfig& config);
  const LightingConfig& config() const { return config_; }

  /**
   * @brief Adds an image (CV_8UC1 or CV_8UC3) to the field estimate. An image of another shape (aspect, channels)
   * than the field's restarts the estimate. @return true if the image was used (not too dark).
   */
  bool observe(const cv::Mat& image);

  /// True once warmup_frames images were observed.
  bool ready() const;
  int framesUsed() const { return frames_used_; }
  int framesRejected() const { return frames_rejected_; }

  /**
   * @brief The image divided by the field (times the target level), gains clamped; the input itself (not a copy)
   * when the field is not ready or the image does not match it. Same type as the input.
   */
  cv::Mat correct(const cv::Mat& image) const;

  /// The low-passed field at the working resolution, CV_32FC(channels), grey levels; empty if nothing observed.
  cv::Mat field() const;
  /// The field resampled to the image size (CV_32FC(channels)); empty if nothing observed.
  cv::Mat fieldAt(const cv::Size& image_size) const;

  /**
   * @brief The gain correct() applies, averaged over each block of a grid of `grid` blocks laid on an image of
   * `image_size` (CV_32FC(channels)): the levels of an image summarised by blocks, corrected. Empty when the field is
   * not ready or is of another shape.
   */
  cv::Mat gainGrid(const cv::Size& image_size, const cv::Size& grid) const;
  void reset();
  /// A deep copy (the field's data is not shared): for another thread to correct images with the field as it is now.
  LightingCorrector clone() const;

 private:
  cv::Mat smallGain() const;                       // the gains at the working resolution, CV_32FC(n)
  cv::Mat gainMap(const cv::Size& size) const;     // CV_32FC(n) gains of that size, cached per field version
  cv::Size workingSize(const cv::Size& image_size) const;  // the field's size for images of that size
  bool fits(const cv::Size& image_size, int channels) const;

  LightingConfig config_;
  cv::Mat mean_;  // running mean at the working resolution, CV_32FC(n)
  cv::Size working_size_;
  int channels_ = 0;
  int frames_used_ = 0;
  int frames_rejected_ = 0;
  long version_ = 0;
  mutable long gain_version_ = -1;
  mutable cv::Mat gain_;
  mutable cv::Size gain_size_;
};

}  // namespace compose
}  // namespace exocet_mosaic
