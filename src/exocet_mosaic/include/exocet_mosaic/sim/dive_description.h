/**
 * @file dive_description.h
 * @brief A whole simulated dive as the user describes it in YAML: read strictly (unknown keys and values out of
 * range are errors naming the key and the allowed range), overridable from the command line, and written back in
 * full beside the bag so that every bag says how it was made.
 */
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "exocet_mosaic/sim/dive_synthesizer.h"

namespace YAML {
class Node;
}

namespace exocet_mosaic {
namespace sim {

/// Which seabed to render.
struct SeabedSpec {
  std::string kind = "procedural";  ///< procedural | image
  double texel_m = 0.002;           ///< procedural: texel size of the finest level
  double cache_budget_mb = 256.0;   ///< procedural: memory for generated tiles
  bool relief = false;              ///< procedural: rocks, mounds and slopes in 3D (else a plane)
  double relief_scale = 1.0;        ///< multiplies the relief heights (0..2)
  /// Objects with steep sides on the seabed (debris_field.h): none | wreck (piled amphorae, blocks) | boulders.
  std::string objects = "none";
  double objects_density_per_m2 = -1.0;  ///< mean objects per square metre [0, 5]; < 0: the preset's
  std::string image;                ///< image: path of the seabed picture (top row = north)
  double image_pixel_size_m = 0.005;  ///< image: ground size of one pixel
  double image_center_x_m = 0.0;    ///< image: local position of the picture's centre
  double image_center_y_m = 0.0;
};

struct DiveDescription {
  DiveSynthesisConfig synthesis;
  SeabedSpec seabed;
  double origin_latitude_deg = 43.05;  ///< dive origin (WGS 84): off La Seyne-sur-Mer by default
  double origin_longitude_deg = 5.85;
  std::string waypoints_csv;           ///< trajectory.kind = waypoints
  std::string intrinsics_yaml;         ///< camera intrinsics file, overrides preset/hfov/fx.. when given
  std::string camera_preset = "pal";   ///< pal | hd | uhd
  double camera_hfov_deg = 60.0;
  int landmark_count = 0;              ///< landmarks placed along the trajectory
  double landmark_size_m = 0.3;
  double landmark_lateral_offset_m = 0.6;
  std::string image_storage = "raw";   ///< raw | jpeg | png
  int jpeg_quality = 90;
  bool compress_chunks = false;
};

/**
 * @brief Parses a YAML description (text), applying `overrides` ("section.key=value", YAML values) first.
 * Throws std::invalid_argument naming the key, its value and the allowed range or values. Relative file paths are
 * resolved against `base_dir`. Landmarks and the geo-reference are resolved (so the result is ready to run).
 */
DiveDescription parseDiveDescription(const std::string& yaml_text, const std::vector<std::string>& overrides,
                                     const std::string& base_dir);

/// Reads a YAML file and parses it as above (errors name the file).
DiveDescription loadDiveDescription(const std::string& path, const std::vector<std::string>& overrides);

/// The complete description as YAML (every key, defaults included): written beside each bag.
std::string toYaml(const DiveDescription& dive);

/// Texture and relief for a seabed spec (procedural from the dive's seed, or the user's image).
struct Seabed {
  std::unique_ptr<SeabedTexture> texture;
  std::unique_ptr<SeabedRelief> relief;
};
Seabed makeSeabed(const SeabedSpec& spec, uint64_t seed);

}  // namespace sim
}  // namespace exocet_mosaic
