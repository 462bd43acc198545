#include "exocet_mosaic/ros/registration_parameters.h"

#include <limits>
#include <stdexcept>

#include "exocet_common/ros/parameter_reader.h"

namespace exocet_mosaic {
namespace {

constexpr double kAny = std::numeric_limits<double>::max();
constexpr int kAnyInt = std::numeric_limits<int>::max();

// Types are checked here; ranges by the configs' validate(), which names each field's allowed range.
struct SectionReader {
  const exocet_common::ParameterReader& reader;
  std::string section;
  void number(const std::string& field, double* v) const {
    reader.readDouble(section + "/" + field, v, -kAny, kAny, "see " + section + " in config/registration/README.md");
  }
  void integer(const std::string& field, int* v) const {
    reader.readInt(section + "/" + field, v, -kAnyInt, kAnyInt, "see " + section + " in config/registration/README.md");
  }
  void flag(const std::string& field, bool* v) const {
    reader.readBool(section + "/" + field, v, "see " + section + " in config/registration/README.md");
  }
};

void readKlt(const SectionReader& s, registration::KltConfig* c) {
  s.integer("max_features", &c->max_features);
  s.integer("grid_cols", &c->grid_cols);
  s.integer("grid_rows", &c->grid_rows);
  s.number("min_distance_px", &c->min_distance_px);
  s.number("quality_level", &c->quality_level);
  s.number("min_eigenvalue", &c->min_eigenvalue);
  s.integer("block_size", &c->block_size);
  s.integer("detection_max_width_px", &c->detection_max_width_px);
  s.integer("min_features", &c->min_features);
  s.number("redetect_fraction", &c->redetect_fraction);
  s.integer("window_px", &c->window_px);
  s.integer("pyramid_levels", &c->pyramid_levels);
  s.integer("lk_max_iterations", &c->lk_max_iterations);
  s.number("lk_epsilon_px", &c->lk_epsilon_px);
  s.number("fb_threshold_px", &c->fb_threshold_px);
  s.integer("predicted_pyramid_levels", &c->predicted_pyramid_levels);
  s.integer("prediction_probes", &c->prediction_probes);
  s.number("prediction_tolerance_px", &c->prediction_tolerance_px);
  s.number("retrack_fraction", &c->retrack_fraction);
  s.number("fb_fine_start_px", &c->fb_fine_start_px);
  s.integer("min_tracks", &c->min_tracks);
  s.integer("min_inliers", &c->min_inliers);
  s.number("min_inlier_fraction", &c->min_inlier_fraction);
  s.number("rejection_k", &c->rejection_k);
  s.number("min_residual_scale_px", &c->min_residual_scale_px);
  s.number("max_residual_px", &c->max_residual_px);
  s.number("max_motion_fraction", &c->max_motion_fraction);
  s.number("min_mean_grey", &c->min_mean_grey);
  s.number("min_contrast_grey", &c->min_contrast_grey);
  s.flag("derivatives_on_demand", &c->derivatives_on_demand);
  s.number("consensus_threshold_px", &c->consensus_threshold_px);
  s.number("max_local_residual_px", &c->max_local_residual_px);
  s.number("covariance_inflation", &c->covariance_inflation);
  s.number("rigid_k_sigma", &c->rigid_k_sigma);
  s.flag("coarse_search", &c->coarse_search);
  s.integer("coarse_width_px", &c->coarse.width_px);
  s.integer("coarse_min_inliers", &c->coarse.min_inliers);
}

void readIllumination(const SectionReader& s, registration::IlluminationNormalizerConfig* c) {
  s.flag("enabled", &c->enabled);
  s.integer("level", &c->level);
  s.number("sigma_level_px", &c->sigma_level_px);
  s.number("min_contrast_grey", &c->min_contrast_grey);
  s.number("output_gain", &c->output_gain);
  s.number("min_mean_grey", &c->min_mean_grey);
  s.number("min_stddev_grey", &c->min_stddev_grey);
}

void readRmr(const SectionReader& s, registration::RmrConfig* c) {
  s.integer("pyramid_levels", &c->pyramid_levels);
  s.integer("min_level_size_px", &c->min_level_size_px);
  s.integer("finest_level", &c->finest_level);
  s.integer("max_iterations_per_level", &c->max_iterations_per_level);
  s.number("convergence_px", &c->convergence_px);
  s.number("coarse_convergence_px", &c->coarse_convergence_px);
  s.number("max_step_px", &c->max_step_px);
  s.number("tukey_constant", &c->tukey_constant);
  s.number("min_residual_scale", &c->min_residual_scale);
  s.number("smoothing_sigma_px", &c->smoothing_sigma_px);
  s.number("min_gradient", &c->min_gradient);
  s.number("pixel_fraction", &c->pixel_fraction);
  s.integer("min_pixels_per_level", &c->min_pixels_per_level);
  s.integer("max_pixels_per_level", &c->max_pixels_per_level);
  s.flag("estimate_illumination", &c->estimate_illumination);
  s.number("min_gain", &c->min_gain);
  s.number("max_gain", &c->max_gain);
  s.number("min_mean_intensity", &c->min_mean_intensity);
  s.number("min_intensity_stddev", &c->min_intensity_stddev);
  s.integer("min_textured_pixels", &c->min_textured_pixels);
  s.number("not_converged_px", &c->not_converged_px);
  s.number("max_shift_fraction", &c->max_shift_fraction);
  s.number("max_scale_change", &c->max_scale_change);
  s.number("min_inlier_fraction", &c->min_inlier_fraction);
  s.integer("min_inliers", &c->min_inliers);
  s.number("max_residual_scale", &c->max_residual_scale);
  s.number("min_correlation", &c->min_correlation);
  s.number("covariance_inflation", &c->covariance_inflation);
}

}  // namespace

registration::RegistrationConfig readRegistrationConfig(const ros::NodeHandle& private_nh) {
  namespace reg = registration;
  const exocet_common::ParameterReader reader(private_nh);
  reg::RegistrationConfig config;
  std::string method = reg::toString(config.method), model = reg::toString(config.model);
  reader.readString("method", &method, {"klt", "rmr", "auto"},
                    "registration method (auto: KLT, and RMR on the pairs where KLT fails)");
  reader.readString("model", &model, {"translation", "similarity", "affine", "homography"}, "2D motion model");
  config.method = reg::registrationMethodFromString(method);
  config.model = reg::motionModelFromString(model);
  readKlt(SectionReader{reader, "klt"}, &config.klt);
  readRmr(SectionReader{reader, "rmr"}, &config.rmr);
  readIllumination(SectionReader{reader, "illumination"}, &config.illumination);
  const std::string error = config.validate();
  if (!error.empty())
    throw std::invalid_argument("registration parameters (~klt/..., ~rmr/..., ~illumination/...): " + error);
  return config;
}

}  // namespace exocet_mosaic
