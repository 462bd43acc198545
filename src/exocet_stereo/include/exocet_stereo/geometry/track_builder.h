/**
 * @file track_builder.h
 * @brief Feature tracks across many images from pairwise matches, by union-find over (image, keypoint) nodes; a
 * track that holds two different keypoints of the same image is inconsistent and dropped. No ROS in it.
 */
#pragma once

#include <unordered_map>
#include <utility>
#include <vector>

namespace exocet_stereo {
namespace geometry {

/// One observation of a track: keypoint `keypoint` of image `image`.
struct TrackObservation {
  int image = 0;
  int keypoint = 0;
};

/// Union-find over the keypoints of several images.
class TrackBuilder {
 public:
  /// @param keypoint_counts number of keypoints of each image
  explicit TrackBuilder(const std::vector<int>& keypoint_counts);

  /// Links keypoint ka of image a and keypoint kb of image b.
  /// @throws std::out_of_range if an index is outside its image.
  void addMatch(int image_a, int keypoint_a, int image_b, int keypoint_b);

  /**
   * @brief The tracks with at least `min_length` observations, each sorted by image; a track with two keypoints in
   * one image is dropped (counted by inconsistentTracks()).
   */
  std::vector<std::vector<TrackObservation>> tracks(int min_length = 2);

  /// Tracks dropped by the last tracks() call for holding two keypoints of one image.
  int inconsistentTracks() const { return inconsistent_; }

 private:
  int node(int image, int keypoint) const;
  int find(int x);

  std::vector<int> offsets_;  // first node of each image
  std::vector<int> parent_;
  std::vector<int> rank_;
  int inconsistent_ = 0;
};

}  // namespace geometry
}  // namespace exocet_stereo
