// Builds the seabed (texture and relief) a dive description asks for.
#include <stdexcept>

#include "exocet_mosaic/sim/debris_field.h"
#include "exocet_mosaic/sim/dive_description.h"
#include "exocet_mosaic/sim/image_seabed.h"
#include "exocet_mosaic/sim/procedural_seabed.h"

namespace exocet_mosaic {
namespace sim {

Seabed makeSeabed(const SeabedSpec& spec, uint64_t seed) {
  Seabed seabed;
  if (spec.kind == "image") {
    seabed.texture = std::make_unique<ImageSeabed>(spec.image, spec.image_pixel_size_m, spec.image_center_x_m,
                                                   spec.image_center_y_m);
    seabed.relief = std::make_unique<FlatRelief>();
    return seabed;
  }
  if (spec.kind != "procedural") throw std::invalid_argument("seabed.kind '" + spec.kind + "' is not one of procedural, image");
  ProceduralSeabedConfig config;
  config.seed = seed;
  config.base_texel_m = spec.texel_m;
  config.cache_budget_mb = spec.cache_budget_mb;
  config.relief_enabled = spec.relief && spec.relief_scale > 0.0;
  config.mound_amplitude_m *= spec.relief_scale;
  config.rock_height_scale *= spec.relief_scale;
  config.ripple_height_m *= spec.relief_scale;
  // The vehicle flies at a set height over the reference plane, not terrain-following: keep the regional slope
  // to a local one (+-0.3 m over +-15 m) so that the seabed stays under the camera over a long survey.
  config.regional_slope = 0.02 * spec.relief_scale;
  config.regional_slope_extent_m = 15.0;
  const std::string problem = config.validate();
  if (!problem.empty()) throw std::invalid_argument("seabed: " + problem);
  seabed.texture = std::make_unique<ProceduralSeabedTexture>(config);
  if (config.relief_enabled)
    seabed.relief = std::make_unique<ProceduralRelief>(config);
  else
    seabed.relief = std::make_unique<FlatRelief>();
  if (spec.objects != "none") {
    DebrisFieldConfig debris = DebrisFieldConfig::fromPreset(spec.objects, seed);
    if (spec.objects_density_per_m2 >= 0.0) debris.density_per_m2 = spec.objects_density_per_m2;
    auto relief = std::make_unique<DebrisRelief>(debris, std::move(seabed.relief));
    seabed.texture = std::make_unique<DebrisTexture>(std::move(seabed.texture), relief.get(), seed);
    seabed.relief = std::move(relief);
  }
  return seabed;
}

}  // namespace sim
}  // namespace exocet_mosaic
