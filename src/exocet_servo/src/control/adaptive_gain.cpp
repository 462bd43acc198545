#include "exocet_servo/control/adaptive_gain.h"

#include <cmath>
#include <sstream>

namespace exocet_servo {
namespace control {

double AdaptiveGain::operator()(double error_norm) const {
  const double span = gain_at_zero - gain_at_infinity;
  if (span <= 0.0 || slope_at_zero <= 0.0) return gain_at_zero;
  return span * std::exp(-slope_at_zero * error_norm / span) + gain_at_infinity;
}

std::string AdaptiveGain::validate() const {
  std::ostringstream errors;
  auto check = [&errors](bool ok, const char* field, const std::string& range) {
    if (ok) return;
    if (errors.tellp() > 0) errors << "; ";
    errors << field << " must be in " << range;
  };
  check(gain_at_zero > 0.0 && gain_at_zero <= 100.0, "gain.gain_at_zero", "(0, 100]");
  check(gain_at_infinity > 0.0 && gain_at_infinity <= gain_at_zero, "gain.gain_at_infinity", "(0, gain_at_zero]");
  check(slope_at_zero >= 0.0 && slope_at_zero <= 1e6, "gain.slope_at_zero", "[0, 1e6]");
  return errors.str();
}

AdaptiveGain AdaptiveGain::constant(double gain) {
  AdaptiveGain g;
  g.gain_at_zero = gain;
  g.gain_at_infinity = gain;
  g.slope_at_zero = 0.0;
  return g;
}

}  // namespace control
}  // namespace exocet_servo
