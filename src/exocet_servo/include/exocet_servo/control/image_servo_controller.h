/**
 * @file image_servo_controller.h
 * @brief One servoing of the intrinsics-free law on images, step by step (2D4 report 2.3-2.4): SIFT matching of the
 * current image against the reference image, KLT tracking from image to image (re-matched when too few points
 * survive), re-anchoring on the reference once close, depths from a lookup (the stereo rig's job), and one step of
 * InvariantServo per image. The caller moves the camera with the returned velocity: the simulated loop
 * (sim/image_servo_loop.h) integrates it, the servo node sends it to the arm. No ROS in it.
 *
 * The point set shrinks as tracks are lost, which changes the invariant features (S_p is a mean over the set): the
 * law's reference is then re-set to the surviving subset. When the law finds the set degenerate (e.g. only seabed
 * points left after an occlusion: a plane), the next image is matched again instead of stopping.
 */
#pragma once

#include <functional>
#include <random>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "exocet_servo/control/invariant_servo.h"
#include "exocet_servo/vision/point_matcher.h"
#include "exocet_servo/vision/point_tracker.h"

namespace exocet_servo {
namespace control {

/// Parameters of an image servoing; validate() lists the allowed ranges.
struct ImageServoConfig {
  /// The law. Its max_iterations is the servoing's iteration budget (counted by the caller); its image size is
  /// replaced by the controlled camera's; convergence_threshold on |e| as in invariant_servo.h. Defaults: |e| < 3e-4
  /// (just above the floor that the re-anchored points' jitter leaves, ~1e-4), at most 80 iterations, gain 0.3 far
  /// from the goal (keeps the first image motions trackable) rising to 0.7 near it.
  ServoConfig servo = [] {
    ServoConfig c;
    c.convergence_threshold = 3e-4;
    c.convergence_window = 6;  // or the mean of e over 6 images: after the rig's step |e| can stay at 1e-3 (noise)
    c.max_iterations = 80;
    c.gain = AdaptiveGain{0.7, 0.3, 4.0};
    return c;
  }();
  vision::MatcherConfig matcher;
  vision::TrackerConfig tracker;
  double dt_s = 1.0;                  ///< period of the velocity (integration, or command), (0, 100]
  double depth_noise_fraction = 0.0;  ///< simulation: relative depth error, fixed per point, [0, 0.5]
  unsigned seed = 1;                  ///< of the depth errors
  int max_points = 300;               ///< points given to the law (evenly thinned), [4, 100000]
  int depth_check_radius_px = 3;      ///< half-side of the window a depth lookup checks for a discontinuity, [0, 50]
  double depth_max_relative_step = 0.03;  ///< max / min depth in that window, [0, 10]
  int max_rematches = 10;                 ///< SIFT re-matchings allowed during one servoing, [0, 100000]
  /// Once the law's |e| falls below this, the points are re-anchored on the reference image at every image
  /// (PointTracker::anchorOnReference); 0 disables it. [0, 1]
  double anchor_below_error = 0.01;
  double anchor_max_residual_px = 3.0;  ///< of the affine fit, (0, 50]
  /// Match the whole image again once, when |e| first falls below this (0 disables it), [0, 1]: near the goal the
  /// current view is nearly the reference view, so SIFT finds many more pairs than across the rig's baseline at the
  /// start, and more points lower the floor of |e| (the re-anchored points' jitter averages out).
  double rematch_below_error = 0.002;
  /// A point set on which the law stalls far from the goal (|e| above rematch_below_error not falling below 0.8 x its
  /// smallest value since the last matching for this many images: after tracking losses the survivors can be too few
  /// or too bunched to drive every axis) is replaced: the whole image is matched again. 0 disables it, [0, 100000].
  int stall_rematch_images = 12;
  /// SIFT pairs are also checked in 3D: each pair's two points (back-projected with the depths and the intrinsics
  /// estimates) must follow one rigid motion, fitted by RANSAC; a pair farther from it than this fraction of its
  /// depth is an outlier (0 disables the check), [0, 1]. The epipolar RANSAC of the matcher lets through pairs that
  /// slide along their epipolar lines (repeated texture); with few points across the rig's baseline they are enough
  /// to send the servo away.
  double rigid_outlier_fraction = 0.03;
  /// "" or every bad field with its allowed range ("; "-joined).
  std::string validate() const;
};

/// Depth (m, Z in the camera frame) of the surface seen at a pixel; NaN or infinity when unknown or unusable (on a
/// depth discontinuity: a silhouette's patch mixes foreground and background and is no 3D point).
using DepthLookup = std::function<double(const Eigen::Vector2d& px)>;

/// Outcome of one image.
enum class ImageStepStatus {
  kRunning,       ///< a velocity to apply
  kConverged,     ///< the law's |e| fell below its threshold (velocity zero)
  kLostTracking,  ///< too few tracked points and SIFT re-matching failed, or re-matched too often
  kServoStopped,  ///< the law stopped otherwise (error growing, degenerate, points left the image...)
  kNoReference,   ///< step() before a usable setReference()
};
/// Short name ("running", "converged", "lost tracking", "servo stopped", "no reference").
std::string toString(ImageStepStatus status);

/// One image's step.
struct ImageStep {
  ImageStepStatus status = ImageStepStatus::kNoReference;
  ServoStatus servo_status = ServoStatus::kInvalidInput;  ///< of the law's step
  std::string message;
  Eigen::Matrix<double, 6, 1> velocity = Eigen::Matrix<double, 6, 1>::Zero();  ///< (v [m/s], omega [rad/s]), camera
  double error_norm = 0.0;                                                     ///< the law's |e|
  int points = 0;                                                              ///< points given to the law
  bool rematched = false;                                                      ///< SIFT matching ran on this image
  bool anchored = false;            ///< the points were re-anchored on the reference image
  double control_time_s = 0.0;      ///< tracking + invariant features + law (no SIFT, no depth lookup), wall
  double control_cpu_time_s = 0.0;  ///< the same, CPU time of the calling thread
  double match_time_s = 0.0;        ///< SIFT matching when it ran
};

/// A servoing, image by image. Not thread-safe.
class ImageServoController {
 public:
  /// @param k_estimate_reference, k_estimate_current what the servo believes of the intrinsics (L_hat only).
  /// @throws std::invalid_argument when the config is invalid.
  ImageServoController(const ImageServoConfig& config, const Eigen::Matrix3d& k_estimate_reference,
                       const Eigen::Matrix3d& k_estimate_current, int current_width_px, int current_height_px);

  /// Starts a servoing towards a reference image (8-bit gray) whose depths `reference_depth` gives.
  /// @return "" or why the reference is unusable (too few keypoints).
  std::string setReference(const cv::Mat& reference_image, const DepthLookup& reference_depth);

  /// One current image (8-bit gray, the controlled camera's) and its depths: the velocity to apply for dt_s.
  ImageStep step(const cv::Mat& current_image, const DepthLookup& current_depth);

  int iterations() const { return iterations_; }           ///< images stepped since setReference()
  int rematches() const { return rematches_; }             ///< SIFT matchings after the first
  int stallRematches() const { return stall_rematches_; }  ///< of which forced by a stalled law
  int initialMatches() const { return initial_matches_; }
  const ImageServoConfig& config() const { return config_; }

 private:
  std::string rematch(const cv::Mat& image, const DepthLookup& current_depth);

  ImageServoConfig config_;
  Eigen::Matrix3d k_reference_, k_current_;
  InvariantServo law_;
  vision::PointMatcher matcher_;
  vision::PointTracker tracker_;
  std::mt19937 rng_;
  std::mt19937 ransac_rng_{20261202};  // its own stream: the depth errors do not depend on the RANSAC draws
  std::normal_distribution<double> gauss_{0.0, 1.0};
  cv::Mat reference_image_;
  DepthLookup reference_depth_;
  bool have_reference_ = false;
  // Reference side of the current pairing, indexed by track id.
  std::vector<Eigen::Vector2d> ref_px_;
  std::vector<cv::Point2f> ref_px_cv_;
  std::vector<double> ref_depth_, cur_depth_factor_;
  std::vector<int> law_ids_;  ///< ids of the law's current reference set
  bool anchoring_ = false;
  bool force_rematch_ = false;
  bool rematched_near_goal_ = false;
  int iterations_ = 0, rematches_ = 0, initial_matches_ = 0, stall_rematches_ = 0;
  double best_error_since_match_ = 0.0;  ///< smallest |e| since the last matching (stall detection)
  int stalled_images_ = 0;
};

}  // namespace control
}  // namespace exocet_servo
