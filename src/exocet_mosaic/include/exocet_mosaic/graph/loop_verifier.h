/**
 * @file loop_verifier.h
 * @brief Verifies a loop candidate by registering the two key frames' images across the larger viewpoint and
 * lighting change of a revisit, and measures the relative pose of the new key frame in the old one's frame, with its
 * covariance, for PoseGraph::addLoop. No ROS in it.
 *
 * Method: SIFT features (cv::SIFT) of both images, Lowe's ratio test, a homography by OpenCV's USAC MAGSAC++; then
 * acceptance tests, each refusing with a reason naming the measured value and its bound:
 *  - enough inliers, in number and as a fraction of the ratio-test matches (repetitive texture such as ripples gives
 *    many ambiguous matches of which a wrong homography keeps few);
 *  - the images overlap enough through the homography, and the inliers spread over the overlap (convex hull area /
 *    overlap area): a homography resting on one corner extrapolates badly and is how a local coincidence looks;
 *  - the seabed-to-seabed map it implies (each image's pixels put on the seabed with its own height and tilt) is
 *    close to a rigid motion: its scale near 1 (the heights are known) and its projective part small, since a
 *    downward camera over a flat seabed sees a similarity;
 *  - forward-backward consistency: the homography fitted independently from the new image to the old one, composed
 *    with the first, moves the overlap's corners by little;
 *  - the inliers' RMS symmetric transfer residual is small.
 *
 * Relative pose: each inlier is put on the seabed in its key frame's level frame (origin under the camera centre,
 * x along the key frame's yaw, y to its left, z up) using the view's tilt and height; the old and new ground points
 * of an inlier are the same seabed point, so g_old = t + R(dyaw) g_new, whose least-squares (t, dyaw) is the pose of
 * the new key frame in the old one's frame (RelativePose2d). Its covariance is sigma^2 (J^T J)^-1 of that fit, sigma
 * the residual's RMS (metres, floored at min_residual_sigma_px times the ground sample distance), with the inlier
 * count capped at max_effective_inliers (feature errors are correlated across a revisit's lighting change), plus the
 * heights' and tilts' 1-sigmas propagated by re-fitting.
 *
 * Conventions: the key frame axes are those of loop_candidates.h (x = image up, y = image left on the seabed for a
 * nadir camera; base_link x and y for the simulator's camera mount, image top forward, image x to starboard), yaw ENU
 * counter-clockwise from east.
 */
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "exocet_mosaic/graph/pose_graph.h"

namespace exocet_mosaic {
namespace graph {

/// The geometry of one key frame's image.
struct LoopView {
  Eigen::Matrix3d camera_matrix = Eigen::Matrix3d::Identity();  ///< K of the undistorted image, pixels
  cv::Size image_size;                                          ///< the image must have this size
  double camera_height_m = 2.5;                                 ///< above the seabed, > 0
  double camera_height_sigma_m = 0.0;                           ///< its 1-sigma, >= 0
  /**
   * Camera optical frame (x right, y down, z along the axis) in the key frame's level frame (x along the key
   * frame's yaw, y left, z up): the tilt, without the yaw. Default: nadir, image top along x (downwardLevelFromCamera).
   */
  Eigen::Quaterniond level_from_camera = Eigen::Quaterniond(0.0, 0.7071067811865476, -0.7071067811865476, 0.0);
  double tilt_sigma_rad = 0.0;  ///< 1-sigma of roll and pitch (each), >= 0
};

/// The nadir camera with image top along the key frame's x axis (image x to its right).
Eigen::Quaterniond downwardLevelFromCamera();

/// SIFT features of one key frame's image: computed once, matched against many.
struct LoopFeatures {
  std::vector<cv::KeyPoint> keypoints;
  cv::Mat descriptors;
  cv::Size image_size;
};

struct LoopVerifierConfig {
  int max_features = 3000;                ///< SIFT features per image, >= 0 (0: all)
  double sift_contrast_threshold = 0.02;  ///< cv::SIFT's, > 0 (lower than its 0.04 for low-contrast seabed)
  /// Subtracted from cv::SIFT's keypoint coordinates (x and y), px, [-1, 1]: OpenCV 4.6's SIFT places its keypoints
  /// 0.25 px down and right of their true position (its first octave is the image doubled by interpolation). Left
  /// in, the bias cancels between images of the same orientation but not across a 180 deg revisit: there it moves
  /// the relative pose by 2 sqrt(2) x 0.25 px (5 mm at 7.5 mm per pixel). test_loop_closure measures it.
  double sift_offset_px = 0.25;
  double ratio = 0.8;                    ///< Lowe's ratio test, (0, 1]
  double ransac_threshold_px = 2.0;      ///< MAGSAC++ inlier threshold, > 0
  int ransac_iterations = 10000;         ///< >= 1
  int min_inliers = 30;                  ///< >= 4
  double min_inlier_fraction = 0.25;     ///< of the ratio-test matches, [0, 1]
  double min_overlap_fraction = 0.15;    ///< overlap area through the homography / image area, [0, 1]
  double min_hull_fraction = 0.3;        ///< inliers' convex hull area / overlap area (new image), [0, 1]
  double max_scale_error = 0.1;          ///< |scale - 1| of the seabed-to-seabed similarity, [0, 1)
  double max_projective_px = 6.0;        ///< largest departure of that map from its similarity (pixels), > 0
  double max_forward_backward_px = 2.0;  ///< corner displacement of H_ba * H_ab over the overlap, pixels, > 0
  double max_rms_residual_px = 1.5;      ///< RMS symmetric transfer residual of the inliers, pixels, > 0
  double min_residual_sigma_px = 0.3;    ///< floor of the residual sigma in the covariance, pixels, >= 0
  int max_effective_inliers = 100;       ///< inlier count used for the covariance at most, >= 1
  std::string validate() const;          ///< "" or each bad field with its allowed range
};

/// The outcome of one verification.
struct LoopVerification {
  bool accepted = false;
  std::string reason;  ///< why refused ("" when accepted)
  /// x_new ~ homography x_old (pixels); identity when no homography was found.
  Eigen::Matrix3d homography = Eigen::Matrix3d::Identity();
  int features_old = 0, features_new = 0;
  int matches = 0;  ///< ratio-test matches
  int inliers = 0;
  double inlier_fraction = 0.0;
  double overlap_fraction = 0.0;  ///< of the new image's area
  double hull_fraction = 0.0;
  double scale = 0.0;          ///< of the seabed-to-seabed similarity
  double projective_px = 0.0;  ///< departure from it
  double forward_backward_px = 0.0;
  double rms_residual_px = 0.0;
  RelativePose2d new_in_old;                             ///< pose of the new key frame in the old one's frame
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();  ///< of (dx m, dy m, dyaw rad)
};

/**
 * @brief Verifies loop candidates by SIFT registration. Stateless between calls (thread-safe for const use).
 */
class LoopVerifier {
 public:
  /// @throws std::invalid_argument when config.validate() is not empty
  explicit LoopVerifier(const LoopVerifierConfig& config = LoopVerifierConfig());

  /// SIFT features of an 8-bit grey image. @throws std::invalid_argument on an empty or non-CV_8UC1 image
  LoopFeatures features(const cv::Mat& gray) const;

  /**
   * @brief Verifies the loop old -> new.
   * @throws std::invalid_argument naming the problem: images empty, not CV_8UC1 or not of their view's size,
   *         views with a non-finite or bad camera matrix, height, sigma or attitude, or a camera not looking down
   */
  LoopVerification verify(const cv::Mat& old_gray, const LoopView& old_view, const cv::Mat& new_gray,
                          const LoopView& new_view) const;
  /// As above, from features computed once per key frame.
  LoopVerification verify(const LoopFeatures& old_features, const LoopView& old_view, const LoopFeatures& new_features,
                          const LoopView& new_view) const;

  const LoopVerifierConfig& config() const { return config_; }

 private:
  LoopVerifierConfig config_;
};

/// Checks a view (and that an image of `image_size` matches it when non-empty). @throws std::invalid_argument
void checkLoopView(const LoopView& view, const char* which);

}  // namespace graph
}  // namespace exocet_mosaic
