#include "exocet_mosaic/compose/lighting_corrector.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <vector>

#include <opencv2/imgproc.hpp>

namespace exocet_mosaic {
namespace compose {

std::string LightingConfig::validate() const {
  std::vector<std::string> bad;
  auto out = [](double v) {
    std::ostringstream s;
    s << v;
    return s.str();
  };
  if (warmup_frames < 1 || warmup_frames > 100000)
    bad.push_back("lighting.warmup_frames must be in [1, 100000], got " + out(warmup_frames));
  if (!(blur_fraction >= 0.0 && blur_fraction <= 1.0))
    bad.push_back("lighting.blur_fraction must be in [0, 1], got " + out(blur_fraction));
  if (working_width_px < 8 || working_width_px > 1024)
    bad.push_back("lighting.working_width_px must be in [8, 1024], got " + out(working_width_px));
  if (memory_frames < 1 || memory_frames > 10000000)
    bad.push_back("lighting.memory_frames must be in [1, 10000000], got " + out(memory_frames));
  if (!(max_gain >= 1.0 && max_gain <= 100.0))
    bad.push_back("lighting.max_gain must be in [1, 100], got " + out(max_gain));
  if (!(target_level >= 0.0 && target_level <= 255.0))
    bad.push_back("lighting.target_level must be in [0, 255] (0: the field's peak), got " + out(target_level));
  if (!(min_relative_brightness >= 0.0 && min_relative_brightness <= 1.0))
    bad.push_back("lighting.min_relative_brightness must be in [0, 1], got " + out(min_relative_brightness));
  if (sample_interval_frames < 1 || sample_interval_frames > 1000)
    bad.push_back("lighting.sample_interval_frames must be in [1, 1000], got " + out(sample_interval_frames));
  std::string joined;
  for (const auto& b : bad) joined += (joined.empty() ? "" : "; ") + b;
  return joined;
}

LightingCorrector::LightingCorrector(const LightingConfig& config) : config_(config) {
  const std::string error = config.validate();
  if (!error.empty()) throw std::invalid_argument(error);
}

void LightingCorrector::setConfig(const LightingConfig& config) {
  const std::string error = config.validate();
  if (!error.empty()) throw std::invalid_argument(error);
  const bool restart = config.working_width_px != config_.working_width_px;
  config_ = config;
  if (restart) reset();
  ++version_;  // blur, gain limits or target may have changed
}

LightingCorrector LightingCorrector::clone() const {
  LightingCorrector copy(*this);
  copy.mean_ = mean_.clone();
  copy.gain_ = gain_.clone();
  return copy;
}

void LightingCorrector::reset() {
  mean_.release();
  working_size_ = cv::Size();
  channels_ = 0;
  frames_used_ = 0;
  frames_rejected_ = 0;
  ++version_;
}

bool LightingCorrector::ready() const { return frames_used_ >= config_.warmup_frames && !mean_.empty(); }

cv::Size LightingCorrector::workingSize(const cv::Size& image_size) const {
  if (image_size.width <= 0 || image_size.height <= 0) return cv::Size();
  const int w = std::min(config_.working_width_px, image_size.width);
  const int h = std::max(1, static_cast<int>(std::lround(static_cast<double>(image_size.height) * w / image_size.width)));
  return cv::Size(w, h);
}

bool LightingCorrector::fits(const cv::Size& image_size, int channels) const {
  return channels == channels_ && !working_size_.empty() && workingSize(image_size) == working_size_;
}

bool LightingCorrector::observe(const cv::Mat& image) {
  if (image.empty() || image.depth() != CV_8U || (image.channels() != 1 && image.channels() != 3)) return false;
  if (!fits(image.size(), image.channels())) {
    reset();
    working_size_ = workingSize(image.size());
    channels_ = image.channels();
  }
  cv::Mat small, small_f;
  cv::resize(image, small, working_size_, 0, 0, cv::INTER_AREA);  // INTER_AREA: a true average, no aliasing
  small.convertTo(small_f, CV_32F);
  // Dark frames (lamps off, the camera in the water column, a cloud of sediment) would pull the field down.
  const cv::Scalar m = cv::mean(small_f);
  double level = 0;
  for (int c = 0; c < channels_; ++c) level += m[c] / channels_;
  if (!mean_.empty()) {
    const cv::Scalar fm = cv::mean(mean_);
    double field_level = 0;
    for (int c = 0; c < channels_; ++c) field_level += fm[c] / channels_;
    if (level < config_.min_relative_brightness * field_level || level < 1.0) {
      ++frames_rejected_;
      return false;
    }
  } else if (level < 1.0) {
    ++frames_rejected_;
    return false;
  }
  ++frames_used_;
  if (mean_.empty()) {
    mean_ = small_f;
  } else {
    // Cumulative mean during the warm-up, then an exponential average with memory_frames' time constant.
    const double alpha = 1.0 / std::min(frames_used_, std::max(config_.memory_frames, 1));
    cv::addWeighted(mean_, 1.0 - alpha, small_f, alpha, 0.0, mean_);
  }
  ++version_;
  return true;
}

cv::Mat LightingCorrector::field() const {
  if (mean_.empty()) return cv::Mat();
  const double sigma = config_.blur_fraction * std::max(mean_.cols, mean_.rows);
  if (sigma < 0.3) return mean_.clone();
  cv::Mat f;
  // Reflection at the borders keeps the level of the image's edges (no dark rim from zero padding).
  cv::GaussianBlur(mean_, f, cv::Size(0, 0), sigma, sigma, cv::BORDER_REFLECT);
  return f;
}

cv::Mat LightingCorrector::fieldAt(const cv::Size& image_size) const {
  const cv::Mat f = field();
  if (f.empty()) return f;
  cv::Mat out;
  cv::resize(f, out, image_size, 0, 0, cv::INTER_LINEAR);
  return out;
}

cv::Mat LightingCorrector::smallGain() const {
  const cv::Mat f = field();
  std::vector<cv::Mat> planes;
  cv::split(f, planes);
  const double max_gain = config_.max_gain, min_gain = 1.0 / config_.max_gain;
  for (auto& p : planes) {
    double peak = 0;
    cv::minMaxLoc(p, nullptr, &peak);
    const double target = config_.target_level > 0 ? config_.target_level : peak;
    cv::Mat g;
    cv::max(p, 1e-3, g);
    cv::divide(target, g, g);
    cv::min(g, max_gain, g);
    cv::max(g, min_gain, g);
    p = g;
  }
  cv::Mat small_gain;
  cv::merge(planes, small_gain);
  return small_gain;
}

cv::Mat LightingCorrector::gainMap(const cv::Size& size) const {
  if (gain_version_ == version_ && gain_size_ == size && !gain_.empty()) return gain_;
  cv::Mat full;
  cv::resize(smallGain(), full, size, 0, 0, cv::INTER_LINEAR);
  gain_ = full;
  gain_size_ = size;
  gain_version_ = version_;
  return gain_;
}

cv::Mat LightingCorrector::gainGrid(const cv::Size& image_size, const cv::Size& grid) const {
  if (!ready() || !fits(image_size, channels_) || grid.width < 1 || grid.height < 1) return cv::Mat();
  // The full-size gain is the working one upsampled linearly: its block means are the working one's area means.
  cv::Mat out;
  cv::resize(smallGain(), out, grid, 0, 0, cv::INTER_AREA);
  return out;
}

cv::Mat LightingCorrector::correct(const cv::Mat& image) const {
  if (!ready() || !fits(image.size(), image.channels()) || image.depth() != CV_8U) return image;
  const cv::Mat gain = gainMap(image.size());
  cv::Mat out(image.size(), image.type());
  const int n = image.cols * channels_;
  for (int y = 0; y < image.rows; ++y) {
    const uchar* src = image.ptr<uchar>(y);
    const float* g = gain.ptr<float>(y);
    uchar* dst = out.ptr<uchar>(y);
    for (int i = 0; i < n; ++i) dst[i] = cv::saturate_cast<uchar>(src[i] * g[i]);
  }
  return out;
}

}  // namespace compose
}  // namespace exocet_mosaic
