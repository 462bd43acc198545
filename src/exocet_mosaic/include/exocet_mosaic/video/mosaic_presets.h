/**
 * @file mosaic_presets.h
 * @brief The live chain's presets (config/registration/<name>.yaml, config/tiles/<name>.yaml) read without ROS, with
 * the same keys and checks as registration_node and tile_writer_node read them from the parameter server, so that a
 * tool running the chain in one process configures it as the launch files do. No ROS in it.
 */
#pragma once

#include <string>

#include "exocet_mosaic/compose/composer_config.h"
#include "exocet_mosaic/registration/registration_config.h"
#include "exocet_mosaic/registration/sequence_registrar.h"
#include "exocet_mosaic/tiles/geotiff_tile_writer.h"

namespace exocet_mosaic {
namespace video {

/// What a registration preset configures.
struct RegistrationPreset {
  registration::RegistrationConfig registration;
  registration::SequenceRegistrarConfig sequence;
};

/// What a tiles preset configures (the output folder is left empty: the caller sets it).
struct TilesPreset {
  compose::ComposerConfig composer;
  tiles::TileWriterConfig files;
};

/**
 * @brief Reads a registration preset (keys of config/registration/README.md: method, model, max_gap_s, klt/...,
 * rmr/..., illumination/...; the ROS-only keys such as expected_rate_hz are accepted and ignored).
 * @throws std::invalid_argument naming the file and the key: unreadable file, unknown key, wrong type, value out of
 *         range (the configs' validate()).
 */
RegistrationPreset loadRegistrationPreset(const std::string& path);

/// Reads a tiles preset (keys of config/tiles/README.md; ROS-only keys accepted and ignored). Throws as above.
TilesPreset loadTilesPreset(const std::string& path);

/**
 * @brief The file of a preset: `name_or_path` itself when it names a .yaml file, else
 * `<config_dir>/<kind>/<name>.yaml` (config_dir: $EXOCET_CONFIG_DIR).
 * @throws std::invalid_argument when the file does not exist or $EXOCET_CONFIG_DIR is unset for a name.
 */
std::string presetPath(const std::string& kind, const std::string& name_or_path);

}  // namespace video
}  // namespace exocet_mosaic
