#include "exocet_mosaic/registration/fallback_registrar.h"

#include <stdexcept>

namespace exocet_mosaic {
namespace registration {
namespace {

// Failures that are about the input or the sequence, not about the method: another method would fail too.
bool worthAnotherMethod(FailureReason reason) {
  return reason != FailureReason::kNone && reason != FailureReason::kNoPreviousFrame &&
         reason != FailureReason::kInvalidInput;
}

}  // namespace

FallbackRegistrar::FallbackRegistrar(std::unique_ptr<FrameRegistrar> primary, std::unique_ptr<FrameRegistrar> fallback)
    : primary_(std::move(primary)), fallback_(std::move(fallback)) {
  if (!primary_ || !fallback_) throw std::invalid_argument("FallbackRegistrar needs two registrars");
}

void FallbackRegistrar::reset() {
  primary_->reset();
  fallback_->reset();
  previous_.release();
}

MotionEstimate FallbackRegistrar::tryFallback(MotionEstimate primary_result, const cv::Mat& previous,
                                              const cv::Mat& current, const Eigen::Matrix3d& prediction_px) {
  if (!primary_result.failed || !worthAnotherMethod(primary_result.failure) || previous.empty() ||
      previous.size() != current.size())
    return primary_result;
  ++fallback_attempts_;
  MotionEstimate second = fallback_->registerPair(previous, current, prediction_px);
  if (!second.failed) {
    ++fallback_successes_;
    second.elapsed_ms += primary_result.elapsed_ms;
    return second;
  }
  primary_result.failure_detail +=
      "; " + toString(fallback_->method()) + " also failed: " + toString(second.failure) + " (" +
      second.failure_detail + ")";
  primary_result.elapsed_ms += second.elapsed_ms;
  return primary_result;
}

MotionEstimate FallbackRegistrar::registerNext(const cv::Mat& gray, const Eigen::Matrix3d& prediction_px) {
  MotionEstimate result = primary_->registerNext(gray, prediction_px);
  result = tryFallback(std::move(result), previous_, gray, prediction_px);
  // A copy: the caller may reuse its buffer, and the fallback needs this image as the next pair's first.
  gray.copyTo(previous_);
  return result;
}

MotionEstimate FallbackRegistrar::registerPair(const cv::Mat& previous, const cv::Mat& current,
                                               const Eigen::Matrix3d& prediction_px) {
  return tryFallback(primary_->registerPair(previous, current, prediction_px), previous, current, prediction_px);
}

}  // namespace registration
}  // namespace exocet_mosaic
