/**
 * @file synthetic_dive_bag.h
 * @brief A simulated dive rendered into a bag and its companion files: the work of the dive_synth tool, callable
 * from tests and benchmarks.
 */
#pragma once

#include <cstddef>
#include <functional>
#include <string>

#include "exocet_mosaic/sim/dive_description.h"

namespace exocet_mosaic {

/// What writeSyntheticDive() wrote.
struct SyntheticDiveSummary {
  int frames = 0;           ///< camera frames of the dive, dropped ones included
  double duration_s = 0.0;  ///< dive time covered
  size_t messages = 0;      ///< messages in the bag
  int epsg = 0;             ///< EPSG code of the UTM zone of the positions
};

/**
 * @brief Renders `dive` into `output_bag` (OUT.bag: camera images and camera_info, the navigation sensors under
 * /nav, the datum, /tf_static, the ground truth topics) and writes beside it OUT.ground_truth.csv (one row per
 * camera frame), OUT.landmarks.csv (the surveyed targets) and OUT.config.yaml (the complete description). Each
 * file is written under a temporary name and renamed when complete. The same description gives the same bytes, whatever
 * dive.synthesis.threads is.
 *
 * @param progress called on the calling thread after each frame (may be empty); an exception it throws abandons
 *        the dive and leaves nothing under the output names.
 * @throws std::invalid_argument for a bad description or output name (the message names it), std::runtime_error
 *         when a file cannot be written.
 */
SyntheticDiveSummary writeSyntheticDive(const sim::DiveDescription& dive, const std::string& output_bag,
                                        const std::function<void(int frames_done, int frames_total)>& progress);

}  // namespace exocet_mosaic
