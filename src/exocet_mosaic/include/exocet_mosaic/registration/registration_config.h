/**
 * @file registration_config.h
 * @brief Everything that configures the frame-to-frame registration, and the factory of the registrar it describes.
 * No ROS in it.
 */
#pragma once

#include <memory>
#include <string>

#include "exocet_mosaic/registration/frame_registrar.h"
#include "exocet_mosaic/registration/illumination_normalizer.h"
#include "exocet_mosaic/registration/klt_registrar.h"
#include "exocet_mosaic/registration/rmr_registrar.h"

namespace exocet_mosaic {
namespace registration {

struct RegistrationConfig {
  /// klt, rmr, or auto: KLT first (fast), RMR on the pairs where KLT fails (whole-image, needs no features).
  RegistrationMethod method = RegistrationMethod::kAuto;
  /// The motion model of both methods (overrides klt.model and rmr.model).
  MotionModel model = MotionModel::kSimilarity;
  KltConfig klt;
  RmrConfig rmr;
  /// Local contrast normalisation of every image before either method sees it (lamp cone, vignetting,
  /// backscatter).
  IlluminationNormalizerConfig illumination;

  /// Empty if usable, otherwise what is wrong (naming the field and its allowed range).
  std::string validate() const;
};

/// The registrar the configuration describes. @throws std::invalid_argument with validate()'s message.
std::unique_ptr<FrameRegistrar> makeRegistrar(const RegistrationConfig& config);

}  // namespace registration
}  // namespace exocet_mosaic
