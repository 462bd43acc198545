/**
 * @file normalizing_registrar.h
 * @brief A registrar that hands another one illumination-normalised images (see illumination_normalizer.h).
 * No ROS in it.
 */
#pragma once

#include <memory>

#include "exocet_mosaic/registration/frame_registrar.h"
#include "exocet_mosaic/registration/illumination_normalizer.h"

namespace exocet_mosaic {
namespace registration {

class NormalizingRegistrar : public FrameRegistrar {
 public:
  NormalizingRegistrar(std::unique_ptr<FrameRegistrar> inner, const IlluminationNormalizerConfig& config);

  void reset() override { inner_->reset(); }
  MotionEstimate registerNext(const cv::Mat& gray,
                              const Eigen::Matrix3d& prediction_px = Eigen::Matrix3d::Identity()) override;
  MotionEstimate registerPair(const cv::Mat& previous, const cv::Mat& current,
                              const Eigen::Matrix3d& prediction_px = Eigen::Matrix3d::Identity()) override;
  RegistrationMethod method() const override { return inner_->method(); }
  FrameRegistrar& inner() { return *inner_; }

 private:
  /// The darkness and texture checks judge the camera's image, not the normalised one: they run here first.
  bool checkInput(const cv::Mat& gray, MotionEstimate* failure) const;

  std::unique_ptr<FrameRegistrar> inner_;
  IlluminationNormalizer normalizer_;
};

}  // namespace registration
}  // namespace exocet_mosaic
