#include "exocet_mosaic/registration/registration_config.h"

#include <stdexcept>

#include "exocet_mosaic/registration/fallback_registrar.h"
#include "exocet_mosaic/registration/normalizing_registrar.h"

namespace exocet_mosaic {
namespace registration {

std::string RegistrationConfig::validate() const {
  KltConfig k = klt;
  k.model = model;
  RmrConfig r = rmr;
  r.model = model;
  std::string error = k.validate();
  if (!error.empty()) return "klt: " + error;
  error = r.validate();
  if (!error.empty()) return "rmr: " + error;
  error = illumination.validate();
  if (!error.empty()) return "illumination: " + error;
  return "";
}

namespace {

std::unique_ptr<FrameRegistrar> makeMethod(const RegistrationConfig& config) {
  KltConfig klt = config.klt;
  klt.model = config.model;
  RmrConfig rmr = config.rmr;
  rmr.model = config.model;
  switch (config.method) {
    case RegistrationMethod::kKlt:
      return std::make_unique<KltRegistrar>(klt);
    case RegistrationMethod::kRmr:
      return std::make_unique<RmrRegistrar>(rmr);
    case RegistrationMethod::kAuto:
      return std::make_unique<FallbackRegistrar>(std::make_unique<KltRegistrar>(klt),
                                                 std::make_unique<RmrRegistrar>(rmr));
  }
  throw std::invalid_argument("unknown registration method");
}

}  // namespace

std::unique_ptr<FrameRegistrar> makeRegistrar(const RegistrationConfig& config) {
  const std::string error = config.validate();
  if (!error.empty()) throw std::invalid_argument(error);
  std::unique_ptr<FrameRegistrar> method = makeMethod(config);
  if (!config.illumination.enabled) return method;
  return std::make_unique<NormalizingRegistrar>(std::move(method), config.illumination);
}

}  // namespace registration
}  // namespace exocet_mosaic
