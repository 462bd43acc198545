#include "exocet_servo/control/invariant_servo.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include <Eigen/Eigenvalues>
#include <Eigen/LU>

#include "exocet_servo/control/invariant_interaction.h"

namespace exocet_servo {
namespace control {

namespace {

std::vector<Eigen::Vector3d> normalise(const std::vector<Eigen::Vector2d>& points_px, const Eigen::Matrix3d& k) {
  const Eigen::Matrix3d k_inv = k.inverse();
  std::vector<Eigen::Vector3d> m;
  m.reserve(points_px.size());
  for (const auto& p : points_px) {
    Eigen::Vector3d v = k_inv * Eigen::Vector3d(p.x(), p.y(), 1.0);
    m.push_back(v / v.z());
  }
  return m;
}

std::string checkIntrinsics(const Eigen::Matrix3d& k) {
  if (!(k(0, 0) > 0.0 && k(1, 1) > 0.0) || k(1, 0) != 0.0 || k(2, 0) != 0.0 || k(2, 1) != 0.0 || k(2, 2) != 1.0)
    return "intrinsics estimate must be upper triangular with fx > 0, fy > 0 and K(2,2) = 1";
  return "";
}

/// Pseudo-inverse (6 x 2n) of a full-rank tall matrix through the 6x6 normal matrix; empty when the condition number
/// of L^T L exceeds 1e12 (motion not observable from these points).
Eigen::MatrixXd pseudoInverse(const Eigen::MatrixXd& l) {
  const Eigen::Matrix<double, 6, 6> n = l.transpose() * l;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 6, 6>> eig(n, Eigen::EigenvaluesOnly);
  const double lo = eig.eigenvalues()(0), hi = eig.eigenvalues()(5);
  if (!(lo > 1e-12 * hi)) return Eigen::MatrixXd();
  return n.ldlt().solve(l.transpose());
}

}  // namespace

std::string toString(ServoStatus status) {
  switch (status) {
    case ServoStatus::kRunning:
      return "running";
    case ServoStatus::kConverged:
      return "converged";
    case ServoStatus::kMaxIterations:
      return "max_iterations";
    case ServoStatus::kErrorGrowing:
      return "error_growing";
    case ServoStatus::kPointsLeftImage:
      return "points_left_image";
    case ServoStatus::kDegenerate:
      return "degenerate";
    case ServoStatus::kInvalidInput:
      return "invalid_input";
  }
  return "unknown";
}

std::string ServoConfig::validate() const {
  std::ostringstream errors;
  auto check = [&errors](bool ok, const char* field, const std::string& range) {
    if (ok) return;
    if (errors.tellp() > 0) errors << "; ";
    errors << field << " must be in " << range;
  };
  const std::string gain_errors = gain.validate();
  if (!gain_errors.empty()) errors << gain_errors;
  check(convergence_threshold > 0.0 && convergence_threshold <= 1.0, "convergence_threshold", "(0, 1]");
  check(convergence_window >= 1 && convergence_window <= 1000, "convergence_window", "[1, 1000]");
  check(max_iterations >= 1 && max_iterations <= 1000000, "max_iterations", "[1, 1000000]");
  check(growth_iterations >= 2 && growth_iterations <= 10000, "growth_iterations", "[2, 10000]");
  check(growth_ratio >= 1.0 && growth_ratio <= 1e6, "growth_ratio", "[1, 1e6]");
  check(image_width_px >= 16 && image_width_px <= 100000, "image_width_px", "[16, 100000]");
  check(image_height_px >= 16 && image_height_px <= 100000, "image_height_px", "[16, 100000]");
  check(image_margin_px >= 0.0 && image_margin_px <= std::min(image_width_px, image_height_px) / 4.0, "image_margin_px",
        "[0, min(image_width_px, image_height_px) / 4]");
  check(default_depth_m > 0.0 && default_depth_m <= 1000.0, "default_depth_m", "(0, 1000]");
  return errors.str();
}

InvariantServo::InvariantServo(const ServoConfig& config) : config_(config) {
  const std::string errors = config.validate();
  if (!errors.empty()) throw std::invalid_argument("ServoConfig: " + errors);
}

std::string InvariantServo::setReference(const std::vector<Eigen::Vector2d>& points_px, const Eigen::Matrix3d& k,
                                         const std::vector<double>& depths_m) {
  has_reference_ = false;
  finished_ = false;
  iteration_ = 0;
  growth_count_ = 0;
  last_norm_ = min_norm_ = 0.0;
  recent_errors_.clear();
  if (points_px.size() < 4) return "reference needs at least 4 points, got " + std::to_string(points_px.size());
  std::string err = checkIntrinsics(k);
  if (!err.empty()) return "reference " + err;
  err = computeInvariantPoints(homogeneous(points_px), &reference_);
  if (!err.empty()) return "reference: " + err;
  reference_stacked_ = reference_.stacked();
  const std::vector<double> depths =
      depths_m.empty() ? std::vector<double>(points_px.size(), config_.default_depth_m) : depths_m;
  err = invariantInteraction(normalise(points_px, k), depths, &reference_interaction_);
  if (!err.empty()) return "reference: " + err;
  has_reference_ = true;
  return "";
}

ServoStep InvariantServo::finish(ServoStep step, ServoStatus status, const std::string& message) {
  step.status = status;
  step.message = message;
  if (status != ServoStatus::kRunning) {
    step.velocity.setZero();
    finished_ = true;
    last_terminal_ = step;
  }
  return step;
}

ServoStep InvariantServo::step(const std::vector<Eigen::Vector2d>& points_px, const Eigen::Matrix3d& k,
                               const std::vector<double>& depths_m) {
  if (finished_) {
    ServoStep again = last_terminal_;
    again.velocity.setZero();
    return again;
  }
  ServoStep out;
  out.iteration = ++iteration_;
  if (!has_reference_) return finish(out, ServoStatus::kInvalidInput, "no reference: call setReference() first");
  const size_t n = points_px.size();
  if (n != reference_.q.size()) {
    std::ostringstream msg;
    msg << n << " current points for " << reference_.q.size() << " reference points (must be matched one to one)";
    return finish(out, ServoStatus::kInvalidInput, msg.str());
  }
  if (!depths_m.empty() && depths_m.size() != n) {
    std::ostringstream msg;
    msg << depths_m.size() << " depths for " << n << " points (give one per point, or none)";
    return finish(out, ServoStatus::kInvalidInput, msg.str());
  }
  const std::string k_err = checkIntrinsics(k);
  if (!k_err.empty()) return finish(out, ServoStatus::kInvalidInput, "current " + k_err);
  const double margin = config_.image_margin_px;
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector2d& p = points_px[i];
    if (!(p.x() >= margin && p.y() >= margin && p.x() <= config_.image_width_px - 1 - margin &&
          p.y() <= config_.image_height_px - 1 - margin)) {
      std::ostringstream msg;
      msg << "point " << i << " at (" << p.x() << ", " << p.y() << ") px left the image [" << margin << ", "
          << config_.image_width_px - 1 - margin << "] x [" << margin << ", " << config_.image_height_px - 1 - margin
          << "] at iteration " << iteration_;
      return finish(out, ServoStatus::kPointsLeftImage, msg.str());
    }
  }

  InvariantPoints current;
  std::string err = computeInvariantPoints(homogeneous(points_px), &current);
  if (!err.empty()) return finish(out, ServoStatus::kDegenerate, "current points: " + err);
  const Eigen::VectorXd diff = current.stacked() - reference_stacked_;
  out.feature_rms = std::sqrt(diff.squaredNorm() / static_cast<double>(diff.size()));

  Eigen::MatrixXd l;
  if (config_.interaction == InteractionModel::kDesired) {
    l = reference_interaction_;
  } else {
    const std::vector<double> depths = depths_m.empty() ? std::vector<double>(n, config_.default_depth_m) : depths_m;
    err = invariantInteraction(normalise(points_px, k), depths, &l);
    if (!err.empty()) return finish(out, ServoStatus::kInvalidInput, err);
    if (config_.interaction == InteractionModel::kMean) l = 0.5 * (l + reference_interaction_);
  }
  const Eigen::MatrixXd l_pinv = pseudoInverse(l);
  if (l_pinv.size() == 0)
    return finish(out, ServoStatus::kDegenerate,
                  "the interaction matrix is rank deficient: the depths must vary from point to point (equal depths, "
                  "or a planar object, make the translations look like a change of intrinsics, which the invariant "
                  "points remove); give per-point depth estimates");
  out.task_error = l_pinv * diff;
  out.error_norm = out.task_error.norm();
  out.gain = config_.gain(out.error_norm);

  if (out.error_norm < config_.convergence_threshold) {
    std::ostringstream msg;
    msg << "converged in " << iteration_ << " iterations: |e| = " << out.error_norm << " < "
        << config_.convergence_threshold;
    return finish(out, ServoStatus::kConverged, msg.str());
  }
  recent_errors_.push_back(out.task_error);
  if (static_cast<int>(recent_errors_.size()) > config_.convergence_window) recent_errors_.pop_front();
  if (config_.convergence_window > 1 && static_cast<int>(recent_errors_.size()) == config_.convergence_window) {
    Eigen::Matrix<double, 6, 1> mean = Eigen::Matrix<double, 6, 1>::Zero();
    for (const auto& e : recent_errors_) mean += e;
    mean /= static_cast<double>(recent_errors_.size());
    if (mean.norm() < config_.convergence_threshold) {
      std::ostringstream msg;
      msg << "converged in " << iteration_ << " iterations: the mean of e over the last " << config_.convergence_window
          << " is " << mean.norm() << " < " << config_.convergence_threshold << " (|e| = " << out.error_norm << ")";
      return finish(out, ServoStatus::kConverged, msg.str());
    }
  }
  // Growth: noise makes |e| wobble near convergence, so a run of increases only counts once |e| is well above the
  // smallest value reached.
  if (iteration_ == 1) {
    min_norm_ = out.error_norm;
    growth_count_ = 0;
  } else {
    growth_count_ = out.error_norm > last_norm_ ? growth_count_ + 1 : 0;
    min_norm_ = std::min(min_norm_, out.error_norm);
  }
  last_norm_ = out.error_norm;
  if (growth_count_ >= config_.growth_iterations && out.error_norm > config_.growth_ratio * min_norm_) {
    std::ostringstream msg;
    msg << "diverging: |e| grew for " << growth_count_ << " iterations to " << out.error_norm << " ("
        << out.error_norm / min_norm_ << " times its minimum " << min_norm_ << ")";
    return finish(out, ServoStatus::kErrorGrowing, msg.str());
  }
  if (iteration_ >= config_.max_iterations) {
    std::ostringstream msg;
    msg << "not converged after " << iteration_ << " iterations (max_iterations): |e| = " << out.error_norm
        << ", threshold " << config_.convergence_threshold;
    return finish(out, ServoStatus::kMaxIterations, msg.str());
  }
  out.velocity = -out.gain * out.task_error;
  return finish(out, ServoStatus::kRunning, "running");
}

}  // namespace control
}  // namespace exocet_servo
