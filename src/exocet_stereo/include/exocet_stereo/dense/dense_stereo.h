/**
 * @file dense_stereo.h
 * @brief Dense stereo correspondence on rectified pairs: the five methods of Scharstein & Szeliski's taxonomy
 *        (shiftable-window SSD, dynamic programming, scanline optimisation, graph cuts, Bayesian diffusion), an
 *        SGM-style multi-direction variant of scanline optimisation, OpenCV's StereoSGBM as a baseline and PatchMatch
 *        Stereo with slanted support windows ("pm", patchmatch_stereo.h).
 *
 * Every method returns a CV_32F disparity map of the LEFT image (x_right = x_left - d), NaN where unknown, and shares
 * the same optional post-processing (left-right consistency check, hole filling, median filter), so comparisons are
 * fair.
 */
#pragma once

#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

namespace exocet_stereo {
namespace dense {

/// Parameters shared by all methods (each method reads the fields it needs). Costs are in "cost units": one unit is
/// one differing census bit; see cost_volume.h. validate() lists every bad field with its allowed range.
struct DenseStereoConfig {
  // --- Search range ---
  int max_disparity_px = 15;  ///< disparities searched are 0..max_disparity_px (inclusive), [1, 512]

  // --- Matching cost (census + colour + gradient, see cost_volume.h) ---
  int census_radius_px = 2;           ///< census window (2r+1)^2, at most 48 bits: [1, 3]
  double census_weight = 0.5;         ///< per differing census bit, [0, 10]
  double color_weight = 0.25;         ///< per grey level of mean absolute colour difference, [0, 10]
  double color_truncation = 30.0;     ///< absolute colour difference saturates here (grey levels), [1, 255]
  double gradient_weight = 0.5;       ///< per grey level of horizontal gradient difference, [0, 10]
  double gradient_truncation = 12.0;  ///< gradient difference saturates here (grey levels), [1, 255]
  int aggregation_radius_px = 0;      ///< box aggregation of the cost for the global methods (0: none), [0, 15]

  // --- Shiftable-window SSD (method "ssd") ---
  int window_radius_px = 3;  ///< SSD window (2r+1)^2; shifting searches the same size, [1, 15]

  // --- Smoothness (so / sgm / gc / bd / sgbm) ---
  double penalty_small = 10.0;  ///< P1: disparity change of 1 px (SO/SGM, SGBM), [0, 1000]
  double penalty_large =
      60.0;  ///< P2: larger jumps (SO/SGM), Potts/linear weight scale for GC, >= penalty_small, <= 10000
  double contrast_threshold = 12.0;  ///< grey-level step above which smoothness is weakened (edges), [0, 255]
  double contrast_factor = 3.0;      ///< smoothness divided by this across a contrast step, [1, 100]
  int smoothness_truncation_px = 2;  ///< GC truncated-linear smoothness min(|dp - dq|, T); T = 1 is Potts, [1, 64]
  int sgm_paths = 8;                 ///< SGM directions of method "sgm": 2, 4 or 8 (method "so" uses one scanline)

  // --- Dynamic programming (method "dp") ---
  double occlusion_cost = 10.0;     ///< per occluded pixel (left or right), [0, 1000]
  double dp_vertical_weight = 0.2;  ///< weight of the previous line's disparity (smooths streaks), [0, 10]

  // --- Graph cuts (method "gc") ---
  int gc_cycles = 3;  ///< alpha-expansion cycles over all labels (stops earlier when no label improves), [1, 10]

  // --- Bayesian diffusion (method "bd") ---
  int bd_iterations = 30;                ///< diffusion iterations, [1, 500]
  double bd_temperature = 8.0;           ///< cost -> probability: p ~ exp(-cost / T), [0.1, 1000]
  double bd_outlier_probability = 0.02;  ///< robust prior: mass spread uniformly over all disparities, [0, 0.5]
  double bd_neighbour_weight = 0.25;     ///< weight of each of the 4 neighbours' messages, [0, 1]

  // --- PatchMatch Stereo with slanted windows (method "pm", Bleyer, Rhemann & Rother, BMVC 2011) ---
  int pm_window_radius_px = 17;  ///< adaptive-weight support window (2r+1)^2 (35x35 in the paper), [1, 30]
  int pm_window_step_px = 1;     ///< use every n-th window row and column (2: ~4x faster, coarser), [1, 4]
  double pm_gamma = 10.0;        ///< support weight exp(-|I_p - I_q|_1 / gamma), L1 over 3 channels, [0.1, 255]
  double pm_alpha = 0.9;         ///< cost = (1 - alpha) min(colour, tau_col) + alpha min(gradient, tau_grad), [0, 1]
  double pm_tau_color = 10.0;    ///< truncation of the L1 colour difference (grey levels summed over 3 ch.), [0.1, 765]
  double pm_tau_gradient = 2.0;  ///< truncation of the L1 x/y gradient difference (grey levels / px), [0.1, 255]
  int pm_iterations = 3;         ///< propagation iterations, each over both views, [1, 20]
  double pm_min_weight = 1e-4;   ///< window pixels of smaller support weight are skipped (0: exact), [0, 0.1]
  int pm_seed = 1;               ///< random initialisation and refinement draws (results do not depend on threads)

  // --- Post-processing (applied identically for every method; "pm" fills holes from planes, see its header) ---
  bool subpixel = true;                  ///< parabola fit on the method's final cost around the winner
  bool left_right_check = true;          ///< invalidate pixels whose right-view disparity disagrees
  double left_right_tolerance_px = 1.0;  ///< allowed |d_left - d_right|, [0, 10]
  bool fill_holes = true;          ///< fill unknown pixels from the lower (background) of the nearest valid neighbours
  int fill_median_radius_px = 7;   ///< then re-estimate filled pixels by a colour-weighted median (0: off), [0, 30]
  double fill_color_sigma = 10.0;  ///< colour distance (grey levels per channel) of weight 1/e, (0, 255]
  int median_radius_px = 1;        ///< median filter (2r+1)^2 after filling (0: none), [0, 5]

  /// Empty if usable, otherwise every bad field with its allowed range, separated by "; ".
  std::string validate() const;
  /// Number of disparity labels (max_disparity_px + 1).
  int labelCount() const { return max_disparity_px + 1; }
};

/**
 * @brief A dense stereo matcher. compute() takes a rectified pair (CV_8UC1 or CV_8UC3, same size, width >
 *        max_disparity_px) and returns the left disparity (CV_32F, NaN where unknown).
 */
class DenseStereo {
 public:
  explicit DenseStereo(const DenseStereoConfig& config);
  virtual ~DenseStereo() = default;

  /// Left disparity after the configured post-processing. @throws std::invalid_argument on bad images.
  /// Virtual so that a method whose post-processing needs more than disparities (planes of "pm") can replace it.
  virtual cv::Mat compute(const cv::Mat& left, const cv::Mat& right) const;

  /// Method name as accepted by create().
  virtual std::string name() const = 0;
  const DenseStereoConfig& config() const { return config_; }

  /// Empty if the pair is usable, otherwise what is wrong (types, sizes, width versus disparity range).
  std::string checkImages(const cv::Mat& left, const cv::Mat& right) const;

 protected:
  /**
   * @brief Raw disparities of both views before the shared post-processing. Sub-pixel refinement (if enabled) is the
   *        method's job since it needs its final cost. NaN where the method itself knows nothing.
   * @param disparity_right  nullptr when no left-right check is wanted; otherwise filled with the RIGHT view's
   *                          disparity (x_left = x_right + d).
   */
  virtual void computeRaw(const cv::Mat& left, const cv::Mat& right, cv::Mat* disparity_left,
                          cv::Mat* disparity_right) const = 0;

  DenseStereoConfig config_;
};

/// Methods create() knows: ssd, dp, so, sgm, gc, bd, sgbm, pm.
std::vector<std::string> denseStereoMethods();

/**
 * @brief Factory by method name.
 * @throws std::invalid_argument naming the unknown method (and the known ones) or config.validate()'s message.
 */
std::unique_ptr<DenseStereo> createDenseStereo(const std::string& method,
                                               const DenseStereoConfig& config = DenseStereoConfig());

/**
 * @brief Configuration tuned for one method on the four Middlebury v2 scenes (one setting for all scenes; there is no
 *        separate training set, so the figures are optimistic). Differences from the struct defaults: ssd uses a
 *        15x15 window and no weighted-median fill (real-time budget); sgm uses penalties 12 / 50 and colour weight
 *        0.4; dp and bd aggregate the cost over 3x3; gc uses a 7x7 census at full weight, truncated-linear smoothness
 *        (T = 3, penalty_large 80), two expansion cycles and no left-right check (its occlusion handling is better
 *        without: 1.9 % versus 3.4 % nonocc on Tsukuba, and it halves the run time); pm keeps the paper's settings
 *        (pm_* defaults) with the paper's weighted median of the filled pixels over 35x35 (fill_median_radius_px 17)
 *        and no final median (its filling tells occlusions from mismatches: see patchmatch_stereo.h).
 */
DenseStereoConfig defaultConfigFor(const std::string& method, int max_disparity_px);

}  // namespace dense
}  // namespace exocet_stereo
