#include "exocet_mosaic/registration/normalizing_registrar.h"

#include <chrono>
#include <sstream>
#include <stdexcept>

#include <opencv2/imgproc.hpp>

namespace exocet_mosaic {
namespace registration {

NormalizingRegistrar::NormalizingRegistrar(std::unique_ptr<FrameRegistrar> inner,
                                           const IlluminationNormalizerConfig& config)
    : inner_(std::move(inner)), normalizer_(config) {
  if (!inner_) throw std::invalid_argument("NormalizingRegistrar needs a registrar");
}

bool NormalizingRegistrar::checkInput(const cv::Mat& gray, MotionEstimate* failure) const {
  if (gray.empty() || gray.type() != CV_8UC1) return true;  // the inner registrar reports kInvalidInput
  cv::Scalar mean, stddev;
  cv::Mat small;
  cv::resize(gray, small, cv::Size(), 0.25, 0.25, cv::INTER_AREA);
  cv::meanStdDev(small, mean, stddev);
  const IlluminationNormalizerConfig& c = normalizer_.config();
  if (mean[0] >= c.min_mean_grey && stddev[0] >= c.min_stddev_grey) return true;
  std::ostringstream detail;
  detail << "image mean " << mean[0] << " and standard deviation " << stddev[0]
         << " grey levels; at least " << c.min_mean_grey << " and " << c.min_stddev_grey << " are needed";
  *failure = MotionEstimate();
  failure->failed = true;
  failure->failure = mean[0] < c.min_mean_grey ? FailureReason::kTooDark : FailureReason::kTooLittleTexture;
  failure->failure_detail = detail.str();
  failure->method = inner_->method();
  return false;
}

MotionEstimate NormalizingRegistrar::registerNext(const cv::Mat& gray, const Eigen::Matrix3d& prediction_px) {
  const auto start = std::chrono::steady_clock::now();
  MotionEstimate dark;
  const bool usable = checkInput(gray, &dark);
  // Even a dark image goes through, so that the inner registrar's sequence stays in step (and fails on it).
  MotionEstimate e = inner_->registerNext(normalizer_.apply(gray), prediction_px);
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
  if (!checkInput(previous, &dark) || !checkInput(current, &dark)) return dark;
  MotionEstimate e = inner_->registerPair(normalizer_.apply(previous), normalizer_.apply(current), prediction_px);
  e.elapsed_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  return e;
}

}  // namespace registration
}  // namespace exocet_mosaic
