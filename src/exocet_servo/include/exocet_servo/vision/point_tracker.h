/**
 * @file point_tracker.h
 * @brief Pyramidal Lucas-Kanade tracking of a set of points from image to image during the servo, with a
 * forward-backward check (a point is kept when tracking it back lands within max_fb_error_px of where it started).
 * Each point keeps the id it was given, so the caller keeps its pairing with the reference. The pyramid of the last
 * image is kept, so each image's pyramid is built once. No ROS in it.
 */
#pragma once

#include <string>
#include <vector>

#include <opencv2/core.hpp>

namespace exocet_servo {
namespace vision {

/// Tracker parameters; validate() lists the allowed ranges.
struct TrackerConfig {
  int window_px = 21;            ///< LK window side, odd, [5, 63]
  int pyramid_levels = 4;        ///< levels above the full image, [0, 8]
  int max_iterations = 30;       ///< LK iterations per level, [1, 100]
  double epsilon_px = 0.01;      ///< LK stop, (0, 1]
  double max_fb_error_px = 0.3;  ///< forward-backward distance, (0, 20]
  double border_px = 10.0;       ///< points closer to the image border are dropped, [0, 1000]
  int min_points = 40;           ///< the caller re-matches below this, [4, 100000]
  /// "" or every bad field with its allowed range ("; "-joined).
  std::string validate() const;
};

/// KLT tracker with forward-backward check.
class PointTracker {
 public:
  /// @throws std::invalid_argument with config.validate()'s message.
  explicit PointTracker(const TrackerConfig& config = TrackerConfig());

  /// Starts tracking points (pixels in image, 8-bit gray) with the given ids (same size).
  void reset(const cv::Mat& image, const std::vector<cv::Point2f>& points_px, const std::vector<int>& ids);

  /// Tracks the current points into the next image; drops the lost ones. @return the number of points kept.
  int track(const cv::Mat& next_image);

  /// Re-anchors the points on the reference image, near convergence: frame-to-frame tracking drifts and the SIFT
  /// positions of the two images disagree by ~0.1-0.3 px, which sets the servo's final error. Close to the reference
  /// pose the current image is the reference image seen through another K, K_cur K_ref^-1: an affine map (up to the
  /// remaining parallax). The map is fitted (RANSAC) to the current pairs, the reference image warped with it, and
  /// each point re-tracked from its warped reference position into the current image (forward-backward checked, at
  /// most two pyramid levels, started at the last positions). It replaces track() on that image. No intrinsics
  /// needed. Points that fail are dropped.
  /// @param reference_image the reference (8-bit gray).
  /// @param reference_px reference position of each id (indexed by id).
  /// @param current_image the new image, same size as the previous ones.
  /// @param max_affine_residual_px pairs farther than this from the fitted map are dropped (also the RANSAC
  ///        threshold).
  /// @return the number of points kept, or -1 when no affine map fits (too few pairs): the points are then unchanged.
  int anchorOnReference(const cv::Mat& reference_image, const std::vector<cv::Point2f>& reference_px,
                        const cv::Mat& current_image, double max_affine_residual_px = 3.0);

  const std::vector<cv::Point2f>& points() const { return points_; }
  const std::vector<int>& ids() const { return ids_; }
  /// True when fewer than config.min_points are tracked.
  bool needsRematch() const { return static_cast<int>(points_.size()) < config_.min_points; }
  const TrackerConfig& config() const { return config_; }

 private:
  std::vector<cv::Mat> pyramid(const cv::Mat& image) const;
  /// Keeps the points tracked forward to `forward` whose backward track lands within max_fb_error_px of `origin`,
  /// away from the border (and inliers when `inlier` is given); their ids follow them.
  void keepConsistent(const std::vector<cv::Point2f>& origin, const std::vector<cv::Point2f>& forward,
                      const std::vector<cv::Point2f>& backward, const std::vector<uchar>& status_f,
                      const std::vector<uchar>& status_b, const std::vector<uchar>* inlier);

  TrackerConfig config_;
  std::vector<cv::Mat> previous_pyramid_;
  cv::Size image_size_;
  std::vector<cv::Point2f> points_;
  std::vector<int> ids_;
};

}  // namespace vision
}  // namespace exocet_servo
