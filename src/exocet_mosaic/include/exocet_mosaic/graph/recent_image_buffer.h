/**
 * @file recent_image_buffer.h
 * @brief The images of the last seconds by stamp, bounded in age, count and bytes: the loop closer's feeder makes a
 * key frame when the image's motion arrives from the registration, and takes the image kept for that stamp then. A
 * 4K camera's JPEGs (about 1.3 MB each) at 25 frames/s would otherwise hold hundreds of MB. No ROS.
 */
#pragma once

#include <cmath>
#include <cstddef>
#include <map>
#include <optional>
#include <utility>

namespace exocet_mosaic {
namespace graph {

/// Limits of a RecentImageBuffer.
struct RecentImageBufferLimits {
  double max_age_s = 10.0;          ///< images older than the newest by more than this go
  std::size_t max_images = 250;     ///< at most this many
  std::size_t max_bytes = 64000000;  ///< and at most this many bytes (the newest image is kept whatever its size)
};

/**
 * @brief Images (any handle, e.g. a message pointer) by stamp, with their size in bytes; the oldest go first when a
 * limit is passed. Not thread-safe.
 */
template <typename Image>
class RecentImageBuffer {
 public:
  explicit RecentImageBuffer(const RecentImageBufferLimits& limits) : limits_(limits) {}

  /// Keeps `image` (of `bytes`) under `stamp_s`, replacing one of the same stamp, then lets the oldest go.
  void add(double stamp_s, Image image, std::size_t bytes) {
    auto& slot = images_[stamp_s];
    bytes_ -= slot.second;
    slot = {std::move(image), bytes};
    bytes_ += bytes;
    const double newest_s = images_.rbegin()->first;
    while (images_.size() > 1 && (images_.begin()->first < newest_s - limits_.max_age_s ||
                                  images_.size() > limits_.max_images || bytes_ > limits_.max_bytes)) {
      bytes_ -= images_.begin()->second.second;
      images_.erase(images_.begin());
    }
  }

  /// The image kept for `stamp_s` (within tolerance_s); nullopt when it is not (never came, or already gone).
  std::optional<Image> find(double stamp_s, double tolerance_s = 1e-4) const {
    const auto it = images_.lower_bound(stamp_s - tolerance_s);
    if (it == images_.end() || std::abs(it->first - stamp_s) > tolerance_s) return std::nullopt;
    return it->second.first;
  }

  std::size_t size() const { return images_.size(); }
  std::size_t bytes() const { return bytes_; }

 private:
  RecentImageBufferLimits limits_;
  std::map<double, std::pair<Image, std::size_t>> images_;
  std::size_t bytes_ = 0;
};

}  // namespace graph
}  // namespace exocet_mosaic
