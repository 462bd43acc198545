/**
 * @file fallback_registrar.h
 * @brief Method `auto`: a primary registration method, and a second one tried on the same pair when the first fails.
 * No ROS in it.
 */
#pragma once

#include <memory>

#include "exocet_mosaic/registration/frame_registrar.h"

namespace exocet_mosaic {
namespace registration {

/**
 * Runs `primary` on every image (so that its per-frame state stays current) and, when it fails on a pair for a
 * reason another method may overcome (too few tracks, too little texture, no convergence...), runs `fallback` on
 * that pair. The result says which method produced it; when both fail, the primary's failure is returned with the
 * fallback's reason appended to its detail.
 */
class FallbackRegistrar : public FrameRegistrar {
 public:
  FallbackRegistrar(std::unique_ptr<FrameRegistrar> primary, std::unique_ptr<FrameRegistrar> fallback);

  void reset() override;
  MotionEstimate registerNext(const cv::Mat& gray,
                              const Eigen::Matrix3d& prediction_px = Eigen::Matrix3d::Identity()) override;
  MotionEstimate registerPair(const cv::Mat& previous, const cv::Mat& current,
                              const Eigen::Matrix3d& prediction_px = Eigen::Matrix3d::Identity()) override;
  RegistrationMethod method() const override { return RegistrationMethod::kAuto; }

  /// Pairs on which the fallback was tried, and on which it succeeded.
  int fallbackAttempts() const { return fallback_attempts_; }
  int fallbackSuccesses() const { return fallback_successes_; }

 private:
  MotionEstimate tryFallback(MotionEstimate primary_result, const cv::Mat& previous, const cv::Mat& current,
                             const Eigen::Matrix3d& prediction_px);

  std::unique_ptr<FrameRegistrar> primary_;
  std::unique_ptr<FrameRegistrar> fallback_;
  cv::Mat previous_;
  int fallback_attempts_ = 0;
  int fallback_successes_ = 0;
};

}  // namespace registration
}  // namespace exocet_mosaic
