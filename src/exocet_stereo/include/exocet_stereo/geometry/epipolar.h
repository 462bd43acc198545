/**
 * @file epipolar.h
 * @brief Epipolar geometry of calibrated views: the relative pose, the essential matrix E = [t]x R and the
 * fundamental matrix F = K2^-T E K1^-1 of two views whose poses are known (a calibrated rig or a multi-view set),
 * and the distances of a match to F (2D4 report section 3.2.2). No ROS in it.
 *
 * Convention (OpenCV's): b^T F a = 0 for a pixel a of the first view and its match b in the second.
 */
#pragma once

#include <Eigen/Core>

#include "exocet_common/geometry/fundamental_estimator.h"
#include "exocet_stereo/geometry/pinhole_view.h"

namespace exocet_stereo {
namespace geometry {

/// Pose of the second camera relative to the first: X2 = R_21 X1 + t_21 (camera coordinates).
struct RelativePose {
  Eigen::Matrix3d R_21 = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t_21 = Eigen::Vector3d::Zero();
};

/// The relative pose of view2 with respect to view1 (both world-to-camera).
RelativePose relativePose(const PinholeView& view1, const PinholeView& view2);

/// E = [t_21]x R_21, so that y2^T E y1 = 0 for normalised coordinates y = K^-1 x.
Eigen::Matrix3d essentialMatrix(const RelativePose& pose);

/// F = K2^-T E K1^-1 of a calibrated pair, scaled to unit Frobenius norm.
Eigen::Matrix3d fundamentalFromCalibration(const Eigen::Matrix3d& K1, const Eigen::Matrix3d& K2,
                                           const RelativePose& pose);

/// F of two calibrated views of a multi-view set (unit Frobenius norm).
Eigen::Matrix3d fundamentalFromViews(const PinholeView& view1, const PinholeView& view2);

/// Sampson distance (pixels) of a match to F: the shared one (exocet_common), which the estimator also scores with.
using exocet_common::geometry::sampsonDistance_px;

/// Distance (pixels) from b to the epipolar line F a in the second image.
double epipolarLineDistance_px(const Eigen::Matrix3d& F, const Eigen::Vector2d& a, const Eigen::Vector2d& b);

/// Symmetric epipolar distance: the larger of the point-to-line distances in each image (pixels).
double symmetricEpipolarDistance_px(const Eigen::Matrix3d& F, const Eigen::Vector2d& a, const Eigen::Vector2d& b);

/**
 * @brief A conservative epipolar tolerance for poses known only approximately: a rotation error of
 * `rotation_error_rad` moves an epipolar line by up to about focal * angle, and a centre error that is a fraction
 * `relative_centre_error` of the camera-to-scene distance by about focal * fraction. Returns their sum plus the
 * matching noise, so that true matches survive while gross mismatches far from the line are removed. Pass the
 * errors of the pair (for two cameras each off by e, about 2 e).
 */
double epipolarToleranceForPoseError_px(double focal_px, double rotation_error_rad, double relative_centre_error,
                                        double noise_px);

}  // namespace geometry
}  // namespace exocet_stereo
