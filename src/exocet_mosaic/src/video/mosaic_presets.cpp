#include "exocet_mosaic/video/mosaic_presets.h"

#include <cstdlib>
#include <filesystem>
#include <functional>
#include <map>
#include <set>
#include <stdexcept>

#include <yaml-cpp/yaml.h>

namespace exocet_mosaic {
namespace video {
namespace {

/// A flat view of a preset: "section/key" -> scalar node; nested maps are flattened with '/'.
void flatten(const YAML::Node& node, const std::string& prefix, std::map<std::string, YAML::Node>* out) {
  for (const auto& kv : node) {
    const std::string key = prefix + kv.first.as<std::string>();
    if (kv.second.IsMap())
      flatten(kv.second, key + "/", out);
    else
      (*out)[key] = kv.second;
  }
}

/// Binds keys to fields and applies a preset's values to them, naming the file and key on any problem.
class KeyBinder {
 public:
  explicit KeyBinder(std::string path) : path_(std::move(path)) {}

  void number(const std::string& key, double* v) {
    setters_[key] = [this, key, v](const YAML::Node& n) { *v = as<double>(key, n, "a number"); };
  }
  void integer(const std::string& key, int* v) {
    setters_[key] = [this, key, v](const YAML::Node& n) { *v = as<int>(key, n, "an integer"); };
  }
  void flag(const std::string& key, bool* v) {
    setters_[key] = [this, key, v](const YAML::Node& n) { *v = as<bool>(key, n, "true or false"); };
  }
  void text(const std::string& key, std::string* v) {
    setters_[key] = [this, key, v](const YAML::Node& n) { *v = as<std::string>(key, n, "a string"); };
  }
  /// Keys the nodes read that mean nothing without ROS (topics, diagnostics): accepted, not used.
  void ignored(const std::string& key) {
    setters_[key] = [](const YAML::Node&) {};
  }

  void apply() {
    YAML::Node root;
    try {
      root = YAML::LoadFile(path_);
    } catch (const YAML::Exception& e) {
      throw std::invalid_argument("preset " + path_ + ": cannot read it: " + e.what());
    }
    if (root.IsNull()) return;
    if (!root.IsMap()) throw std::invalid_argument("preset " + path_ + ": not a YAML mapping");
    std::map<std::string, YAML::Node> values;
    flatten(root, "", &values);
    for (const auto& [key, node] : values) {
      const auto setter = setters_.find(key);
      if (setter == setters_.end()) throw std::invalid_argument("preset " + path_ + ": unknown key '" + key + "'");
      setter->second(node);
    }
  }

  [[noreturn]] void fail(const std::string& what) const {
    throw std::invalid_argument("preset " + path_ + ": " + what);
  }

 private:
  template <typename T>
  T as(const std::string& key, const YAML::Node& n, const char* expected) const {
    try {
      return n.as<T>();
    } catch (const YAML::Exception&) {
      fail("key '" + key + "' must be " + expected);
    }
  }

  std::string path_;
  std::map<std::string, std::function<void(const YAML::Node&)>> setters_;
};

void bindKlt(KeyBinder* b, registration::KltConfig* c) {
  b->integer("klt/max_features", &c->max_features);
  b->integer("klt/grid_cols", &c->grid_cols);
  b->integer("klt/grid_rows", &c->grid_rows);
  b->number("klt/min_distance_px", &c->min_distance_px);
  b->number("klt/quality_level", &c->quality_level);
  b->number("klt/min_eigenvalue", &c->min_eigenvalue);
  b->integer("klt/block_size", &c->block_size);
  b->integer("klt/detection_max_width_px", &c->detection_max_width_px);
  b->integer("klt/min_features", &c->min_features);
  b->number("klt/redetect_fraction", &c->redetect_fraction);
  b->integer("klt/window_px", &c->window_px);
  b->integer("klt/pyramid_levels", &c->pyramid_levels);
  b->integer("klt/lk_max_iterations", &c->lk_max_iterations);
  b->number("klt/lk_epsilon_px", &c->lk_epsilon_px);
  b->number("klt/fb_threshold_px", &c->fb_threshold_px);
  b->integer("klt/predicted_pyramid_levels", &c->predicted_pyramid_levels);
  b->integer("klt/prediction_probes", &c->prediction_probes);
  b->number("klt/prediction_tolerance_px", &c->prediction_tolerance_px);
  b->number("klt/retrack_fraction", &c->retrack_fraction);
  b->number("klt/fb_fine_start_px", &c->fb_fine_start_px);
  b->integer("klt/min_tracks", &c->min_tracks);
  b->integer("klt/min_inliers", &c->min_inliers);
  b->number("klt/min_inlier_fraction", &c->min_inlier_fraction);
  b->number("klt/rejection_k", &c->rejection_k);
  b->number("klt/min_residual_scale_px", &c->min_residual_scale_px);
  b->number("klt/max_residual_px", &c->max_residual_px);
  b->number("klt/max_motion_fraction", &c->max_motion_fraction);
  b->number("klt/min_mean_grey", &c->min_mean_grey);
  b->number("klt/min_contrast_grey", &c->min_contrast_grey);
  b->flag("klt/derivatives_on_demand", &c->derivatives_on_demand);
  b->number("klt/consensus_threshold_px", &c->consensus_threshold_px);
  b->number("klt/max_local_residual_px", &c->max_local_residual_px);
  b->number("klt/covariance_inflation", &c->covariance_inflation);
  b->number("klt/rigid_k_sigma", &c->rigid_k_sigma);
  b->flag("klt/coarse_search", &c->coarse_search);
  b->integer("klt/coarse_width_px", &c->coarse.width_px);
  b->integer("klt/coarse_min_inliers", &c->coarse.min_inliers);
}

void bindRmr(KeyBinder* b, registration::RmrConfig* c) {
  b->integer("rmr/pyramid_levels", &c->pyramid_levels);
  b->integer("rmr/min_level_size_px", &c->min_level_size_px);
  b->integer("rmr/finest_level", &c->finest_level);
  b->integer("rmr/max_iterations_per_level", &c->max_iterations_per_level);
  b->number("rmr/convergence_px", &c->convergence_px);
  b->number("rmr/coarse_convergence_px", &c->coarse_convergence_px);
  b->number("rmr/max_step_px", &c->max_step_px);
  b->number("rmr/tukey_constant", &c->tukey_constant);
  b->number("rmr/min_residual_scale", &c->min_residual_scale);
  b->number("rmr/smoothing_sigma_px", &c->smoothing_sigma_px);
  b->number("rmr/min_gradient", &c->min_gradient);
  b->number("rmr/pixel_fraction", &c->pixel_fraction);
  b->integer("rmr/min_pixels_per_level", &c->min_pixels_per_level);
  b->integer("rmr/max_pixels_per_level", &c->max_pixels_per_level);
  b->flag("rmr/estimate_illumination", &c->estimate_illumination);
  b->number("rmr/min_gain", &c->min_gain);
  b->number("rmr/max_gain", &c->max_gain);
  b->number("rmr/min_mean_intensity", &c->min_mean_intensity);
  b->number("rmr/min_intensity_stddev", &c->min_intensity_stddev);
  b->integer("rmr/min_textured_pixels", &c->min_textured_pixels);
  b->number("rmr/not_converged_px", &c->not_converged_px);
  b->number("rmr/max_shift_fraction", &c->max_shift_fraction);
  b->number("rmr/max_scale_change", &c->max_scale_change);
  b->number("rmr/min_inlier_fraction", &c->min_inlier_fraction);
  b->integer("rmr/min_inliers", &c->min_inliers);
  b->number("rmr/max_residual_scale", &c->max_residual_scale);
  b->number("rmr/min_correlation", &c->min_correlation);
  b->number("rmr/covariance_inflation", &c->covariance_inflation);
}

void bindIllumination(KeyBinder* b, registration::IlluminationNormalizerConfig* c) {
  b->flag("illumination/enabled", &c->enabled);
  b->integer("illumination/level", &c->level);
  b->number("illumination/sigma_level_px", &c->sigma_level_px);
  b->number("illumination/min_contrast_grey", &c->min_contrast_grey);
  b->number("illumination/output_gain", &c->output_gain);
  b->number("illumination/min_mean_grey", &c->min_mean_grey);
  b->number("illumination/min_stddev_grey", &c->min_stddev_grey);
}

}  // namespace

RegistrationPreset loadRegistrationPreset(const std::string& path) {
  RegistrationPreset preset;
  KeyBinder b(path);
  std::string method = registration::toString(preset.registration.method);
  std::string model = registration::toString(preset.registration.model);
  b.text("method", &method);
  b.text("model", &model);
  b.number("max_gap_s", &preset.sequence.max_gap_s);
  b.flag("undistort", &preset.sequence.undistort);
  for (const char* key : {"expected_rate_hz", "queue_size", "quality_window", "warn_failure_fraction", "transport",
                          "image_topic", "camera_info_topic", "motion_topic"})
    b.ignored(key);
  bindKlt(&b, &preset.registration.klt);
  bindRmr(&b, &preset.registration.rmr);
  bindIllumination(&b, &preset.registration.illumination);
  b.apply();
  try {
    preset.registration.method = registration::registrationMethodFromString(method);
    preset.registration.model = registration::motionModelFromString(model);
  } catch (const std::invalid_argument& e) {
    b.fail(e.what());
  }
  std::string error = preset.registration.validate();
  if (error.empty()) error = preset.sequence.validate();
  if (!error.empty()) b.fail(error);
  return preset;
}

TilesPreset loadTilesPreset(const std::string& path) {
  TilesPreset preset;
  compose::ComposerConfig& c = preset.composer;
  tiles::TileWriterConfig& f = preset.files;
  KeyBinder b(path);
  b.integer("frames_per_mosaic", &c.frames_per_mosaic);
  b.number("gsd_m", &c.gsd_m);
  b.number("max_extent_m", &c.max_extent_m);
  b.number("max_memory_mb", &c.max_memory_mb);
  b.number("navigation_jump_sigma", &c.navigation_jump_sigma);
  b.number("navigation_jump_min_m", &c.navigation_jump_min_m);
  b.integer("navigation_jump_confirm_frames", &c.navigation_jump_confirm_frames);
  b.text("blend", &c.blend);
  b.number("feather_power", &c.feather_power);
  b.integer("multiband_bands", &c.multiband_bands);
  b.number("min_key_frame_shift_fraction", &c.min_key_frame_shift_fraction);
  b.text("anchor", &c.anchor);
  b.number("tile_continuity_sigma_m", &c.tile_continuity_sigma_m);
  b.number("navigation_samples_per_mosaic", &c.navigation_samples_per_mosaic);
  b.flag("lighting/enabled", &c.lighting.enabled);
  b.integer("lighting/warmup_frames", &c.lighting.warmup_frames);
  b.integer("lighting/memory_frames", &c.lighting.memory_frames);
  b.number("lighting/max_gain", &c.lighting.max_gain);
  b.text("prefix", &f.prefix);
  b.text("compression", &f.compression);
  b.integer("block_size_px", &f.block_size_px);
  b.flag("write_world_file", &f.write_world_file);
  b.flag("write_cog", &f.write_cog);
  b.flag("write_kmz", &f.write_kmz);
  b.integer("kmz_max_side_px", &f.kmz_max_side_px);
  for (const char* key :
       {"preview_period_s", "preview_max_side_px", "queue_size", "sync_timeout_s", "max_pending_frames", "clock_jump_s",
        "exit_when_idle_s", "max_failed_tiles_kept", "retry_period_s", "resume_max_gap_s", "progress_period_s",
        "utm_zone", "northern_hemisphere", "undistort", "transport", "image_topic", "camera_info_topic",
        "motion_topic", "odometry_topic", "camera_height_topic", "datum_topic", "tile_topic", "preview_topic",
        "footprints_topic", "frame_id", "map_frame", "dive_name", "udp_host", "udp_port"})
    b.ignored(key);
  b.apply();
  const std::string error = c.validate();
  if (!error.empty()) b.fail(error);
  tiles::TileWriterConfig check = f;
  check.output_dir = ".";  // the caller's folder; only the other fields are checked here
  const std::string files_error = check.validate();
  if (!files_error.empty()) b.fail(files_error);
  return preset;
}

std::string presetPath(const std::string& kind, const std::string& name_or_path) {
  namespace fs = std::filesystem;
  const bool is_file = name_or_path.size() > 5 && name_or_path.substr(name_or_path.size() - 5) == ".yaml";
  std::string path = name_or_path;
  if (!is_file) {
    const char* dir = std::getenv("EXOCET_CONFIG_DIR");
    if (dir == nullptr || *dir == '\0')
      throw std::invalid_argument(kind + " preset '" + name_or_path +
                                  "': EXOCET_CONFIG_DIR is not set (source the workspace's devel/setup.bash) or give "
                                  "a .yaml path");
    path = std::string(dir) + "/" + kind + "/" + name_or_path + ".yaml";
  }
  if (!fs::is_regular_file(path)) throw std::invalid_argument(kind + " preset '" + path + "' does not exist");
  return path;
}

}  // namespace video
}  // namespace exocet_mosaic
