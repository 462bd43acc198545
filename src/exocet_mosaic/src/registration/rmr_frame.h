/**
 * @file rmr_frame.h
 * @brief Internal to the RMR registration: one image prepared once (its Gaussian pyramid, its brightness statistics)
 * and, when it serves as the reference image, the pixels of each level it is registered on with what the linearised
 * optical-flow constraint needs of them. No ROS in it.
 */
#pragma once

#include <array>
#include <memory>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "exocet_mosaic/registration/motion_model.h"

namespace exocet_mosaic {
namespace registration {
namespace internal {

/// What selects the pixels of a reference level (a subset of RmrConfig, so that this file does not depend on it).
struct RmrSelectionParameters {
  MotionModel model = MotionModel::kAffine;
  double min_gradient = 2.0;     ///< |gx| + |gy| (grey levels per pixel) below which a pixel is never used
  double pixel_fraction = 0.15;  ///< share of the level's pixels kept, strongest cell maxima first
  int min_pixels = 2000;         ///< ... but at least this many (when textured enough)
  int max_pixels = 20000;        ///< ... and at most this many at `finest_level`, a quarter as many a level coarser...
  int finest_level = 0;          ///< level of the final estimate (where max_pixels applies)
  double smoothing_sigma_px = 0.0;  ///< Gaussian pre-smoothing of the full-resolution image (0: none)
};

/**
 * @brief The selected pixels of one reference level (at most one per selection cell, in the raster order of the
 * cells; structure of arrays).
 *
 * For each pixel: its level coordinates, its grey level, and its steepest-descent vector grad(I) . dW/dp at the
 * identity (model parameters in coordinates centred on the level's image of the level-0 centre), which the inverse
 * compositional iterations reuse unchanged.
 */
struct RmrLevelSelection {
  int count = 0;                   ///< selected pixels
  int textured = 0;                ///< pixels of the level with |gx| + |gy| >= min_gradient (estimated on one row
                                   ///< in each band of selection cells)
  int geometric_parameters = 0;    ///< size of each steepest-descent vector
  std::vector<float> x, y, value;  ///< count each
  std::vector<float> steepest;     ///< geometric_parameters arrays of count: [j * count + i] for pixel i
  /// Indices of the selected pixels of the neighbouring cells after each pixel's (right, down-left, down, down-right;
  /// -1: none): each neighbouring pair once, to measure the residuals' spatial correlation.
  std::vector<std::array<int, 4>> next;
};

/// An image prepared for the RMR registration. Immutable after construction except for the lazily built selections.
class RmrFrame {
 public:
  /**
   * @param gray CV_8UC1. @param levels number of pyramid levels (>= 1), level 0 being `gray` itself.
   * @param recycled a frame no longer needed whose buffers are reused: fresh large allocations cost a page fault per
   *        4 KiB on first touch, which is a large share of the registration's time in steady state.
   */
  RmrFrame(const cv::Mat& gray, int levels, const RmrSelectionParameters& selection,
           std::unique_ptr<RmrFrame> recycled = nullptr);

  int levels() const { return static_cast<int>(levels_.size()); }
  cv::Size size() const { return levels_.front().size(); }
  /// Level `level` of the Gaussian pyramid (CV_32F). Pixel x of level L sits at 2^L x of level 0 (pyrDown).
  const cv::Mat& level(int level) const { return levels_[level]; }
  /// Mean and standard deviation of the grey levels (measured on level 1 when there is one: same mean, cheaper).
  double mean() const { return mean_; }
  double stddev() const { return stddev_; }

  /// The pixels of `level` to register on when this image is the reference; built on first use.
  const RmrLevelSelection& selection(int level);

  /// Centre of the parameterisation at `level`: the level-0 centre ((w - 1) / 2, (h - 1) / 2) divided by 2^level,
  /// so that the parameters of two levels differ only by the scaling of the coordinates.
  Eigen::Vector2d centre(int level) const;

 private:
  std::vector<cv::Mat> levels_;
  std::vector<RmrLevelSelection> selections_;
  std::vector<bool> selected_;  ///< selections_[level] is built
  // Scratch of the selection, kept for reuse.
  std::vector<float> candidate_magnitude_;
  std::vector<int> histogram_;
  std::vector<int> candidate_index_, candidate_cell_, band_row_;
  std::vector<float> band_max_;
  std::vector<int> row_index_[2], row_of_[2];
  RmrSelectionParameters parameters_;
  double mean_ = 0.0;
  double stddev_ = 0.0;
};

}  // namespace internal
}  // namespace registration
}  // namespace exocet_mosaic
