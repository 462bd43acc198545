#include "exocet_mosaic/registration/rmr_registrar.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>

#include <Eigen/Dense>

#include "rmr_frame.h"
#include "rmr_level_solver.h"

namespace exocet_mosaic {
namespace registration {

namespace {

constexpr int kMinImageSide = 16;
constexpr int kMaxImageSide = 32767;  // the pixel selection packs (row, column) in one int

double nowMs() {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

std::string str(double value) {
  std::ostringstream s;
  s.precision(4);
  s << value;
  return s.str();
}

// Centred matrix of level 0 expressed at `level` (coordinates divided by 2^level), and back.
Eigen::Matrix3d toLevel(Eigen::Matrix3d m, int level) {
  const double s = std::ldexp(1.0, -level);
  m(0, 2) *= s;
  m(1, 2) *= s;
  m(2, 0) /= s;
  m(2, 1) /= s;
  return m;
}
Eigen::Matrix3d toLevelZero(const Eigen::Matrix3d& m, int level) { return toLevel(m, -level); }

bool usableImage(const cv::Mat& image) {
  return !image.empty() && image.type() == CV_8UC1 && image.cols >= kMinImageSide && image.rows >= kMinImageSide &&
         image.cols <= kMaxImageSide && image.rows <= kMaxImageSide;
}

std::string describeImage(const cv::Mat& image) {
  if (image.empty()) return "an empty image";
  return "a " + std::to_string(image.cols) + "x" + std::to_string(image.rows) + " image of type " +
         std::to_string(image.type()) + " (need CV_8UC1, " + std::to_string(kMinImageSide) + " to " +
         std::to_string(kMaxImageSide) + " px a side)";
}

MotionEstimate& fail(MotionEstimate& estimate, FailureReason reason, const std::string& detail) {
  estimate.failed = true;
  estimate.failure = reason;
  estimate.failure_detail = detail;
  return estimate;
}

}  // namespace

std::string RmrConfig::validate() const {
  std::ostringstream err;
  const auto range = [&err](const char* name, double v, double lo, double hi) {
    if (!(v >= lo && v <= hi)) err << "rmr." << name << " " << v << " out of range [" << lo << ", " << hi << "]; ";
  };
  const auto open_low = [&err](const char* name, double v, double lo, double hi) {
    if (!(v > lo && v <= hi)) err << "rmr." << name << " " << v << " out of range (" << lo << ", " << hi << "]; ";
  };
  range("pyramid_levels", pyramid_levels, 1, 10);
  range("min_level_size_px", min_level_size_px, 8, 1024);
  range("finest_level", finest_level, 0, std::max(0, pyramid_levels - 1));
  range("max_iterations_per_level", max_iterations_per_level, 1, 200);
  open_low("convergence_px", convergence_px, 0.0, 1.0);
  open_low("coarse_convergence_px", coarse_convergence_px, 0.0, 1.0);
  open_low("max_step_px", max_step_px, 0.0, 100.0);
  range("tukey_constant", tukey_constant, 1.0, 20.0);
  range("min_residual_scale", min_residual_scale, 0.01, 50.0);
  range("smoothing_sigma_px", smoothing_sigma_px, 0.0, 3.0);
  range("min_gradient", min_gradient, 0.0, 255.0);
  open_low("pixel_fraction", pixel_fraction, 0.0, 1.0);
  range("min_pixels_per_level", min_pixels_per_level, 0, 1e7);
  range("max_pixels_per_level", max_pixels_per_level, 100, 1e7);
  open_low("min_gain", min_gain, 0.0, 1.0);
  range("max_gain", max_gain, 1.0, 100.0);
  range("min_mean_intensity", min_mean_intensity, 0.0, 255.0);
  range("min_intensity_stddev", min_intensity_stddev, 0.0, 128.0);
  range("min_textured_pixels", min_textured_pixels, 10, 1e7);
  open_low("not_converged_px", not_converged_px, 0.0, 100.0);
  open_low("max_shift_fraction", max_shift_fraction, 0.0, 10.0);
  open_low("max_scale_change", max_scale_change, 0.0, 10.0);
  range("min_inlier_fraction", min_inlier_fraction, 0.0, 1.0);
  range("min_inliers", min_inliers, 0, 1e7);
  open_low("max_residual_scale", max_residual_scale, 0.0, 255.0);
  range("min_correlation", min_correlation, -1.0, 1.0);
  range("covariance_inflation", covariance_inflation, 0.01, 100.0);
  std::string s = err.str();
  if (s.size() >= 2) s.resize(s.size() - 2);
  return s;
}

RmrRegistrar::RmrRegistrar(const RmrConfig& config)
    : config_(config), solver_(std::make_unique<internal::RmrLevelSolver>()) {
  const std::string problem = config_.validate();
  if (!problem.empty()) throw std::invalid_argument("RmrConfig: " + problem);
}

RmrRegistrar::~RmrRegistrar() = default;

void RmrRegistrar::reset() { recycle(std::move(previous_)); }

void RmrRegistrar::recycle(std::unique_ptr<internal::RmrFrame> frame) {
  if (frame && spare_frames_.size() < 2) spare_frames_.push_back(std::move(frame));
}

int RmrRegistrar::levelCount(cv::Size size) const {
  int levels = 1;
  int w = size.width, h = size.height;
  while (levels < config_.pyramid_levels) {
    w = (w + 1) / 2;
    h = (h + 1) / 2;
    if (std::min(w, h) < config_.min_level_size_px) break;
    ++levels;
  }
  return levels;
}

std::unique_ptr<internal::RmrFrame> RmrRegistrar::prepare(const cv::Mat& gray) {
  internal::RmrSelectionParameters selection;
  selection.model = config_.model;
  selection.min_gradient = config_.min_gradient;
  selection.pixel_fraction = config_.pixel_fraction;
  selection.min_pixels = config_.min_pixels_per_level;
  selection.max_pixels = config_.max_pixels_per_level;
  const int levels = levelCount(gray.size());
  selection.finest_level = std::min(config_.finest_level, levels - 1);
  selection.smoothing_sigma_px = config_.smoothing_sigma_px;
  std::unique_ptr<internal::RmrFrame> recycled;
  if (!spare_frames_.empty()) {
    recycled = std::move(spare_frames_.back());
    spare_frames_.pop_back();
  }
  return std::make_unique<internal::RmrFrame>(gray, levels, selection, std::move(recycled));
}

MotionEstimate RmrRegistrar::registerNext(const cv::Mat& gray, const Eigen::Matrix3d& prediction_px) {
  const double start_ms = nowMs();
  MotionEstimate estimate;
  estimate.method = RegistrationMethod::kRmr;
  estimate.model = config_.model;
  estimate.parameters = Eigen::VectorXd::Zero(parameterCount(config_.model));
  if (!usableImage(gray)) {
    recycle(std::move(previous_));
    fail(estimate, FailureReason::kInvalidInput, "got " + describeImage(gray));
    estimate.elapsed_ms = nowMs() - start_ms;
    return estimate;
  }
  estimate.centre_px = Eigen::Vector2d(0.5 * (gray.cols - 1), 0.5 * (gray.rows - 1));
  std::unique_ptr<internal::RmrFrame> previous = std::move(previous_);
  previous_ = prepare(gray);
  if (!previous) {
    fail(estimate, FailureReason::kNoPreviousFrame, "first image after a reset");
  } else if (previous->size() != previous_->size()) {
    fail(estimate, FailureReason::kInvalidInput,
         "image size changed from " + std::to_string(previous->size().width) + "x" +
             std::to_string(previous->size().height) + " to " + std::to_string(gray.cols) + "x" +
             std::to_string(gray.rows));
    previous.reset();  // buffers of the wrong size: not worth recycling
  } else {
    estimate = this->estimate(previous.get(), *previous_, prediction_px, start_ms);
  }
  recycle(std::move(previous));
  estimate.elapsed_ms = nowMs() - start_ms;
  return estimate;
}

MotionEstimate RmrRegistrar::registerPair(const cv::Mat& previous, const cv::Mat& current,
                                          const Eigen::Matrix3d& prediction_px) {
  const double start_ms = nowMs();
  MotionEstimate estimate;
  estimate.method = RegistrationMethod::kRmr;
  estimate.model = config_.model;
  estimate.parameters = Eigen::VectorXd::Zero(parameterCount(config_.model));
  if (!usableImage(previous) || !usableImage(current) || previous.size() != current.size()) {
    fail(estimate, FailureReason::kInvalidInput,
         "got " + describeImage(previous) + " and " + describeImage(current) + " (need the same size)");
    estimate.elapsed_ms = nowMs() - start_ms;
    return estimate;
  }
  std::unique_ptr<internal::RmrFrame> a = prepare(previous);
  std::unique_ptr<internal::RmrFrame> b = prepare(current);
  estimate = this->estimate(a.get(), *b, prediction_px, start_ms);
  recycle(std::move(a));
  recycle(std::move(b));
  estimate.elapsed_ms = nowMs() - start_ms;
  return estimate;
}

MotionEstimate RmrRegistrar::estimate(internal::RmrFrame* a, const internal::RmrFrame& b,
                                      const Eigen::Matrix3d& prediction_px, double start_ms) {
  const MotionModel model = config_.model;
  const int ng = parameterCount(model);
  const cv::Size size = a->size();
  const Eigen::Vector2d centre = a->centre(0);
  MotionEstimate est;
  est.method = RegistrationMethod::kRmr;
  est.model = model;
  est.centre_px = centre;
  est.parameters = Eigen::VectorXd::Zero(ng);
  const auto finish = [&est, start_ms](FailureReason reason, const std::string& detail) {
    if (reason != FailureReason::kNone) {
      fail(est, reason, detail);
    } else {
      est.failed = false;
      est.failure = FailureReason::kNone;
      est.failure_detail.clear();
    }
    est.elapsed_ms = nowMs() - start_ms;
    return est;
  };

  // Starting point (also the parameters reported by the failures found before the estimation).
  if (!prediction_px.allFinite() || std::abs(prediction_px(2, 2)) < 1e-12)
    return finish(FailureReason::kInvalidInput, "the prediction is not a finite, normalisable pixel matrix");
  const Eigen::VectorXd predicted =
      parametersFromPixelMatrix(model, prediction_px / prediction_px(2, 2), centre, size.width, size.height);
  if (!predicted.allFinite())
    return finish(FailureReason::kInvalidInput, "the prediction has no finite " + toString(model) + " parameters");
  est.parameters = predicted;
  est.pixel_matrix = pixelMatrix(model, est.parameters, centre);

  // Signal.
  const std::pair<const internal::RmrFrame*, const char*> frames[] = {{a, "previous"}, {&b, "current"}};
  for (const auto& [frame, name] : frames) {
    if (frame->mean() < config_.min_mean_intensity)
      return finish(FailureReason::kTooDark, std::string(name) + " image mean " + str(frame->mean()) +
                                                 " < min_mean_intensity " + str(config_.min_mean_intensity));
    if (frame->stddev() < config_.min_intensity_stddev)
      return finish(FailureReason::kTooDark, std::string(name) + " image standard deviation " + str(frame->stddev()) +
                                                 " < min_intensity_stddev " + str(config_.min_intensity_stddev));
  }

  // Texture.
  const int levels = a->levels();
  const int finest = std::min(config_.finest_level, levels - 1);
  const int min_level_pixels = 10 * (ng + (config_.estimate_illumination ? 2 : 0));
  const internal::RmrLevelSelection& finest_selection = a->selection(finest);
  if (finest_selection.textured < config_.min_textured_pixels || finest_selection.count < min_level_pixels)
    return finish(FailureReason::kTooLittleTexture,
                  std::to_string(finest_selection.textured) +
                      " pixels with |gx| + |gy| >= " + str(config_.min_gradient) + " at level " +
                      std::to_string(finest) + " < min_textured_pixels " + std::to_string(config_.min_textured_pixels));

  // Coarse to fine.
  internal::RmrState state;
  state.centred = toLevel(centredMatrix(model, est.parameters), levels - 1);
  internal::RmrSolverSettings settings;
  settings.model = model;
  settings.illumination = config_.estimate_illumination;
  settings.max_iterations = config_.max_iterations_per_level;
  settings.tukey_constant = config_.tukey_constant;
  settings.min_scale = config_.min_residual_scale;
  settings.max_step_px = config_.max_step_px;
  internal::RmrLevelResult last;
  std::string skipped;  // coarse levels whose estimate was abandoned
  for (int level = levels - 1; level >= finest; --level) {
    const internal::RmrLevelSelection& selection = a->selection(level);
    if (level > finest && selection.count < min_level_pixels) {
      state.centred = toLevel(state.centred, -1);  // too coarse to have texture: start at the next level
      continue;
    }
    const cv::Mat& target = b.level(level);
    settings.convergence_px = level == finest ? config_.convergence_px : config_.coarse_convergence_px;
    settings.min_evaluated = std::max(min_level_pixels, selection.count / 10);
    settings.divergence_px = 2.0 * config_.max_shift_fraction * std::hypot(target.cols, target.rows) + 2.0;
    // The coarsest level (when two or more are above the finest) first estimates the translation alone: on a few
    // hundred pixels of a smooth image, the other parameters are poorly determined (a rippled seabed constrains one
    // direction only) and, from a distant start, would send the iterations astray.
    internal::RmrState before = state;
    if (level == levels - 1 && level >= finest + 2 && model != MotionModel::kTranslation) {
      settings.translation_only = true;
      last = solver_->solve(selection, target, a->centre(level), settings, &state);
      est.iterations += last.iterations;
      settings.translation_only = false;
      if (last.failure == FailureReason::kNone)
        before = state;  // keep the translation if the full model fails
      else
        state = before;
    }
    last = solver_->solve(selection, target, a->centre(level), settings, &state);
    est.iterations += last.iterations;
    if (last.failure != FailureReason::kNone) {
      if (level > finest) {
        // A coarse level is only a starting point: go on from the previous one's, one level finer.
        skipped += (skipped.empty() ? "" : ", ") + std::to_string(level) + " (" + last.detail + ")";
        state = before;
        state.centred = toLevel(state.centred, -1);
        continue;
      }
      if (state.centred.allFinite()) {
        est.parameters = internal::parametersFromCentred(model, toLevelZero(state.centred, level));
        est.pixel_matrix = pixelMatrix(model, est.parameters, centre);
      }
      return finish(last.failure, "level " + std::to_string(level) + ": " + last.detail +
                                      (skipped.empty() ? "" : "; coarser levels abandoned: " + skipped));
    }
    if (level > finest) state.centred = toLevel(state.centred, -1);
  }

  // The estimate and its statistics.
  est.parameters = internal::parametersFromCentred(model, toLevelZero(state.centred, finest));
  est.pixel_matrix = pixelMatrix(model, est.parameters, centre);
  const internal::RmrFitStatistics stats = solver_->statistics(finest_selection, b.level(finest).size(), state, last);
  est.observations = stats.evaluated;
  est.inliers = stats.inliers;
  est.inlier_fraction = stats.evaluated > 0 ? double(stats.inliers) / stats.evaluated : 0.0;
  est.residual_scale = last.scale;
  est.weights = stats.weights;
  if (stats.covariance.rows() >= ng) {
    // Parameters of level `finest` to level 0: translations x 2^L, perspective terms / 2^L.
    Eigen::VectorXd to_zero = Eigen::VectorXd::Ones(ng);
    to_zero.head<2>().setConstant(std::ldexp(1.0, finest));
    if (model == MotionModel::kHomography) to_zero.tail<2>().setConstant(std::ldexp(1.0, -finest));
    est.covariance = config_.covariance_inflation * to_zero.asDiagonal() * stats.covariance.topLeftCorner(ng, ng) *
                     to_zero.asDiagonal();
  }

  // Acceptance.
  if (!last.converged && last.last_increment_px > config_.not_converged_px)
    return finish(FailureReason::kNotConverged, "last increment " + str(last.last_increment_px) + " px (level " +
                                                    std::to_string(finest) + ") > not_converged_px " +
                                                    str(config_.not_converged_px) + " after " +
                                                    std::to_string(last.iterations) + " iterations");
  const Eigen::Matrix3d centred0 = centredMatrix(model, est.parameters);
  const double diagonal = std::hypot(size.width, size.height);
  const double shift = internal::cornerShift(centred0, centre);
  if (shift > config_.max_shift_fraction * diagonal)
    return finish(FailureReason::kMotionTooLarge, "an image corner moves by " + str(shift) + " px > " +
                                                      str(config_.max_shift_fraction) + " of the diagonal");
  const double scale = std::sqrt(std::abs(centred0.topLeftCorner<2, 2>().determinant()));
  if (!(scale <= 1.0 + config_.max_scale_change && scale >= 1.0 / (1.0 + config_.max_scale_change)))
    return finish(FailureReason::kMotionTooLarge, "scale change " + str(scale) +
                                                      " outside [1 / (1 + x), 1 + x] with x = max_scale_change " +
                                                      str(config_.max_scale_change));
  if (config_.estimate_illumination && !(state.gain >= config_.min_gain && state.gain <= config_.max_gain))
    return finish(FailureReason::kInconsistent, "illumination gain " + str(state.gain) + " outside [" +
                                                    str(config_.min_gain) + ", " + str(config_.max_gain) + "]");
  if (est.inlier_fraction < config_.min_inlier_fraction || est.inliers < config_.min_inliers)
    return finish(FailureReason::kTooFewInliers,
                  std::to_string(est.inliers) + " inliers of " + std::to_string(est.observations) +
                      " evaluated pixels (need a fraction >= " + str(config_.min_inlier_fraction) +
                      " and >= " + std::to_string(config_.min_inliers) + ")");
  if (est.residual_scale > config_.max_residual_scale)
    return finish(FailureReason::kInconsistent, "residual scale " + str(est.residual_scale) +
                                                    " grey levels > max_residual_scale " +
                                                    str(config_.max_residual_scale));
  if (stats.correlation < config_.min_correlation)
    return finish(FailureReason::kInconsistent, "correlation of the aligned images " + str(stats.correlation) +
                                                    " < min_correlation " + str(config_.min_correlation));
  if (est.covariance.rows() != ng || !est.covariance.allFinite())
    return finish(FailureReason::kInconsistent, "the normal equations are singular at the solution");
  return finish(FailureReason::kNone, "");
}

}  // namespace registration
}  // namespace exocet_mosaic
