#include "exocet_mosaic/registration/sequence_registrar.h"

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <sstream>
#include <stdexcept>

#include "exocet_mosaic/registration/motion_model.h"

namespace exocet_mosaic {
namespace registration {

std::string SequenceRegistrarConfig::validate() const {
  std::ostringstream why;
  if (!(max_gap_s > 0.0 && max_gap_s <= 3600.0))
    why << "max_gap_s = " << max_gap_s << " is outside (0, 3600] s";
  else if (!(max_prediction_ratio >= 1.0 && max_prediction_ratio <= 100.0))
    why << "max_prediction_ratio = " << max_prediction_ratio << " is outside [1, 100]";
  else if (!(calibration_wait_s >= 0.0 && calibration_wait_s <= 60.0))
    why << "calibration_wait_s = " << calibration_wait_s << " is outside [0, 60] s";
  return why.str();
}

SequenceRegistrar::SequenceRegistrar(std::unique_ptr<FrameRegistrar> registrar, const SequenceRegistrarConfig& config)
    : config_(config) {
  const std::string error = config.validate();
  if (!error.empty()) throw std::invalid_argument("sequence registrar: " + error);
  replaceRegistrar(std::move(registrar));
}

void SequenceRegistrar::replaceRegistrar(std::unique_ptr<FrameRegistrar> registrar) {
  if (!registrar) throw std::invalid_argument("sequence registrar: no registrar given");
  registrar_ = std::move(registrar);
  restart();
}

void SequenceRegistrar::restart() {
  registrar_->reset();
  have_previous_ = false;
  previous_interval_s_ = 0.0;
  last_motion_ = MotionEstimate();
}

void SequenceRegistrar::setCalibration(const CameraCalibration& calibration) { calibration_ = calibration; }

bool SequenceRegistrar::holdForCalibration(double stamp_s) {
  if (calibration_ || calibration_wait_over_ || config_.calibration_wait_s <= 0.0) return false;
  if (!std::isfinite(stamp_s)) return false;  // add() refuses it, naming the stamp
  // A stamp before the first one (a bag replayed again) measures the wait from there.
  if (!first_uncalibrated_stamp_s_ || stamp_s < *first_uncalibrated_stamp_s_) first_uncalibrated_stamp_s_ = stamp_s;
  if (stamp_s - *first_uncalibrated_stamp_s_ < config_.calibration_wait_s) return true;
  calibration_wait_over_ = true;
  return false;
}

Eigen::Matrix3d SequenceRegistrar::predictionFor(double interval_s) const {
  if (!have_previous_ || last_motion_.failed || previous_interval_s_ <= 0.0 || !(interval_s > 0.0))
    return Eigen::Matrix3d::Identity();
  // Constant velocity: the previous motion scaled to this interval bridges dropped frames.
  const double ratio = std::min(interval_s / previous_interval_s_, config_.max_prediction_ratio);
  return pixelMatrix(last_motion_.model, ratio * last_motion_.parameters, last_motion_.centre_px);
}

std::string SequenceRegistrar::updateUndistorter(const cv::Size& size, std::string* warning) {
  if (!config_.undistort || !calibration_) return "";
  const CameraCalibration& c = *calibration_;
  if (!c.distortion_model.empty() && c.distortion_model != "plumb_bob" && c.distortion_model != "rational_polynomial") {
    *warning = "camera calibration distortion model '" + c.distortion_model +
               "' is not supported (plumb_bob): the images are registered as they are";
    return "";
  }
  if (c.size != size || undistorter_.sameCalibration(c.size, c.k, c.d)) return "";
  try {
    ImageUndistorter next(c.size, c.k, c.d);
    // Only a change of the image geometry breaks the sequence (not a first calibration without distortion).
    const bool geometry_changes = undistorter_.active() || next.active();
    undistorter_ = next;
    return have_previous_ && geometry_changes ? "the camera calibration changed" : "";
  } catch (const std::invalid_argument& e) {
    *warning = std::string("camera calibration unusable: ") + e.what();
    return "";
  }
}

SequenceStep SequenceRegistrar::add(const cv::Mat& gray_in, double stamp_s) {
  if (gray_in.empty() || gray_in.type() != CV_8UC1)
    throw std::invalid_argument("sequence registrar: the image must be 8-bit grey (CV_8UC1) and not empty");
  if (!std::isfinite(stamp_s) || stamp_s <= 0.0) {
    std::ostringstream why;
    why << "sequence registrar: image stamp " << stamp_s << " s is not a finite positive time";
    throw std::invalid_argument(why.str());
  }
  if (have_previous_ && stamp_s == previous_stamp_s_) {
    std::ostringstream why;
    why << std::fixed << std::setprecision(3) << "sequence registrar: image stamped " << stamp_s
        << " s like the previous one (a duplicated stamp): skipped";
    throw std::invalid_argument(why.str());
  }
  SequenceStep step;
  step.restart_reason = updateUndistorter(gray_in.size(), &step.calibration_warning);
  cv::Mat gray = gray_in;
  if (undistorter_.active()) {
    if (gray.size() == undistorter_.size()) {
      gray = undistorter_.apply(gray);
      step.undistorted = true;
    } else if (step.calibration_warning.empty()) {
      std::ostringstream why;
      why << "image size " << gray.cols << "x" << gray.rows << " differs from the calibration's "
          << undistorter_.size().width << "x" << undistorter_.size().height << ": not undistorted";
      step.calibration_warning = why.str();
    }
  }
  step.image_size = gray.size();
  if (calibration_ && calibration_->size == gray.size()) {
    if (step.undistorted) {
      step.camera_matrix = undistorter_.cameraMatrix();
    } else {
      step.camera_matrix = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(calibration_->k.data());
    }
  }

  const double interval_s = have_previous_ ? stamp_s - previous_stamp_s_ : 0.0;
  if (have_previous_ && step.restart_reason.empty()) {
    std::ostringstream why;
    if (interval_s <= 0.0)
      why << "image stamps went back by " << -interval_s << " s (bag replayed again or clock jump)";
    else if (interval_s > config_.max_gap_s)
      why << "gap of " << interval_s << " s between images exceeds max_gap_s = " << config_.max_gap_s << " s";
    else if (gray.size() != previous_size_)
      why << "image size changed from " << previous_size_.width << "x" << previous_size_.height << " to " << gray.cols
          << "x" << gray.rows;
    step.restart_reason = why.str();
  }
  if (!step.restart_reason.empty()) restart();

  if (!have_previous_) {
    registrar_->reset();
    registrar_->registerNext(gray);  // keeps the image as the first of the next pair
    have_previous_ = true;
    previous_stamp_s_ = stamp_s;
    previous_size_ = gray.size();
    previous_interval_s_ = 0.0;
    last_motion_ = MotionEstimate();
    return step;
  }

  step.motion = registrar_->registerNext(gray, predictionFor(interval_s));
  step.has_motion = true;
  step.previous_stamp_s = previous_stamp_s_;
  last_motion_ = step.motion;
  previous_interval_s_ = interval_s;
  previous_stamp_s_ = stamp_s;
  return step;
}

}  // namespace registration
}  // namespace exocet_mosaic
