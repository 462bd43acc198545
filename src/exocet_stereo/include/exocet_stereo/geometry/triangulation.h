/**
 * @file triangulation.h
 * @brief Triangulation of a point seen in calibrated views (2D4 report section 3.2.3): the linear DLT over N views,
 * the optimal two-view correction of Lindstrom ("Triangulation made easy", CVPR 2010, niter2: the two-iteration
 * solution of Hartley-Sturm's problem, exact to machine precision in practice), and a Gauss-Newton refinement of
 * the reprojection error over N views. No ROS in it.
 */
#pragma once

#include <vector>

#include <Eigen/Core>

#include "exocet_stereo/geometry/pinhole_view.h"

namespace exocet_stereo {
namespace geometry {

/**
 * @brief Linear triangulation: the right singular vector of the stacked rows x P3 - P1, y P3 - P2 (each row
 * normalised so that views weigh the same).
 * @throws std::invalid_argument with fewer than 2 views or mismatched lists.
 */
Eigen::Vector3d triangulateLinear(const std::vector<Projection>& projections,
                                  const std::vector<Eigen::Vector2d>& pixels);

/**
 * @brief Lindstrom's niter2: the pixels closest (in the sum of squared image distances) to (a, b) that satisfy
 * b^T F a = 0 exactly. Returns {a', b'}.
 */
std::pair<Eigen::Vector2d, Eigen::Vector2d> correctMatchOptimal(const Eigen::Matrix3d& F, const Eigen::Vector2d& a,
                                                                const Eigen::Vector2d& b);

/// Optimal two-view triangulation: correctMatchOptimal() with the F of the two views, then the linear solution.
Eigen::Vector3d triangulateOptimalTwoView(const PinholeView& view1, const PinholeView& view2, const Eigen::Vector2d& a,
                                          const Eigen::Vector2d& b);

/// Outcome of a refinement.
struct TriangulationRefinement {
  Eigen::Vector3d X = Eigen::Vector3d::Zero();
  double initial_rms_px = 0.0;  ///< RMS reprojection error before
  double final_rms_px = 0.0;    ///< and after
  int iterations = 0;
};

/**
 * @brief Gauss-Newton (with step halving) on the reprojection error of X over all views.
 * @throws std::invalid_argument with fewer than 2 views or mismatched lists.
 */
TriangulationRefinement refineTriangulation(const std::vector<Projection>& projections,
                                            const std::vector<Eigen::Vector2d>& pixels, const Eigen::Vector3d& X0,
                                            int max_iterations = 10);

/// RMS reprojection error (pixels) of X over the views; infinity if X is at infinity in one of them.
double reprojectionRms_px(const std::vector<Projection>& projections, const std::vector<Eigen::Vector2d>& pixels,
                          const Eigen::Vector3d& X);

}  // namespace geometry
}  // namespace exocet_stereo
