/**
 * @file sequence_evaluation.h
 * @brief Scores a registration method on an image sequence whose true frame-to-frame motions are known: corner
 * transfer errors, failures, gross (unreported) failures, covariance consistency, speed. No ROS in it.
 */
#pragma once

#include <functional>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "exocet_mosaic/registration/frame_registrar.h"
#include "exocet_mosaic/registration/sequence_registrar.h"

namespace exocet_mosaic {
namespace registration {

struct PairScore {
  int index = 0;                  ///< the pair (index - 1, index)
  bool failed = false;
  FailureReason failure = FailureReason::kNone;
  RegistrationMethod method = RegistrationMethod::kKlt;
  double corner_error_px = 0.0;   ///< largest corner-transfer error (NaN when failed)
  double corner_nees = 0.0;       ///< mean over the corners of e^T C^-1 e (2 when the covariance is right)
  double elapsed_ms = 0.0;
};

struct SequenceScore {
  std::vector<PairScore> pairs;
  int failures = 0;
  int gross_failures = 0;         ///< not reported as failed, yet corner error > the gross threshold
  double failure_rate = 0.0;      ///< failures / pairs
  double gross_failure_rate = 0.0;
  double median_px = 0.0;         ///< over the pairs not reported as failed
  double p95_px = 0.0;
  double max_px = 0.0;
  /// Median of the per-pair corner NEES divided by its expectation under a right covariance (about 1.39 for the
  /// median of a chi-square with 2 degrees of freedom): 1 = consistent, > 1 = the covariance is too small.
  double nees_ratio = 0.0;
  double mean_ms = 0.0;
  double fps = 0.0;               ///< pairs per second of wall time spent in registerNext
};

/// Score of pairs already computed (fills the summary fields from `pairs`).
SequenceScore summarize(std::vector<PairScore> pairs, double gross_threshold_px = 2.0);

/**
 * Feeds `frames`, taken at `stamps_s`, through `sequence` (restarted first), the front-end registration_node runs:
 * each estimation starts from the previous motion scaled to the frame interval. Every pair is scored against
 * `truth` (truth[i] maps frame i-1 to frame i; truth[0] is not used); a frame that restarts the sequence counts as a
 * failed pair. `select`, if given, says which pairs count (e.g. one segment of a dive); all pairs are registered
 * regardless, so that the registrar's state is that of a real run.
 * @throws std::invalid_argument if the sizes of `frames`, `stamps_s` and `truth` differ.
 */
SequenceScore evaluateSequence(SequenceRegistrar& sequence, const std::vector<cv::Mat>& frames,
                               const std::vector<double>& stamps_s, const std::vector<Eigen::Matrix3d>& truth,
                               double gross_threshold_px = 2.0, const std::function<bool(int)>& select = nullptr);

/// The score of one estimate against the true pixel matrix of a width x height image pair.
PairScore scorePair(const MotionEstimate& estimate, const Eigen::Matrix3d& truth, int width, int height);

}  // namespace registration
}  // namespace exocet_mosaic
