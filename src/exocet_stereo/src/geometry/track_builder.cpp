#include "exocet_stereo/geometry/track_builder.h"

#include <algorithm>
#include <numeric>
#include <stdexcept>
#include <string>

namespace exocet_stereo {
namespace geometry {

TrackBuilder::TrackBuilder(const std::vector<int>& keypoint_counts) {
  offsets_.push_back(0);
  for (int count : keypoint_counts) {
    if (count < 0) throw std::invalid_argument("TrackBuilder: keypoint counts must be >= 0");
    offsets_.push_back(offsets_.back() + count);
  }
  parent_.resize(offsets_.back());
  std::iota(parent_.begin(), parent_.end(), 0);
  rank_.assign(parent_.size(), 0);
}

int TrackBuilder::node(int image, int keypoint) const {
  if (image < 0 || image + 1 >= static_cast<int>(offsets_.size()) || keypoint < 0 ||
      keypoint >= offsets_[image + 1] - offsets_[image])
    throw std::out_of_range("TrackBuilder: keypoint " + std::to_string(keypoint) + " of image " +
                            std::to_string(image) + " does not exist");
  return offsets_[image] + keypoint;
}

int TrackBuilder::find(int x) {
  while (parent_[x] != x) {
    parent_[x] = parent_[parent_[x]];  // path halving
    x = parent_[x];
  }
  return x;
}

void TrackBuilder::addMatch(int image_a, int keypoint_a, int image_b, int keypoint_b) {
  int ra = find(node(image_a, keypoint_a)), rb = find(node(image_b, keypoint_b));
  if (ra == rb) return;
  if (rank_[ra] < rank_[rb]) std::swap(ra, rb);
  parent_[rb] = ra;
  if (rank_[ra] == rank_[rb]) ++rank_[ra];
}

std::vector<std::vector<TrackObservation>> TrackBuilder::tracks(int min_length) {
  std::unordered_map<int, std::vector<TrackObservation>> groups;
  for (size_t image = 0; image + 1 < offsets_.size(); ++image)
    for (int k = 0; k < offsets_[image + 1] - offsets_[image]; ++k) {
      const int n = offsets_[image] + k;
      const int root = find(n);
      if (root == n && parent_[n] == n && rank_[n] == 0) continue;  // never linked: a singleton
      groups[root].push_back({static_cast<int>(image), k});
    }
  inconsistent_ = 0;
  std::vector<std::vector<TrackObservation>> out;
  for (auto& [root, track] : groups) {
    if (static_cast<int>(track.size()) < min_length) continue;
    // Observations are appended image by image, so a repeated image sits next to itself.
    bool repeated = false;
    for (size_t i = 1; i < track.size(); ++i) repeated |= track[i].image == track[i - 1].image;
    if (repeated) {
      ++inconsistent_;
      continue;
    }
    out.push_back(std::move(track));
  }
  // Deterministic order regardless of the hash map.
  std::sort(out.begin(), out.end(), [](const auto& x, const auto& y) {
    return std::make_pair(x[0].image, x[0].keypoint) < std::make_pair(y[0].image, y[0].keypoint);
  });
  return out;
}

}  // namespace geometry
}  // namespace exocet_stereo
