/**
 * @file rigid_scene_check.h
 * @brief Whether point tracks between two images move with one rigid scene, whatever its relief: the two-view
 * epipolar constraint (a fundamental matrix fitted by RANSAC, exocet_common/geometry) within the tracking noise
 * measured on the tracks themselves. No ROS in it.
 *
 * A seabed with relief seen from a moving camera does not move as one plane: the residuals of a homography are the
 * parallax of the relief, coherent along the epipolar lines, and neighbouring tracks across a depth edge disagree.
 * Tracks on particles that drift, or on fish, move on their own: they leave the epipolar lines. So a track is taken
 * as part of the scene when its Sampson distance to the fitted epipolar geometry is below k_sigma times the tracking
 * noise; the noise is measured per image pair from the forward-backward distances of the tracks (a track and its way
 * back err independently: |fb| follows a Rayleigh law of scale sqrt(2) sigma, median 1.665 sigma). No threshold in
 * pixels is set by hand.
 */
#pragma once

#include <string>
#include <vector>

#include <opencv2/core.hpp>

namespace exocet_mosaic {
namespace registration {

/// The per-coordinate tracking noise (px) that forward-backward distances imply: median / 1.665, at least
/// `floor_px`; `floor_px` when the list is empty.
double trackingNoiseFromForwardBackward_px(std::vector<float> fb_distances_px, double floor_px);

/// Parameters of the check. validate() lists the allowed ranges.
struct RigidSceneConfig {
  /// A track is in the scene when its Sampson distance is at most k_sigma tracking-noise sigmas: 3 keeps 99.7 % of
  /// a Gaussian noise, [1, 20].
  double k_sigma = 3.0;
  unsigned seed = 1;  ///< of the RANSAC (the same tracks always give the same answer)

  std::string validate() const;
};

/// The check's outcome.
struct RigidSceneCheck {
  bool estimated = false;           ///< a fundamental matrix was fitted (at least 8 tracks, RANSAC succeeded)
  std::vector<uint8_t> consistent;  ///< per track: 1 on the epipolar geometry within k_sigma * sigma_px
  int consistent_count = 0;
  double sigma_px = 0.0;      ///< the tracking noise used
  double threshold_px = 0.0;  ///< k_sigma * sigma_px
  std::string detail;         ///< what was found, in words
};

/// Checks the tracks from_px[i] -> to_px[i] against one rigid scene, with tracking noise `sigma_px` (> 0).
RigidSceneCheck checkRigidScene(const std::vector<cv::Point2f>& from_px, const std::vector<cv::Point2f>& to_px,
                                double sigma_px, const RigidSceneConfig& config = {});

}  // namespace registration
}  // namespace exocet_mosaic
