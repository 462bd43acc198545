/**
 * @file similarity_alignment.h
 * @brief The similarity (scale, rotation, translation) that best maps one point set onto another in least squares
 * (Umeyama 1991, Eigen::umeyama), used to compare a reconstruction whose gauge is arbitrary with ground truth.
 */
#pragma once

#include <vector>

#include <Eigen/Core>

namespace exocet_stereo {
namespace geometry {

/// y ~ scale R x + t.
struct Similarity {
  double scale = 1.0;
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();

  Eigen::Vector3d apply(const Eigen::Vector3d& x) const { return scale * R * x + t; }
};

/**
 * @brief Least-squares similarity from `source` onto `target` (Umeyama).
 * @throws std::invalid_argument with fewer than 3 points or mismatched lists.
 */
Similarity alignSimilarity(const std::vector<Eigen::Vector3d>& source, const std::vector<Eigen::Vector3d>& target);

/// Errors |S(source_i) - target_i| after alignment, in target units.
std::vector<double> alignedErrors(const Similarity& S, const std::vector<Eigen::Vector3d>& source,
                                  const std::vector<Eigen::Vector3d>& target);

}  // namespace geometry
}  // namespace exocet_stereo
