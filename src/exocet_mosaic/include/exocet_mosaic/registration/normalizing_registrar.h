/**
 * @file normalizing_registrar.h
 * @brief A registrar that hands another one illumination-normalised images (see illumination_normalizer.h), after
 * checking that the camera's image is bright and contrasted enough. No ROS in it.
 */
#pragma once

#include <memory>

#include "exocet_mosaic/registration/frame_registrar.h"
#include "exocet_mosaic/registration/illumination_normalizer.h"
#include "exocet_mosaic/registration/klt_registrar.h"

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
  /// Normalises `gray` into `out`. The darkness and texture checks judge the camera's image, not the normalised
  /// one (its statistics come from the normaliser's pass): false, and `failure` filled, when it fails them.
  bool normalize(const cv::Mat& gray, cv::Mat* out, MotionEstimate* failure);

  std::unique_ptr<FrameRegistrar> inner_;
  KltRegistrar* klt_ = nullptr;  ///< inner_ when it is a KLT registrar: the normaliser writes into its pyramid
  IlluminationNormalizer normalizer_;
  // The normalised images, reused from call to call (registrars copy what they keep of an image).
  cv::Mat normalized_, normalized_previous_;
};

}  // namespace registration
}  // namespace exocet_mosaic
