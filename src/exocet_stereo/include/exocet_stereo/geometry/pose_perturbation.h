/**
 * @file pose_perturbation.h
 * @brief Seeded perturbation of camera poses (random-direction centre shift proportional to the camera-to-scene
 * distance, random-axis rotation of a fixed angle), to start bundle adjustment from poses as wrong as a navigation
 * prior, and the centre error of a reconstruction against ground truth after a similarity alignment. No ROS in it.
 */
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "exocet_stereo/geometry/pinhole_view.h"

namespace exocet_stereo {
namespace geometry {

/**
 * @brief Each view's centre moves by `centre_fraction` of its distance to `scene_centre` in a uniformly random
 * direction, and its orientation turns by `angle_rad` about a uniformly random axis; K is kept.
 */
std::vector<PinholeView> perturbPoses(const std::vector<PinholeView>& views, const Eigen::Vector3d& scene_centre,
                                      double centre_fraction, double angle_rad, uint64_t seed);

/// Centre errors of `estimated` against `truth` after the best similarity, as % of each true camera's distance to
/// `scene_centre`.
struct CentreErrors {
  double max_pct = 0.0;
  double rms_pct = 0.0;
  double scale = 1.0;  ///< scale of the alignment
};

/// @throws std::invalid_argument with fewer than 3 views or mismatched lists.
CentreErrors centreErrorsAfterSimilarity(const std::vector<PinholeView>& estimated,
                                         const std::vector<PinholeView>& truth, const Eigen::Vector3d& scene_centre);

}  // namespace geometry
}  // namespace exocet_stereo
