#include "exocet_mosaic/sim/imaging_config.h"

#include <algorithm>
#include <cmath>
#include <sstream>

namespace exocet_mosaic {
namespace sim {

namespace {
void checkRange(std::ostringstream& err, const std::string& field, double v, double lo, double hi, const char* unit) {
  if (!std::isfinite(v) || v < lo || v > hi)
    err << "imaging." << field << " = " << v << " out of range [" << lo << ", " << hi << "]" << unit << "; ";
}
}  // namespace

std::string ImagingConfig::validate() const {
  std::ostringstream err;
  checkRange(err, "exposure_gain", exposure_gain, 0.01, 100.0, "");
  checkRange(err, "gamma", gamma, 0.5, 4.0, "");
  checkRange(err, "light_cone_strength", light_cone_strength, 0.0, 1.0, "");
  checkRange(err, "light_half_angle_deg", light_half_angle_deg, 1.0, 89.0, " deg");
  for (int i = 0; i < 3; ++i) checkRange(err, "light_offset_m", light_offset_m[i], -5.0, 5.0, " m");
  checkRange(err, "vignetting", vignetting, 0.0, 1.0, "");
  for (int i = 0; i < 3; ++i) checkRange(err, "attenuation_per_m", attenuation_per_m[i], 0.0, 5.0, " 1/m");
  checkRange(err, "backscatter", backscatter, 0.0, 1.0, "");
  for (int i = 0; i < 3; ++i) checkRange(err, "backscatter_colour", backscatter_colour[i], 0.0, 1.0, "");
  checkRange(err, "noise_sigma_dn", noise_sigma_dn, 0.0, 50.0, " DN");
  checkRange(err, "shot_noise_dn", shot_noise_dn, 0.0, 10.0, " DN");
  checkRange(err, "marine_snow_per_m3", marine_snow_per_m3, 0.0, 2000.0, " 1/m^3");
  checkRange(err, "marine_snow_size_m", marine_snow_size_m, 0.0005, 0.05, " m");
  checkRange(err, "marine_snow_brightness", marine_snow_brightness, 0.0, 5.0, "");
  checkRange(err, "marine_snow_sink_mps", marine_snow_sink_mps, 0.0, 1.0, " m/s");
  checkRange(err, "motion_blur_exposure_s", motion_blur_exposure_s, 0.0, 0.5, " s");
  if (motion_blur_samples < 2 || motion_blur_samples > 64)
    err << "imaging.motion_blur_samples = " << motion_blur_samples << " out of range [2, 64]; ";
  for (size_t i = 0; i < segments.size(); ++i) {
    const WaterSegment& s = segments[i];
    const std::string f = "segments[" + std::to_string(i) + "].";
    if (!(s.end_s > s.start_s)) err << "imaging." << f << "end_s must be greater than start_s; ";
    checkRange(err, f + "turbidity", s.turbidity, 0.1, 20.0, "");
    checkRange(err, f + "light_gain", s.light_gain, 0.0, 10.0, "");
  }
  std::string s = err.str();
  if (!s.empty()) s.resize(s.size() - 2);
  return s;
}

void ImagingConfig::waterAt(double t_s, double* turbidity, double* light_gain) const {
  *turbidity = 1.0;
  *light_gain = 1.0;
  for (const WaterSegment& s : segments) {
    if (t_s < s.start_s || t_s >= s.end_s) continue;
    // Ramp in and out over a few seconds so that the water changes as a plume drifts by, not in one frame.
    const double ramp_s = std::min(2.0, 0.25 * (s.end_s - s.start_s));
    const double w = std::min({1.0, (t_s - s.start_s) / ramp_s, (s.end_s - t_s) / ramp_s});
    *turbidity *= 1.0 + w * (s.turbidity - 1.0);
    *light_gain *= 1.0 + w * (s.light_gain - 1.0);
  }
}

}  // namespace sim
}  // namespace exocet_mosaic
