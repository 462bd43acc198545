/**
 * @file bundle_adjustment.h
 * @brief Metric bundle adjustment with Ceres (2D4 report section 3.2.4.1): camera poses and points refined to
 * minimise the robust (Huber or Cauchy) reprojection error, intrinsics fixed or refined, and an optional stereo-rig
 * mode in which every station has a free left-camera pose and all right cameras share one right-from-left
 * transform. The gauge is fixed: the first observed (left) camera is held constant, and the scale by its distance to
 * the next observed camera (independent cameras) or by the rig baseline (rig mode). Cameras without observations are
 * left as they are. No ROS in it.
 */
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "exocet_stereo/geometry/pinhole_view.h"

namespace exocet_stereo {
namespace geometry {

/// One measured pixel of point `point` in camera `camera`.
struct BaObservation {
  int camera = 0;
  int point = 0;
  Eigen::Vector2d pixel = Eigen::Vector2d::Zero();
};

/// The unknowns (initial values, refined in place) and the measurements.
struct BaProblem {
  /// Cameras (K, R, t). In rig mode cameras 2s and 2s+1 are the left and right cameras of station s; the right
  /// cameras' poses only initialise the shared rig transform (from station 0).
  std::vector<PinholeView> cameras;
  std::vector<Eigen::Vector3d> points;  ///< world points
  std::vector<BaObservation> observations;
};

enum class RobustLoss { kNone, kHuber, kCauchy };

/// Settings. validate() lists every bad field with its allowed range.
struct BundleAdjustmentConfig {
  RobustLoss loss = RobustLoss::kHuber;
  double loss_scale_px = 1.0;       ///< where the robust loss departs from quadratic, (0, 100]
  bool refine_intrinsics = false;   ///< refine fx, fy, cx, cy; cameras with identical K share one block
  bool shared_rig = false;          ///< rig mode (see BaProblem::cameras); needs an even number of cameras
  bool refine_rig = true;           ///< rig mode: refine the rig rotation and the direction of its baseline
  bool fix_scale = true;            ///< hold the first baseline length (independent cameras; rig mode always does)
  bool compute_covariance = false;  ///< per-camera 6x6 covariance of (rotation vector, centre)
  int max_iterations = 100;         ///< Levenberg-Marquardt iterations, [1, 1000]
  int threads = 1;                  ///< Ceres threads, [1, 16]

  std::string validate() const;
};

/// Outcome of one adjustment.
struct BaReport {
  bool converged = false;
  int gauge_camera = -1;  ///< the camera held constant
  int scale_camera = -1;  ///< the camera whose distance to the gauge camera is held (-1: none, rig or fix_scale off)
  std::string message;    ///< Ceres' termination summary
  int iterations = 0;
  double initial_rms_px = 0.0;  ///< RMS reprojection error over all observations, before
  double final_rms_px = 0.0;    ///< and after
  /// Per camera, when asked: 6x6 covariance of (rotation vector, centre), world units and radians; zero for the
  /// held first camera and for right cameras in rig mode (their pose follows the left one and the rig).
  std::vector<Eigen::Matrix<double, 6, 6>> camera_covariance;
  bool covariance_ok = false;
  Eigen::Matrix3d rig_R = Eigen::Matrix3d::Identity();  ///< rig mode: right-from-left rotation
  Eigen::Vector3d rig_t = Eigen::Vector3d::Zero();      ///< and translation
};

/**
 * @brief Adjusts problem.cameras and problem.points in place.
 * @throws std::invalid_argument if the config is invalid, an observation references a missing camera or point, or
 * rig mode is asked with an odd number of cameras.
 */
BaReport bundleAdjust(BaProblem& problem, const BundleAdjustmentConfig& config = BundleAdjustmentConfig());

/// Reprojection error (pixels) of every observation with the current cameras and points (infinity behind a camera).
std::vector<double> reprojectionErrors_px(const BaProblem& problem);

}  // namespace geometry
}  // namespace exocet_stereo
