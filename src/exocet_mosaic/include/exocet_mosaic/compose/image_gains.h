/**
 * @file image_gains.h
 * @brief Gains of a dive's images solved together over every overlap, as OpenCV's stitcher GainCompensator (Brown &
 * Lowe 2007) solves its images', but on coarse ground cells and as a sparse system, so that a dive of thousands of
 * images is solved in milliseconds. One gain per image and channel: what a tile gain cannot take (a pass lit
 * differently from the next along part of a tile, the lamp's distance changing with the altitude) is taken per image.
 *
 * Each image is summarised once by the mean level of a grid of blocks (ImageLevels, from the image as kept: before
 * the lighting correction); the solve applies the lighting field as it is then, places the blocks on the ground at the
 * images' current placements, and compares images block by block within ground cells. No ROS in it.
 */
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

namespace exocet_mosaic {
namespace compose {

/// An image's levels: the mean of each block of a grid, before any correction.
struct ImageLevels {
  cv::Size image_size;  ///< of the image summarised
  cv::Mat block_mean;   ///< CV_32FC(channels), grid rows x grid columns
  int channels() const { return block_mean.empty() ? 0 : block_mean.channels(); }
};

/// Parameters of ImageGains. validate() lists the allowed ranges.
struct ImageGainsConfig {
  int grid_columns = 16;  ///< blocks across an image, [2, 256]
  int grid_rows = 12;     ///< blocks down an image, [2, 256]
  /// Ground cells in which blocks of two images are compared (m), [0, 100]; 0: the median block footprint.
  double cell_size_m = 0.0;
  /// 1-sigma of a cell's log level ratio between two images (texture under a coarse placement, noise), (0, 10]:
  /// 0.08 is Brown & Lowe's 10 grey levels at a mid level.
  double cell_sigma = 0.08;
  /// Prior 1-sigma of an image's log gain, weighed like the overlaps by the image's common cells (as Brown & Lowe's
  /// and OpenCV's gain compensation do), (0, 10]: the gains stay near 1 where nothing asks otherwise, and a long line
  /// of images cannot drift.
  double gain_sigma = 0.3;
  int min_common_cells = 4;  ///< fewer common cells: the pair is not used, [1, 100000]
  double max_gain = 2.0;     ///< gains clamped to [1 / max_gain, max_gain], [1, 10]
  double min_level = 4.0;    ///< blocks darker than this (grey levels) in any channel are left out, [0, 254]
  std::string validate() const;
};

/// Where an image lies and how it is lit when the gains are solved.
struct ImagePlacement {
  cv::Matx33d en_from_px = cv::Matx33d::eye();  ///< image px -> (E, N) in metres (any common frame: UTM, local)
  /// The lighting correction's gain at each block (CV_32FC(channels), the grid's size); empty: none.
  cv::Mat block_gain;
};

/// What ImageGains::solve() found.
struct ImageGainSolution {
  std::map<std::string, std::array<double, 3>> gain;  ///< per image id, per channel (BGR; grey: [0])
  int images = 0;                                     ///< images placed (fixed ones included)
  int fixed_images = 0;                               ///< of those, the ones whose gains were given
  int pairs = 0;                                      ///< pairs of images with enough common cells
  double cell_size_m = 0;
  /// Largest |mean level difference| (grey) over the pairs, before and after the gains (pairs measured on their
  /// common cells, mean over channels).
  double step_before_grey = 0, step_after_grey = 0;
  std::string problem;  ///< why nothing was solved, empty if solved
};

/**
 * @brief Summarises an image (CV_8UC1 / CV_8UC3) as the mean of each block of a grid.
 * @throws std::invalid_argument for an empty or non-8-bit image or a bad grid
 */
ImageLevels imageLevels(const cv::Mat& image, int grid_columns, int grid_rows);

/// Gains of many images over their overlaps. Not thread-safe.
class ImageGains {
 public:
  /// @throws std::invalid_argument with config.validate()'s text
  explicit ImageGains(const ImageGainsConfig& config = ImageGainsConfig());
  const ImageGainsConfig& config() const { return config_; }
  /// Adds (or replaces) an image's levels, computed with this config's grid. Levels of another channel count than
  /// the first image's, or of another grid, are refused. @return false if refused
  bool add(const std::string& id, ImageLevels levels);
  bool contains(const std::string& id) const { return levels_.count(id) > 0; }
  void remove(const std::string& id) { levels_.erase(id); }
  std::size_t size() const { return levels_.size(); }
  int channels() const { return channels_; }
  /// Memory held by the levels (bytes).
  std::size_t memoryBytes() const;

  /**
   * @brief Solves the gains of the placed images: per channel, least squares over the pairs of images with enough
   * common cells of log g_a - log g_b = the median over their common cells of log(level_b / level_a) (each pair
   * weighted by its common cells), plus the prior towards log g = 0; a sparse Cholesky solve. Images not placed, or
   * without overlap, get no entry (their gain is 1).
   * @param placements per image id; ids without levels are ignored
   * @param fixed_gains images whose gains are known (per image id, per channel): they take part in the pairs with the
   * other images as anchors but are not solved, and get no entry in the solution; pairs of two fixed images are left
   * out. A live dive solves its newest images against the gains already given to their older neighbours, so that the
   * solve's size does not grow with the dive. With every fixed gain at the value of a solve of all the images, the
   * others get the values of that solve (the least squares are the same).
   */
  ImageGainSolution solve(const std::map<std::string, ImagePlacement>& placements,
                          const std::map<std::string, std::array<double, 3>>& fixed_gains = {}) const;

 private:
  ImageGainsConfig config_;
  int channels_ = 0;
  std::map<std::string, ImageLevels> levels_;
};

}  // namespace compose
}  // namespace exocet_mosaic
