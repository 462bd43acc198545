/**
 * @file imaging_config.h
 * @brief Underwater image formation parameters: artificial light, vignetting, attenuation, colour cast,
 * backscatter, sensor noise, marine snow, motion blur. Every amount at zero gives an ideal image (the albedo).
 */
#pragma once

#include <array>
#include <string>
#include <vector>

namespace exocet_mosaic {
namespace sim {

/// A stretch of the dive with other water or light: turbid plumes, a dimmed or failing lamp.
struct WaterSegment {
  double start_s = 0.0;          ///< dive time, seconds from the start
  double end_s = 0.0;
  double turbidity = 1.0;        ///< multiplies attenuation and backscatter (>= 1 is murkier)
  double light_gain = 1.0;       ///< multiplies the lamp (< 1 is darker)
};

struct ImagingConfig {
  double exposure_gain = 1.0;    ///< linear radiance multiplier before the camera response
  double gamma = 2.2;            ///< camera response: value = (gain * radiance)^(1/gamma); 1 = linear
  // Artificial light: a lamp on the vehicle, its beam aimed at the seabed under the camera.
  double light_cone_strength = 0.0;   ///< 0 = uniform ambient light, 1 = lamp only
  double light_half_angle_deg = 35.0; ///< angle off the beam axis where the lamp's intensity halves
  std::array<double, 3> light_offset_m{{0.0, -0.4, 0.0}};  ///< lamp position in the camera frame (y < 0: forward)
  double vignetting = 0.0;            ///< 0 = none, 1 = full cos^4 fall-off
  /// Attenuation coefficients of water (1/m) for R, G, B: red is absorbed first (the colour cast).
  std::array<double, 3> attenuation_per_m{{0.0, 0.0, 0.0}};
  double backscatter = 0.0;           ///< veiling light strength (0..1)
  std::array<double, 3> backscatter_colour{{0.05, 0.30, 0.35}};  ///< veiling light colour, linear RGB
  double noise_sigma_dn = 0.0;        ///< read noise, 1-sigma in 8-bit digital numbers
  double shot_noise_dn = 0.0;         ///< signal-dependent noise: variance += shot_noise_dn * value_dn
  double marine_snow_per_m3 = 0.0;    ///< particle density in the water
  double marine_snow_size_m = 0.004;  ///< mean particle diameter
  double marine_snow_brightness = 0.8;  ///< reflectance-like brightness of a lit particle
  double marine_snow_sink_mps = 0.01; ///< sinking speed of the particles
  double motion_blur_exposure_s = 0.0;  ///< exposure time for motion blur; 0 = none
  int motion_blur_samples = 5;          ///< sub-frames averaged over the exposure
  std::vector<WaterSegment> segments;   ///< turbid or dark stretches

  /// "" if valid, otherwise each problem naming the field (imaging.<name>) and its allowed range.
  std::string validate() const;
  /// Turbidity and light gain at dive time t (1, 1 outside every segment; segments multiply where they overlap).
  void waterAt(double t_s, double* turbidity, double* light_gain) const;
};

}  // namespace sim
}  // namespace exocet_mosaic
