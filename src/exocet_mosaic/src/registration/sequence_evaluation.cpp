#include "exocet_mosaic/registration/sequence_evaluation.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include <Eigen/Dense>

namespace exocet_mosaic {
namespace registration {
namespace {

double quantile(std::vector<double> v, double q) {
  if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
  std::sort(v.begin(), v.end());
  const double pos = q * double(v.size() - 1);
  const size_t i = size_t(std::floor(pos));
  const double f = pos - double(i);
  return i + 1 < v.size() ? v[i] * (1.0 - f) + v[i + 1] * f : v[i];
}

}  // namespace

PairScore scorePair(const MotionEstimate& estimate, const Eigen::Matrix3d& truth, int width, int height) {
  PairScore s;
  s.failed = estimate.failed;
  s.failure = estimate.failure;
  s.method = estimate.method;
  s.elapsed_ms = estimate.elapsed_ms;
  if (estimate.failed) {
    s.corner_error_px = std::numeric_limits<double>::quiet_NaN();
    s.corner_nees = std::numeric_limits<double>::quiet_NaN();
    return s;
  }
  s.corner_error_px = cornerTransferError_px(estimate.pixel_matrix, truth, width, height);
  const Eigen::Vector2d corners[4] = {{0.0, 0.0}, {width - 1.0, 0.0}, {0.0, height - 1.0}, {width - 1.0, height - 1.0}};
  double nees = 0.0;
  for (const Eigen::Vector2d& c : corners) {
    const Eigen::Vector2d e = transferPoint(estimate.pixel_matrix, c) - transferPoint(truth, c);
    const Eigen::Matrix2d cov =
        transferCovariance(estimate.model, estimate.parameters, estimate.covariance, estimate.centre_px, c);
    nees += e.dot(cov.ldlt().solve(e));
  }
  s.corner_nees = nees / 4.0;
  return s;
}

SequenceScore summarize(std::vector<PairScore> pairs, double gross_threshold_px) {
  SequenceScore score;
  score.pairs = std::move(pairs);
  std::vector<double> errors, nees;
  double ms = 0.0;
  for (const PairScore& p : score.pairs) {
    ms += p.elapsed_ms;
    if (p.failed) {
      ++score.failures;
      continue;
    }
    errors.push_back(p.corner_error_px);
    if (std::isfinite(p.corner_nees)) nees.push_back(p.corner_nees);
    if (!(p.corner_error_px <= gross_threshold_px)) ++score.gross_failures;
  }
  const double n = double(std::max<size_t>(1, score.pairs.size()));
  score.failure_rate = score.failures / n;
  score.gross_failure_rate = score.gross_failures / n;
  score.median_px = quantile(errors, 0.5);
  score.p95_px = quantile(errors, 0.95);
  score.max_px = errors.empty() ? std::numeric_limits<double>::quiet_NaN()
                                : *std::max_element(errors.begin(), errors.end());
  // Median of chi-square(2) is 2 ln 2; the per-pair NEES averages 4 correlated corners, so this is approximate.
  score.nees_ratio = quantile(nees, 0.5) / (2.0 * std::log(2.0));
  score.mean_ms = ms / n;
  score.fps = ms > 0.0 ? 1000.0 * n / ms : 0.0;
  return score;
}

SequenceScore evaluateSequence(SequenceRegistrar& sequence, const std::vector<cv::Mat>& frames,
                               const std::vector<double>& stamps_s, const std::vector<Eigen::Matrix3d>& truth,
                               double gross_threshold_px, const std::function<bool(int)>& select) {
  if (stamps_s.size() != frames.size() || truth.size() != frames.size())
    throw std::invalid_argument("evaluateSequence: " + std::to_string(frames.size()) + " frames, " +
                                std::to_string(stamps_s.size()) + " stamps and " + std::to_string(truth.size()) +
                                " true motions: they must be as many");
  sequence.restart();
  std::vector<PairScore> pairs;
  for (size_t i = 0; i < frames.size(); ++i) {
    const auto start = std::chrono::steady_clock::now();
    const SequenceStep step = sequence.add(frames[i], stamps_s[i]);
    const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    if (i == 0 || (select && !select(int(i)))) continue;
    MotionEstimate e = step.motion;
    if (!step.has_motion) {  // a restart: no motion for this pair
      e = MotionEstimate();
      e.failure_detail = step.restart_reason;
    }
    PairScore s = scorePair(e, truth[i], frames[i].cols, frames[i].rows);
    s.index = int(i);
    s.elapsed_ms = ms;
    pairs.push_back(s);
  }
  return summarize(std::move(pairs), gross_threshold_px);
}

}  // namespace registration
}  // namespace exocet_mosaic
