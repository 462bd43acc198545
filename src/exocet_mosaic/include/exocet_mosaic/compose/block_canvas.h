/**
 * @file block_canvas.h
 * @brief A sparse, unbounded canvas of float accumulators (sum of w * I per channel and sum of w) in square blocks
 * allocated on demand, so that memory follows the covered area, not the bounding box of a winding track.
 */
#pragma once

#include <cstddef>
#include <cstdint>
#include <unordered_map>

#include <opencv2/core.hpp>

namespace exocet_mosaic {
namespace compose {

/// Sparse block canvas; canvas pixel coordinates may be negative.
class BlockCanvas {
 public:
  /// @param channels 1 or 3; @param block_size_px side of a block, [16, 4096].
  BlockCanvas(int channels, int block_size_px);

  /**
   * @brief Adds an image placed with its top-left pixel at canvas pixel top_left.
   * @param image CV_8UC(channels); @param weight CV_32F of the same size, 0 = no data.
   * @param replace false: accumulate w * I and w; true: where weight > 0.5, overwrite (last image wins).
   */
  void accumulate(const cv::Mat& image, const cv::Mat& weight, const cv::Point& top_left, bool replace);

  /**
   * @brief Same with the weight in the last channel of image_alpha (CV_8UC(channels + 1), weight = alpha / 255):
   * one warp of a 4-channel image costs about half of two warps (image, then float weight).
   */
  void accumulateAlpha(const cv::Mat& image_alpha, const cv::Point& top_left, bool replace);

  /// Bounding box of the pixels that received a positive weight (canvas px); empty if none.
  cv::Rect dataBounds() const { return data_bounds_; }

  /**
   * @brief The normalised canvas over region, downscaled by scale (<= 1) per block for previews.
   * @param image output CV_8UC(channels); @param mask output CV_8UC1, 255 where data.
   */
  void render(const cv::Rect& region, cv::Mat* image, cv::Mat* mask, double scale = 1.0) const;

  /// Sum of weights over region (CV_32F), 0 where no block: for tests and seam analyses.
  cv::Mat weights(const cv::Rect& region) const;

  std::size_t memoryBytes() const { return blocks_.size() * block_bytes_; }
  std::size_t blockCount() const { return blocks_.size(); }
  int channels() const { return channels_; }
  int blockSize() const { return block_size_; }
  void clear();

 private:
  static std::int64_t key(int bx, int by) {
    return (static_cast<std::int64_t>(bx) << 32) ^ static_cast<std::uint32_t>(by);
  }
  cv::Mat& block(int bx, int by);  // allocates (zeros) on demand
  const cv::Mat* findBlock(int bx, int by) const;
  template <typename Weight>
  void accumulateImpl(const cv::Mat& image, int pixel_stride, const Weight& weight, const cv::Point& top_left,
                      bool replace);
  void normalizeBlock(const cv::Mat& acc, cv::Mat* image, cv::Mat* mask) const;

  int channels_;
  int block_size_;
  std::size_t block_bytes_;
  std::unordered_map<std::int64_t, cv::Mat> blocks_;  // CV_32FC(channels + 1): sum w*I per channel, then sum w
  cv::Rect data_bounds_;
};

}  // namespace compose
}  // namespace exocet_mosaic
