/**
 * @file feature_track_builder.h
 * @brief KLT feature tracks through a dense image sequence, kept at key frames (every `step` frames): the point
 * matches between every pair of key frames that share tracks, the input of the self-calibration (2D3 section 3.3.1).
 * No ROS in it.
 */
#pragma once

#include <map>
#include <string>
#include <unordered_map>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

namespace exocet_mosaic {
namespace selfcal {

/// How features are found and followed. validate() names a bad field and its allowed range.
struct TrackerConfig {
  int step = 10;                     ///< a key frame every `step` frames (frames 0, step, 2 step...), >= 1
  int max_corners = 800;             ///< live tracks wanted; corners are added when fewer survive (50..20000)
  double quality_level = 0.005;      ///< goodFeaturesToTrack's corner quality, relative to the best (0, 1)
  double min_distance_px = 8.0;      ///< spacing between corners, and between a new corner and a live track (>= 1)
  int window_px = 21;                ///< Lucas-Kanade window side (odd, 5..101)
  int pyramid_levels = 3;            ///< pyramid levels above the image (0..6)
  double forward_backward_px = 0.5;  ///< a point tracked forward then back must return within this (> 0)
  double border_px = 4.0;            ///< points closer than this to the image edge are dropped (>= 0)
  int min_shared_tracks = 30;        ///< key-frame pairs sharing fewer tracks are not reported (>= 8)
  /// Re-anchor every track at each key frame to the frame it was born in (see FeatureTrackBuilder).
  bool anchor_to_birth = true;
  /// An anchored position more than this from the frame-to-frame one ends the track (> 0).
  double anchor_max_shift_px = 3.0;

  /// Empty if usable, otherwise every bad field with its allowed range, separated by "; ".
  std::string validate() const;
};

/// The matches between two key frames: point k of `points_a` and of `points_b` is one tracked seabed feature.
struct KeyFramePair {
  int key_a = 0, key_b = 0;                         ///< key-frame indices, key_a < key_b
  int frame_a = 0, frame_b = 0;                     ///< frame indices in the sequence (key index * step)
  std::vector<Eigen::Vector2d> points_a, points_b;  ///< pixels (OpenCV convention: (0, 0) = centre of top-left pixel)
  std::vector<int> track_ids;
};

/**
 * @brief Follows features frame to frame with pyramidal Lucas-Kanade (Shi-Tomasi corners, forward-backward check)
 * and remembers where every live track is at each key frame. Frames are given one at a time, so a long dive is
 * streamed, never held in memory (only the frames that live tracks were born in are kept).
 *
 * Anchoring: frame-to-frame Lucas-Kanade has a small bias per feature when the image turns (the window's texture
 * rotates); the bias has the same sign from frame to frame and accumulates, reaching pixels over a turn, which
 * ruins a fundamental matrix. At each key frame, the tracks born in an earlier frame are therefore tracked again
 * from that birth frame, warped by the homography fitted to those tracks so that its appearance matches the current
 * frame: the positions then carry one Lucas-Kanade error, not the sum of many.
 */
class FeatureTrackBuilder {
 public:
  /// @throws std::invalid_argument with config.validate()'s message.
  explicit FeatureTrackBuilder(const TrackerConfig& config);

  /**
   * @brief Tracks the live features into `gray` (CV_8UC1, same size as the first frame) and, at a key frame, records
   * their positions. @throws std::invalid_argument for an empty, non-8-bit or resized image (naming the frame).
   */
  void addFrame(const cv::Mat& gray);

  /// Every pair of key frames (a < b) sharing at least min_shared_tracks tracks, ordered by (a, b).
  std::vector<KeyFramePair> keyFramePairs() const;

  int frameCount() const { return frame_count_; }
  int keyFrameCount() const { return static_cast<int>(key_points_.size()); }
  int liveTracks() const { return static_cast<int>(live_points_.size()); }
  /// Tracks started since the beginning (each new corner starts one).
  int tracksStarted() const { return next_track_id_; }
  cv::Size imageSize() const { return image_size_; }
  const TrackerConfig& config() const { return config_; }

 private:
  void trackInto(const std::vector<cv::Mat>& pyramid);
  void anchorToBirth(const cv::Mat& gray);
  void addCorners(const cv::Mat& gray);
  /// Keeps the live tracks whose flag is set.
  void keepTracks(const std::vector<bool>& keep);

  TrackerConfig config_;
  cv::Size image_size_;
  int frame_count_ = 0;
  int next_track_id_ = 0;
  std::vector<cv::Mat> previous_pyramid_;
  std::vector<cv::Point2f> live_points_;
  std::vector<int> live_ids_;
  std::vector<int> live_birth_frames_;          ///< frame each live track was born in
  std::vector<cv::Point2f> live_birth_points_;  ///< and where
  std::map<int, cv::Mat> birth_images_;         ///< frames that live tracks were born in
  /// Per key frame: track id -> pixel.
  std::vector<std::unordered_map<int, cv::Point2f>> key_points_;
};

}  // namespace selfcal
}  // namespace exocet_mosaic
