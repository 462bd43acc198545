#include "exocet_mosaic/registration/normalizing_registrar.h"

#include <chrono>
#include <sstream>
#include <stdexcept>

namespace exocet_mosaic {
namespace registration {

NormalizingRegistrar::NormalizingRegistrar(std::unique_ptr<FrameRegistrar> inner,
                                           const IlluminationNormalizerConfig& config)
    : inner_(std::move(inner)), normalizer_(config) {
  if (!inner_) throw std::invalid_argument("NormalizingRegistrar needs a registrar");
  klt_ = dynamic_cast<KltRegistrar*>(inner_.get());
}

bool NormalizingRegistrar::normalize(const cv::Mat& gray, cv::Mat* out, MotionEstimate* failure) {
  InputStatistics input;
  normalizer_.apply(gray, out, &input);
  if (gray.empty() || gray.type() != CV_8UC1) return true;  // the inner registrar reports kInvalidInput
  const IlluminationNormalizerConfig& c = normalizer_.config();
  if (input.mean_grey >= c.min_mean_grey && input.stddev_grey >= c.min_stddev_grey) return true;
  std::ostringstream detail;
  detail << "image mean " << input.mean_grey << " and standard deviation " << input.stddev_grey
         << " grey levels; at least " << c.min_mean_grey << " and " << c.min_stddev_grey << " are needed";
  *failure = MotionEstimate();
  failure->failed = true;
  failure->failure = input.mean_grey < c.min_mean_grey ? FailureReason::kTooDark : FailureReason::kTooLittleTexture;
  failure->failure_detail = detail.str();
  failure->method = inner_->method();
  return false;
}

MotionEstimate NormalizingRegistrar::registerNext(const cv::Mat& gray, const Eigen::Matrix3d& prediction_px) {
  const auto start = std::chrono::steady_clock::now();
  MotionEstimate dark;
  if (klt_ && !gray.empty() && gray.type() == CV_8UC1) {
    // Straight into the KLT pyramid's finest level, which spares a copy of the image.
    normalized_ = klt_->nextImageBuffer(gray.size());
  } else if (normalized_.u && normalized_.u->refcount > 1) {
    normalized_.release();  // should a registrar have kept a reference to the last image after all, it stays intact
  }
  const bool usable = normalize(gray, &normalized_, &dark);
  // Even a dark image goes through, so that the inner registrar's sequence stays in step (and fails on it).
  MotionEstimate e = inner_->registerNext(normalized_, prediction_px);
  if (!usable && !e.failed) e = dark;
  if (!usable && e.failed && e.failure != FailureReason::kNoPreviousFrame && e.failure != FailureReason::kInvalidInput)
    e = dark;
  e.elapsed_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  return e;
}

MotionEstimate NormalizingRegistrar::registerPair(const cv::Mat& previous, const cv::Mat& current,
                                                  const Eigen::Matrix3d& prediction_px) {
  const auto start = std::chrono::steady_clock::now();
  MotionEstimate dark;
  for (cv::Mat* buffer : {&normalized_, &normalized_previous_})
    if (buffer->u && buffer->u->refcount > 1) buffer->release();
  if (!normalize(previous, &normalized_previous_, &dark) || !normalize(current, &normalized_, &dark)) return dark;
  MotionEstimate e = inner_->registerPair(normalized_previous_, normalized_, prediction_px);
  e.elapsed_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  return e;
}

}  // namespace registration
}  // namespace exocet_mosaic
