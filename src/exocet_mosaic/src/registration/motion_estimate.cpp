#include "exocet_mosaic/registration/motion_estimate.h"

#include <stdexcept>

namespace exocet_mosaic {
namespace registration {

std::string toString(RegistrationMethod method) {
  switch (method) {
    case RegistrationMethod::kKlt:
      return "klt";
    case RegistrationMethod::kRmr:
      return "rmr";
    case RegistrationMethod::kAuto:
      return "auto";
  }
  return "unknown";
}

RegistrationMethod registrationMethodFromString(const std::string& name) {
  if (name == "klt") return RegistrationMethod::kKlt;
  if (name == "rmr") return RegistrationMethod::kRmr;
  if (name == "auto") return RegistrationMethod::kAuto;
  throw std::invalid_argument("registration method '" + name + "': allowed values are klt, rmr, auto");
}

std::string toString(FailureReason reason) {
  switch (reason) {
    case FailureReason::kNone:
      return "none";
    case FailureReason::kNoPreviousFrame:
      return "no_previous_frame";
    case FailureReason::kInvalidInput:
      return "invalid_input";
    case FailureReason::kTooDark:
      return "too_dark";
    case FailureReason::kTooLittleTexture:
      return "too_little_texture";
    case FailureReason::kTooFewTracks:
      return "too_few_tracks";
    case FailureReason::kTooFewInliers:
      return "too_few_inliers";
    case FailureReason::kMotionTooLarge:
      return "motion_too_large";
    case FailureReason::kNotConverged:
      return "not_converged";
    case FailureReason::kInconsistent:
      return "inconsistent";
  }
  return "unknown";
}

}  // namespace registration
}  // namespace exocet_mosaic
