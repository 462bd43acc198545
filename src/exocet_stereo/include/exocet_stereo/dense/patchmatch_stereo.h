/**
 * @file patchmatch_stereo.h
 * @brief "pm": PatchMatch Stereo with slanted support windows (Bleyer, Rhemann & Rother, BMVC 2011).
 *
 * Every pixel of both views carries a disparity plane d = a x + b y + c. Its cost is the adaptive-support-weight sum
 * over a (2r+1)^2 window of (1 - alpha) min(|I_q - I'_q'|_1, tau_col) + alpha min(|grad_q - grad'_q'|_1, tau_grad),
 * weights exp(-|I_p - I_q|_1 / gamma), q' = q shifted by the plane's disparity at q and sampled with linear
 * interpolation (so slanted surfaces are matched without fronto-parallel bias). Planes start random (random disparity,
 * random unit normal) and improve by spatial propagation (left/upper neighbours, then right/lower on the next
 * iteration), view propagation (each plane is offered, converted, to the pixel it matches in the other view) and
 * refinement (random perturbations of disparity and normal with ranges halved until the disparity range is < 0.1 px).
 *
 * Differences from the paper, on purpose: view propagation pushes each view's planes to the other view once before
 * that view's pass (not per pixel inside the pass); window pixels with weight below pm_min_weight are skipped; a
 * candidate's window sum stops as soon as it reaches the pixel's best cost; a window pixel whose match q' falls
 * outside the other image is compared with that image's border column (the paper does not say; a maximal cost there
 * favours any plane that keeps the window inside, which costs pixels near the image border their true plane). The scan
 * itself is the paper's sequential one, run as anti-diagonal wavefronts: a pixel only reads its two already-visited
 * neighbours, so all pixels of one anti-diagonal are independent and the result equals the raster scan's exactly, for
 * any number of threads (random draws are a hash of seed, view, iteration and pixel).
 *
 * Post-processing (compute()): left-right check; regions of fewer than 12 pixels that no neighbour's plane continues
 * (within 0.7 px) are invalidated too (isolated wrong planes that pass the check, as in Venus' newspaper text); each
 * invalid pixel is classified as occluded or mismatched (classifyInvalidPixels(), after Hirschmueller's SGM) and takes
 * the plane of its nearest valid left or right neighbour evaluated at the pixel: the lower one if occluded (the
 * background, as in the paper); if mismatched, the one the right view confirms, else the higher one only when it
 * costs 3 % less than the lower (fillHolesFromPlanes()); then a colour-weighted median over the filled pixels, as in
 * the paper, except the mismatched ones given the higher plane. The paper fills every invalid pixel with the
 * background, which erases foreground pixels at discontinuities whose right-view disparity alone was wrong; the
 * classification keeps them. defaultConfigFor("pm") departs from the paper three more times (a left-right tolerance
 * of 0.75 px, a final 5x5 median, gradient differences truncated at 4 grey levels), each chosen on the four Middlebury
 * scenes: see dense_stereo.cpp for why. The shared flags (left_right_check, left_right_tolerance_px, fill_holes,
 * fill_median_radius_px, median_radius_px) switch the steps. Disparities are continuous by nature; with subpixel =
 * false compute() rounds them to integers (integer ground truth).
 */
#pragma once

#include <functional>
#include <string>

#include <opencv2/core.hpp>

#include "exocet_stereo/dense/dense_stereo.h"

namespace exocet_stereo {
namespace dense {

/// Per-pixel planes of both views: CV_32FC3 (a, b, c), disparity d = a x + b y + c in that view's pixel coordinates.
struct PlaneMaps {
  cv::Mat left;   ///< left view: x_right = x_left - d
  cv::Mat right;  ///< right view: x_left = x_right + d
};

/// Disparity map (CV_32F) of a plane map (CV_32FC3).
cv::Mat planeDisparity(const cv::Mat& planes);

/**
 * @brief Fill NaN pixels of `disparity` row-wise with the lower of the planes of the nearest valid pixels to the left
 *        and to the right, evaluated at the pixel and clamped to [0, max_disparity_px]; rows with no valid pixel are
 *        then filled column-wise by fillHoles().
 */
cv::Mat fillHolesFromPlanes(const cv::Mat& disparity, const cv::Mat& planes, double max_disparity_px);

/// Matching cost of the left pixel (x, y) under a plane (a, b, c); lower is better.
using PlaneCost = std::function<float(int x, int y, const cv::Vec3f& plane)>;

/**
 * @brief fillHolesFromPlanes() that tells occlusions from mismatches (`classes`, CV_8U InvalidPixelClass from
 *        classifyInvalidPixels()): an occluded pixel takes the lower of the two neighbouring planes (the background).
 *        A mismatched one (visible in both views: its own surface may be the foreground) takes, of the two
 *        neighbouring planes' disparities, the one that the right view confirms (`disparity_right` within 1 px where
 *        that disparity lands) if only one is confirmed; otherwise the higher one only if its `cost` at the pixel is
 *        below foreground_cost_ratio times the lower one's (near ties go to the background, as in the paper). Empty
 *        `classes` treat every invalid pixel as occluded (the three-argument form); an empty `disparity_right` skips
 *        the confirmation.
 * @param median_holes if not null, set to a CV_8U mask (255) of the filled pixels that the weighted median should
 *        still re-estimate: all but the mismatched pixels given the higher plane (there the right view or the cost
 *        has decided against the background, which the median would bring back).
 * @throws std::invalid_argument on types or sizes that disagree, or a foreground_cost_ratio outside (0, 1].
 */
cv::Mat fillHolesFromPlanes(const cv::Mat& disparity, const cv::Mat& planes, double max_disparity_px,
                            const cv::Mat& classes, const PlaneCost& cost, cv::Mat* median_holes,
                            const cv::Mat& disparity_right = cv::Mat(), double foreground_cost_ratio = 1.0);

/**
 * @brief Invalidate (NaN) the small regions of `disparity` that no neighbour's plane continues: 4-neighbours are
 *        connected when each one's plane, evaluated at the other, is within tolerance_px of the other's plane there
 *        (so a steep but smooth surface stays one region, unlike a disparity-difference speckle filter); connected
 *        regions of fewer than min_region_px pixels are isolated wrong planes that passed the left-right check.
 * @return the number of pixels invalidated. @throws std::invalid_argument on types or sizes that disagree.
 */
int removeSmallPlaneRegions(cv::Mat* disparity, const cv::Mat& planes, int min_region_px, double tolerance_px);

/// PatchMatch Stereo; reads the pm_* fields and max_disparity_px of the config (see the file comment).
class PatchMatchStereo : public DenseStereo {
 public:
  using DenseStereo::DenseStereo;
  std::string name() const override { return "pm"; }

  /// Left disparity after the paper's post-processing (plane-based hole filling). @throws std::invalid_argument.
  cv::Mat compute(const cv::Mat& left, const cv::Mat& right) const override;

  /// Optimised planes of both views, before any post-processing. @throws std::invalid_argument on bad images.
  PlaneMaps computePlanes(const cv::Mat& left, const cv::Mat& right) const;

  /// compute()'s post-processing of planes from computePlanes() (so that the checks and fills can be changed without
  /// optimising again). @throws std::invalid_argument on bad images or plane maps.
  cv::Mat postProcess(const cv::Mat& left, const cv::Mat& right, const PlaneMaps& planes) const;

 protected:
  void computeRaw(const cv::Mat& left, const cv::Mat& right, cv::Mat* disparity_left,
                  cv::Mat* disparity_right) const override;
};

}  // namespace dense
}  // namespace exocet_stereo
