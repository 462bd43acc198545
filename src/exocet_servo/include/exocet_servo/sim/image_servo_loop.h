/**
 * @file image_servo_loop.h
 * @brief Image-level closed loop of the intrinsics-free servo (2D4 report 2.3-2.4): the reference (right) camera
 * renders the reference image at the reference pose; the controlled (left) camera, with other intrinsics, starts at
 * an offset pose. Each iteration renders the left image, tracks the points (KLT, point_tracker.h; SIFT re-matching
 * against the reference when too few survive, point_matcher.h), takes the points' depths from the renderer (the
 * stereo rig's role in the real system, optionally with a relative error), runs one step of control::InvariantServo
 * and integrates the camera velocity through the exponential map (as servo_simulation.h). No ROS in it.
 *
 * The point set shrinks as tracks are lost, which changes the invariant features (S_p is a mean over the set): the
 * servo's reference is then re-set to the surviving subset. When the law finds the set degenerate (e.g. only seabed
 * points left after an occlusion: a plane), the next image is matched again instead of stopping. Points on a depth
 * discontinuity (the chimney's silhouette) are left out: their patch mixes foreground and background and is no 3D
 * point.
 *
 * Accuracy: the servo converges where the current points match the reference points, so the correspondence error is
 * the final pose error. SIFT positions in the two images disagree by ~0.15 px and frame-to-frame KLT drifts, which
 * leaves ~4 mm / 0.4 deg (intrinsics unknown make the pose sensitive: pose_bound.h). Once |e| is small the points are
 * therefore re-anchored on the reference image at every iteration (PointTracker::anchorOnReference: affine-warped
 * reference, direct KLT), which brings the final error to ~0.2 mm / 0.02 deg.
 */
#pragma once

#include <functional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "exocet_servo/control/image_servo_controller.h"
#include "exocet_servo/control/invariant_servo.h"
#include "exocet_servo/sim/point_scene.h"
#include "exocet_servo/sim/vent_renderer.h"
#include "exocet_servo/vision/point_matcher.h"
#include "exocet_servo/vision/point_tracker.h"

namespace exocet_servo {
namespace sim {

/// Cameras and poses of one servoing.
struct ImageServoSetup {
  PinholeCamera reference_camera;                                       ///< takes the reference image (right)
  Eigen::Isometry3d world_T_reference = Eigen::Isometry3d::Identity();  ///< where it takes it: the target pose
  PinholeCamera controlled_camera;                                      ///< the servoed camera (left)
  Eigen::Isometry3d world_T_start = Eigen::Isometry3d::Identity();
  Eigen::Matrix3d k_estimate_reference = Eigen::Matrix3d::Identity();  ///< what the servo believes (L_hat only)
  Eigen::Matrix3d k_estimate_controlled = Eigen::Matrix3d::Identity();
};

/// Loop parameters: those of the controller (control/image_servo_controller.h); dt_s is the integration period.
using ImageServoConfig = control::ImageServoConfig;
/// Outcome of a servoing.
enum class ImageServoStatus {
  kConverged,        ///< the law's |e| fell below its threshold
  kLostTracking,     ///< too few tracked points and SIFT re-matching failed (or re-matched too often)
  kServoStopped,     ///< the law stopped otherwise (error growing, degenerate, points left the image...)
  kMaxIterations,    ///< budget spent
  kReferenceFailed,  ///< the reference image is unusable (too few keypoints)
};

/// Short name of a status ("converged", "lost tracking", ...).
std::string toString(ImageServoStatus status);

/// One iteration of the loop.
struct ImageServoIteration {
  double error_norm = 0.0;                                             ///< the law's |e|
  control::ServoStatus servo_status = control::ServoStatus::kRunning;  ///< of the law's step
  int points = 0;                                                      ///< points given to the law
  bool rematched = false;                                              ///< SIFT matching ran on this image
  bool anchored = false;        ///< the points were re-anchored on the reference image
  double control_time_s = 0.0;  ///< tracking + invariant features + law (no rendering, no SIFT, no depth lookup), wall
  /// The same, CPU time of the calling thread: the work of one core even when other processes share it (with
  /// cv::setNumThreads(1) all of it runs on the calling thread).
  double control_cpu_time_s = 0.0;
  double match_time_s = 0.0;  ///< SIFT matching when it ran
  PoseError error;            ///< to the reference pose, before the step
};

struct ImageServoResult {
  ImageServoStatus status = ImageServoStatus::kReferenceFailed;
  control::ServoStatus servo_status = control::ServoStatus::kInvalidInput;  ///< of the law's last step
  std::string message;
  int iterations = 0;
  int rematches = 0;        ///< SIFT matchings after the first
  int initial_matches = 0;  ///< SIFT matches used at the start
  Eigen::Isometry3d final_pose = Eigen::Isometry3d::Identity();
  PoseError initial_error;
  PoseError final_error;             ///< of the final pose to the reference pose
  double mean_control_time_s = 0.0;  ///< mean of control_time_s over the iterations
  double max_control_time_s = 0.0;
  double mean_control_cpu_time_s = 0.0;  ///< mean of control_cpu_time_s
  std::vector<ImageServoIteration> history;
};

/// Renders the current image of the controlled camera at a pose; `iteration` counts from 0 (lets tests alter the
/// scene, e.g. remove the object).
using CurrentImageRenderer = std::function<RenderedView(const Eigen::Isometry3d& world_T_camera, int iteration)>;

/// Runs one servoing of the controlled camera to the reference pose.
/// @param render_current overrides renderer.render(setup.controlled_camera, pose) when given; the depths still come
///        from `renderer` (the depth map of the returned view screens the discontinuities).
/// @throws std::invalid_argument when a config is invalid.
ImageServoResult runImageServo(const VentRenderer& renderer, const ImageServoSetup& setup,
                               const ImageServoConfig& config, const CurrentImageRenderer& render_current = nullptr);

}  // namespace sim
}  // namespace exocet_servo
