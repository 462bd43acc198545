/**
 * @file sparse_reconstruction.h
 * @brief Multi-view sparse reconstruction from images, intrinsics and approximate poses (2D4 report sections
 * 3.2.1-3.2.4): SIFT matching between neighbours (nearest initial centres, or index ring), epipolar filtering against
 * the approximate poses (with a tolerance for their error) then RANSAC on F, tracks by union-find, triangulation
 * (points seen under too narrow an angle dropped), robust bundle adjustment, removal of observations above a
 * reprojection threshold, and a second adjustment. Views with too few observations keep their initial pose and are
 * not counted as registered. No ROS in it.
 */
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "exocet_stereo/geometry/bundle_adjustment.h"
#include "exocet_stereo/geometry/feature_matching.h"
#include "exocet_stereo/geometry/fundamental_ransac.h"
#include "exocet_stereo/geometry/pinhole_view.h"
#include "exocet_stereo/geometry/track_builder.h"

namespace exocet_stereo {
namespace geometry {

/// Which image pairs are matched.
enum class PairSelection {
  kNearestCentres,  ///< each image with the `neighbour_span` images whose initial centres are nearest
  kIndexRing,       ///< image i with i+1 .. i+span (wrapping around if `ring`): for files stored in ring order
};

/// Settings. validate() lists every bad field with its allowed range (including the nested configs').
struct SparseReconstructionConfig {
  SiftMatchingConfig matching;
  /// Nearest centres by default: the Middlebury ring files are not stored in ring order (view 1 and view 11 share a
  /// centre; the next longitude of view 2 is view 14), so index neighbours are often not image neighbours.
  PairSelection pair_selection = PairSelection::kNearestCentres;
  int neighbour_span = 3;  ///< partners per image, [1, 32]
  bool ring = true;        ///< kIndexRing: indices wrap around (views on a closed ring)
  /// Largest distance (px) of a match to the epipolar line of the initial poses, (0, 1000]; see
  /// epipolarToleranceForPoseError_px().
  double pose_epipolar_tolerance_px = 100.0;
  FundamentalRansacConfig ransac;  ///< per-pair RANSAC on F (its threshold_px is the Sampson gate)
  int min_pair_inliers = 20;       ///< a pair with fewer inliers contributes no match, [8, 100000]
  /// Points whose widest pair of rays is narrower are dropped before and after the first adjustment, [0, 45] deg.
  double min_triangulation_angle_deg = 2.0;
  double outlier_threshold_px = 2.0;  ///< observations above this after the first adjustment are removed, (0, 100]
  /// A view with fewer observations is left out of the adjustment (pose kept, not registered), [1, 100000].
  int min_observations_per_view = 20;
  BundleAdjustmentConfig adjustment;

  std::string validate() const;
};

/// Per-pair statistics.
struct PairMatchStats {
  int image_a = 0, image_b = 0;
  int putative = 0;         ///< after ratio test and mutual check
  int pose_consistent = 0;  ///< within the epipolar tolerance of the initial poses
  int ransac_inliers = 0;   ///< kept
};

/// The result.
struct SparseReconstruction {
  std::vector<PinholeView> views;                     ///< refined cameras (same order as the input)
  std::vector<Eigen::Vector3d> points;                ///< world points
  std::vector<std::vector<TrackObservation>> tracks;  ///< observations of each point (kept ones)
  std::vector<ImageFeatures> features;                ///< per image
  std::vector<PairMatchStats> pairs;
  int views_registered = 0;  ///< views with at least min_observations_per_view observations
  int observations = 0;
  double initial_rms_px = 0.0;   ///< reprojection RMS of the triangulated points with the initial poses
  double final_rms_px = 0.0;     ///< after the second adjustment
  int removed_observations = 0;  ///< after the first adjustment, by the reprojection and angle gates
  BaReport first_adjustment, second_adjustment;
};

/**
 * @brief Runs the pipeline.
 * @param images 8-bit images, one per view
 * @param initial_views intrinsics (trusted) and approximate poses, one per image
 * @throws std::invalid_argument if the config is invalid or the lists differ in length (fewer than 2 views).
 */
SparseReconstruction reconstructSparse(const std::vector<cv::Mat>& images,
                                       const std::vector<PinholeView>& initial_views,
                                       const SparseReconstructionConfig& config = SparseReconstructionConfig());

}  // namespace geometry
}  // namespace exocet_stereo
