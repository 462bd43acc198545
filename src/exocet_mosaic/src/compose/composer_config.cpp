#include "exocet_mosaic/compose/composer_config.h"

#include <sstream>
#include <vector>

namespace exocet_mosaic {
namespace compose {

std::string ComposerConfig::validate() const {
  std::vector<std::string> bad;
  auto check = [&bad](bool ok, const std::string& name, const std::string& range, double value) {
    if (ok) return;
    std::ostringstream s;
    s << name << " must be " << range << ", got " << value;
    bad.push_back(s.str());
  };
  check(frames_per_mosaic >= 2 && frames_per_mosaic <= 100000, "frames_per_mosaic", "in [2, 100000]",
        frames_per_mosaic);
  check(gsd_m == 0.0 || (gsd_m >= 1e-4 && gsd_m <= 100.0), "gsd_m", "0 (native, rounded) or in [1e-4, 100]", gsd_m);
  check(max_extent_m >= 0.1 && max_extent_m <= 100000.0, "max_extent_m", "in [0.1, 100000]", max_extent_m);
  check(max_memory_mb >= 1.0 && max_memory_mb <= 1e6, "max_memory_mb", "in [1, 1000000]", max_memory_mb);
  check(navigation_jump_sigma >= 1.0 && navigation_jump_sigma <= 1000.0, "navigation_jump_sigma", "in [1, 1000]",
        navigation_jump_sigma);
  check(navigation_jump_min_m >= 0.0 && navigation_jump_min_m <= 100000.0, "navigation_jump_min_m", "in [0, 100000]",
        navigation_jump_min_m);
  check(navigation_jump_confirm_frames >= 1 && navigation_jump_confirm_frames <= 1000, "navigation_jump_confirm_frames",
        "in [1, 1000]", navigation_jump_confirm_frames);
  if (blend != "feather" && blend != "multiband" && blend != "none")
    bad.push_back("blend must be \"feather\", \"multiband\" or \"none\", got \"" + blend + "\"");
  check(feather_power >= 0.1 && feather_power <= 10.0, "feather_power", "in [0.1, 10]", feather_power);
  check(multiband_bands >= 1 && multiband_bands <= 10, "multiband_bands", "in [1, 10]", multiband_bands);
  check(min_key_frame_shift_fraction >= 0.0 && min_key_frame_shift_fraction <= 1.0, "min_key_frame_shift_fraction",
        "in [0, 1]", min_key_frame_shift_fraction);
  if (max_image_reduction != 1 && max_image_reduction != 2 && max_image_reduction != 4 && max_image_reduction != 8)
    bad.push_back("max_image_reduction must be 1, 2, 4 or 8, got " + std::to_string(max_image_reduction));
  if (anchor != "similarity" && anchor != "translation")
    bad.push_back("anchor must be \"similarity\" or \"translation\", got \"" + anchor + "\"");
  check(anchor_prior_sigma >= 1e-6 && anchor_prior_sigma <= 10.0, "anchor_prior_sigma", "in [1e-6, 10]",
        anchor_prior_sigma);
  check(tile_continuity_sigma_m >= 0.0 && tile_continuity_sigma_m <= 1000.0, "tile_continuity_sigma_m", "in [0, 1000]",
        tile_continuity_sigma_m);
  check(navigation_samples_per_mosaic >= 1.0 && navigation_samples_per_mosaic <= 10000.0,
        "navigation_samples_per_mosaic", "in [1, 10000]", navigation_samples_per_mosaic);
  check(resample_threshold_px >= 0.0 && resample_threshold_px <= 1000.0, "resample_threshold_px", "in [0, 1000]",
        resample_threshold_px);
  check(block_size_px >= 16 && block_size_px <= 4096, "block_size_px", "in [16, 4096]", block_size_px);
  const std::string lighting_error = lighting.validate();
  if (!lighting_error.empty()) bad.push_back(lighting_error);
  std::string joined;
  for (const auto& b : bad) joined += (joined.empty() ? "" : "; ") + b;
  return joined;
}

}  // namespace compose
}  // namespace exocet_mosaic
