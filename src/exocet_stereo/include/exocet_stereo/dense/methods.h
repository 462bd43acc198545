/**
 * @file methods.h
 * @brief The concrete dense stereo methods (create them with createDenseStereo() by name).
 */
#pragma once

#include <string>

#include "exocet_stereo/dense/cost_volume.h"
#include "exocet_stereo/dense/dense_stereo.h"

namespace exocet_stereo {
namespace dense {

/**
 * @brief "ssd": shiftable-window SSD. Squared colour differences box-filtered over (2r+1)^2, then the minimum over
 *        all windows containing the pixel (a min filter of the aggregated cost), winner-take-all. The right view's
 *        costs are the same volume sheared, so the left-right check is almost free.
 */
class SsdStereo : public DenseStereo {
 public:
  using DenseStereo::DenseStereo;
  std::string name() const override { return "ssd"; }

 protected:
  void computeRaw(const cv::Mat& left, const cv::Mat& right, cv::Mat* disparity_left,
                  cv::Mat* disparity_right) const override;
};

/// Base of the methods that optimise over the census cost volume: runs solve() on the left and right volumes.
class VolumeStereo : public DenseStereo {
 public:
  using DenseStereo::DenseStereo;

  /// Disparity of the view whose volume and grey image are given (sub-pixel if configured).
  virtual cv::Mat solve(const CostVolume& volume, const cv::Mat& gray) const = 0;

 protected:
  void computeRaw(const cv::Mat& left, const cv::Mat& right, cv::Mat* disparity_left,
                  cv::Mat* disparity_right) const override;
};

/**
 * @brief "dp": dynamic programming per scanline with an explicit occlusion model (Cox / Ohta-Kanade style
 *        three-move DP in the disparity-space image): left-occluded pixels step the disparity up one per pixel,
 *        right occlusions jump it down, each occluded pixel costs occlusion_cost; the ordering constraint holds.
 *        Occluded pixels are NaN (filled by the shared hole filling if enabled).
 */
class DpStereo : public VolumeStereo {
 public:
  using VolumeStereo::VolumeStereo;
  std::string name() const override { return "dp"; }
  cv::Mat solve(const CostVolume& volume, const cv::Mat& gray) const override;
};

/**
 * @brief "so" (paths = 1): Scharstein-Szeliski scanline optimisation, the exact 1D minimum per scanline of
 *        data + P1/P2 smoothness (no occlusion model). "sgm" (paths 2/4/8): the same smoothness aggregated along
 *        several directions and summed (Hirschmüller's semi-global matching), winner-take-all.
 */
class ScanlineStereo : public VolumeStereo {
 public:
  ScanlineStereo(const DenseStereoConfig& config, bool semi_global) : VolumeStereo(config), semi_global_(semi_global) {}
  std::string name() const override { return semi_global_ ? "sgm" : "so"; }
  cv::Mat solve(const CostVolume& volume, const cv::Mat& gray) const override;

 private:
  bool semi_global_;
};

/**
 * @brief "gc": alpha-expansion graph cuts (Boykov-Veksler-Zabih) on the 4-connected grid with truncated-linear
 *        smoothness w_pq * min(|dp - dq|, T) (T = smoothness_truncation_px; T = 1 is Potts), w_pq = penalty_large / T
 *        (so the largest jump costs penalty_large), divided by contrast_factor across grey-level steps. Each expansion
 *        is a Boost.Graph Boykov-Kolmogorov max-flow on integer capacities; an expansion is kept only if it lowers the
 *        energy. Starts from winner-take-all; stops after gc_cycles cycles or a cycle without improvement.
 */
class GraphCutStereo : public VolumeStereo {
 public:
  using VolumeStereo::VolumeStereo;
  std::string name() const override { return "gc"; }
  cv::Mat solve(const CostVolume& volume, const cv::Mat& gray) const override;
};

/**
 * @brief "bd": Bayesian diffusion (after Scharstein & Szeliski 1998): costs become per-pixel disparity
 *        probabilities; each iteration multiplies the data likelihood with the 4 neighbours' current distributions
 *        diffused through a robust smoothness prior (most mass at the same disparity, some at +-1, a uniform
 *        outlier floor), renormalised; the final winner maximises the posterior.
 */
class BayesianDiffusionStereo : public VolumeStereo {
 public:
  using VolumeStereo::VolumeStereo;
  std::string name() const override { return "bd"; }
  cv::Mat solve(const CostVolume& volume, const cv::Mat& gray) const override;
};

/// "sgbm": cv::StereoSGBM (MODE_HH) baseline; disparities below its minimum become NaN.
class SgbmStereo : public DenseStereo {
 public:
  using DenseStereo::DenseStereo;
  std::string name() const override { return "sgbm"; }

 protected:
  void computeRaw(const cv::Mat& left, const cv::Mat& right, cv::Mat* disparity_left,
                  cv::Mat* disparity_right) const override;
};

}  // namespace dense
}  // namespace exocet_stereo
