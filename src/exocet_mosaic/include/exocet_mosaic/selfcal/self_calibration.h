/**
 * @file self_calibration.h
 * @brief Camera self-calibration without a pattern (2D3 section 3.3, Pessel et al. 2003): from the point matches
 * between key frames, a fundamental matrix per pair (8-point + RANSAC), a planarity verdict per pair (GRIC), the
 * intrinsics by Mendonca-Cipolla over the pairs with relief, and the extrinsics of each pair from E = K^T F K. A flat
 * seabed is refused with a clear error, or calibrated from its homographies (Triggs) when the caller allows it.
 * No ROS in it.
 */
#pragma once

#include <stdexcept>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "exocet_mosaic/selfcal/feature_track_builder.h"
#include "exocet_mosaic/selfcal/mendonca_cipolla_calibrator.h"
#include "exocet_mosaic/selfcal/planar_self_calibrator.h"
#include "exocet_mosaic/selfcal/planarity_test.h"
#include "exocet_mosaic/selfcal/relative_pose.h"

namespace exocet_mosaic {
namespace selfcal {

/// Everything the self-calibration can be tuned by. validate() names a bad field and its allowed range.
struct SelfCalibrationConfig {
  FundamentalConfig fundamental;  ///< its seed is combined with each pair's key frames
  PlanarityConfig planarity;
  MendoncaCipollaConfig intrinsics;
  PlanarCalibrationConfig planar_intrinsics;
  int min_inliers = 40;    ///< a pair is used only if its F has at least this many inliers (>= 8)
  int min_key_frames = 5;  ///< the pairs used must involve at least this many key frames (>= 3)
  /// A verdict "planar" needs more than this share of the assessed pairs to be planar ([0, 1)).
  double planar_majority = 0.5;
  /// The result is refused as unconstrained if a parameter's 1-sigma exceeds this share of its value (> 0).
  double max_relative_sigma = 0.1;
  bool allow_planar = false;  ///< calibrate a flat seabed from its homographies instead of refusing
  /// Key-frame bootstrap of the Mendonca-Cipolla estimate (0 = none, else >= 20): the pairs' fundamental matrices
  /// share their key frames' tracks, so their errors are correlated and the residual-based covariance (which takes
  /// the pairs as independent) understates the uncertainty. Each replicate draws the key frames with replacement,
  /// weighs every pair by the product of its two key frames' multiplicities and minimises the cost again from the
  /// estimate; the reported 1-sigma of each parameter is the larger of the two.
  int bootstrap_replicates = 200;
  uint64_t bootstrap_seed = 1;  ///< the resampling's random generator: same seed, same result
  std::string validate() const;
};

/// What happened to one key-frame pair.
struct PairReport {
  int key_a = 0, key_b = 0, frame_a = 0, frame_b = 0;
  int matches = 0;
  FundamentalResult fundamental;
  PlanarityVerdict planarity;
  enum class Status { kTooFewMatches, kTooFewInliers, kPlanar, kGeneral } status = Status::kTooFewMatches;
  bool used = false;  ///< in the intrinsics' cost
  RelativePose pose;  ///< extrinsics (Mendonca-Cipolla path, used pairs only)
};

const char* toString(PairReport::Status status);

enum class CalibrationMethod { kMendoncaCipolla, kPlanarHomographies };
const char* toString(CalibrationMethod method);

struct SelfCalibrationResult {
  CalibrationMethod method = CalibrationMethod::kMendoncaCipolla;
  IntrinsicsEstimate intrinsics;
  cv::Size image_size;
  std::vector<PairReport> pairs;
  int pairs_used = 0;
  int key_frames_used = 0;
  int planar_pairs = 0;            ///< pairs whose matches a homography explains as well as F
  int general_pairs = 0;           ///< pairs with significant parallax (relief)
  bool scene_planar = false;       ///< the verdict: most assessed pairs are planar
  std::vector<std::string> notes;  ///< things the user should know (method switched, weak constraints)
  /// Where the 1-sigma comes from: "residuals" (the calibrator's covariance) or "key-frame bootstrap" (the larger of
  /// it and the bootstrap's, Mendonca-Cipolla path).
  std::string uncertainty = "residuals";
  int bootstrap_replicates_used = 0;  ///< replicates that converged
  Intrinsics residual_sigma;          ///< the calibrator's own (residual-based) 1-sigma, for comparison
};

/// Why a calibration cannot be made (the tool's exit code 3). what() says what to do.
class CalibrationImpossible : public std::runtime_error {
 public:
  enum class Reason { kFlatSeabed, kTooFewTracks, kUnconstrained };
  CalibrationImpossible(Reason reason, const std::string& message) : std::runtime_error(message), reason_(reason) {}
  Reason reason() const { return reason_; }

 private:
  Reason reason_;
};

/**
 * @brief Runs the calibration on the key-frame pairs of a FeatureTrackBuilder.
 * @throws CalibrationImpossible (flat seabed without allow_planar, too few usable pairs or key frames, or a result
 * whose uncertainty exceeds max_relative_sigma), std::invalid_argument on a bad config.
 */
SelfCalibrationResult selfCalibrate(const std::vector<KeyFramePair>& pairs, const cv::Size& image_size,
                                    const SelfCalibrationConfig& config);

/// A human-readable summary: each parameter with its 1-sigma, the pairs used, the planarity verdict.
std::string summaryText(const SelfCalibrationResult& result);

/// The extra YAML keys appended to a camera_calibration_parsers file: `self_calibration: {alpha_u_sigma_px: ...}`.
std::string selfCalibrationYamlBlock(const SelfCalibrationResult& result);

}  // namespace selfcal
}  // namespace exocet_mosaic
