/**
 * @file klt_registrar.h
 * @brief The KLT registration method (2D3 report, 3.1): Shi-Tomasi features spread over the image, tracked by
 * pyramidal Lucas-Kanade with a forward-backward check, and a robust least-squares fit of the motion model to the
 * tracks. No ROS in it.
 *
 * Per image, registerNext() builds the image's pyramid once (each level the [1 3 3 1] binomial reduction of the one
 * below); it serves as the "current" pyramid of this pair, and as the "previous" one of the next pair. The image
 * derivatives that Lucas-Kanade needs are computed only around the points it tracks, and only on the levels it tracks
 * them on (KltConfig::derivatives_on_demand). Features live from image to image: the inlier tracks of a pair are the
 * features of the next pair, and new ones are detected (in the empty grid cells only, on a coarse pyramid level)
 * when the set thins out, so that detection is amortised over several images. The forward track starts where the
 * prediction sends the feature, the backward one where the inverse prediction sends the track: two independent
 * starts, so that a track caught in a wrong local minimum does not come back to its feature.
 *
 * Every pyramid level costs Lucas-Kanade as much as the finest one, and the coarse levels only serve to find the
 * motion that the prediction has not taken out. So with a prediction, a few features (prediction_probes) are tracked
 * on the whole pyramid first; if they confirm it (prediction_tolerance_px), the others are tracked on the finest
 * level(s) only (predicted_pyramid_levels), and, should too few of them come back (retrack_fraction), again on the
 * whole pyramid. Each backward track runs on the levels that the distance from its start to its feature calls for
 * (fb_fine_start_px).
 *
 * The pyramid reaches a few window sizes at its coarsest level: a larger motion that no prediction took out (a first
 * pair, a jerk, a frame dropped) leaves most tracks lost or wrong. A pair that fails for want of tracks or inliers,
 * or inconsistently, is then searched for globally (coarse_motion_search.h: SIFT on reduced copies, a similarity by
 * RANSAC over the whole feature sets) and tracked again from where that search puts the features.
 */
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "exocet_mosaic/registration/coarse_motion_search.h"
#include "exocet_mosaic/registration/frame_registrar.h"
#include "exocet_mosaic/registration/motion_estimate.h"
#include "exocet_mosaic/registration/motion_model.h"
#include "exocet_mosaic/registration/robust_motion_fitter.h"

namespace exocet_mosaic {
namespace registration {

/// Parameters of the KLT registration. Distances are in pixels of the full-resolution image. validate() lists the
/// allowed ranges.
struct KltConfig {
  MotionModel model = MotionModel::kSimilarity;  ///< the report's 4-parameter model by default

  // --- Feature detection (Shi-Tomasi: both eigenvalues of the gradient matrix large) ---
  int max_features = 150;            ///< [8, 5000]; at most max_features / (grid_cols * grid_rows) per grid cell
  int grid_cols = 8;                 ///< grid that spreads the features over the image, [1, 64]
  int grid_rows = 6;                 ///< [1, 64]
  double min_distance_px = 12.0;     ///< between two features, [1, 200]
  double quality_level = 0.02;       ///< a corner must reach this fraction of the strongest one, [0, 1)
  double min_eigenvalue = 2e-4;      ///< absolute floor of the smaller eigenvalue (cv::cornerMinEigenVal units), [0, 1]
  int block_size = 5;                ///< gradient window of the detector (pixels of the detection level), odd [3, 15]
  int detection_max_width_px = 240;  ///< detect on the finest pyramid level at most this wide, [64, 100000]
  int min_features = 20;             ///< fewer features in an image: too little texture, [1, max_features]
  /// Detect again when the tracked features or the grid cells holding one fall below this fraction of what the last
  /// detection left, [0, 1] (0: only when a registration failed).
  double redetect_fraction = 0.75;

  // --- Tracking (pyramidal Lucas-Kanade) ---
  int window_px = 11;            ///< side of the tracking window, odd [5, 63]
  int pyramid_levels = 3;        ///< levels including the full resolution, [1, 8]
  int lk_max_iterations = 20;    ///< per level, [1, 100]
  double lk_epsilon_px = 0.03;   ///< per level: stop when the update is smaller, (0, 1]
  double fb_threshold_px = 0.5;  ///< largest forward-backward distance of a kept track, (0, 20]
  /// With a prediction (prediction_px not the identity) that the probes confirm, the features track on this many
  /// finest levels only, [1, 8] (at most pyramid_levels): the coarse levels serve to find the motion that the
  /// prediction has not taken out, and each costs as much as the finest.
  int predicted_pyramid_levels = 1;
  /// Features (spread over the image) tracked on the whole pyramid first to check the prediction, [0, 1000]
  /// (0: the whole pyramid for every feature).
  int prediction_probes = 16;
  /// The prediction is confirmed when three quarters of the probes end up within this distance of where it sent
  /// them, (0, 100].
  double prediction_tolerance_px = 1.0;
  /// If fewer tracks than this fraction of the features (or than min_tracks) come back from the fine levels, the
  /// prediction missed all the same: they are tracked again on the whole pyramid, [0, 1].
  double retrack_fraction = 0.5;
  /// The backward track starts where the inverse prediction sends the forward track; when that start lies within
  /// fb_fine_start_px * 2^L of the feature, the backward track runs on the L finest levels only (no coarse search
  /// is needed to get back, and every level costs as much as the finest). 0: always the whole pyramid. [0, 100]
  double fb_fine_start_px = 1.5;
  /// Compute the image derivatives only around the points to track, not over whole pyramid levels: the same values
  /// (so the same tracks, bit for bit) at a fraction of the cost on large images. false: whole levels, as
  /// cv::buildOpticalFlowPyramid does.
  bool derivatives_on_demand = true;
  int min_tracks = 15;  ///< fewer tracks kept: failure kTooFewTracks, [minimal points of the model, 5000]

  // --- Robust fit and acceptance ---
  int min_inliers = 12;  ///< [minimal points of the model, 5000]
  /// Of the kept tracks, [0, 1]. Not above about a half: in turbid water the marine snow may hold half the tracks.
  double min_inlier_fraction = 0.35;
  /// A track supports a motion hypothesis of the robust fit within this distance, (0, 100]: a few times the tracking
  /// noise, so that false matches that roughly agree (snow at various depths) do not outvote the seabed.
  double consensus_threshold_px = 1.0;
  double rejection_k = 4.0;             ///< a track is struck off beyond rejection_k * sigma, [2, 20]
  double min_residual_scale_px = 0.03;  ///< floor of sigma (covariance, rejection), (0, 10]
  double max_residual_px = 1.0;         ///< larger inlier residual scale: failure kInconsistent, (0, 100]
  /// A pair whose neighbouring inliers disagree by more (RobustFit::local_scale_px) does not move as one plane,
  /// (0, 100]: on a flat seabed the tracks err alike where the model errs (lens distortion), so this stays near the
  /// tracking noise (0.1-0.2 px). With the homography model, such a pair, or one whose residual scale exceeds
  /// max_residual_px, is not refused for it: it is checked against one rigid scene (rigid_scene_check.h: the epipolar
  /// geometry within rigid_k_sigma times the tracking noise measured on its tracks). Relief passes, and the motion is
  /// refitted on the tracks of the scene (the dominant plane's, its covariance from residuals that hold the parallax);
  /// tracks that move on their own (drifting particles, fish) fail it, and so does a pair where they are too many
  /// (kInconsistent). The lower models refuse such a pair (kInconsistent): a plane's perspective, which they cannot
  /// hold, would pass as relief.
  double max_local_residual_px = 0.3;
  /// A track is on the rigid scene's epipolar geometry within this many tracking-noise sigmas, [1, 20].
  double rigid_k_sigma = 3.0;
  /// Factor on the fit's covariance, [1, 100]: the residuals do not show the errors that all tracks share
  /// (interpolation biases, blur); on the rendered benchmark dive the corner NEES says about 1.5 (homography model,
  /// the defaults), hence 1.6, slightly conservative (NEES ratio 0.94 there).
  double covariance_inflation = 1.6;
  /// An image corner moving further than this fraction of the image's smaller side: failure kMotionTooLarge, (0, 10].
  /// A third of the width with a few degrees of rotation moves a corner of a 16:10 image by about 0.6 of its height.
  double max_motion_fraction = 0.8;

  // --- Large motions ---
  /// A pair that fails with kTooFewTracks, kTooFewInliers or kInconsistent is tracked again from the motion a coarse
  /// global search finds (when it finds one that differs from the prediction); false: the first failure stands.
  bool coarse_search = true;
  CoarseSearchConfig coarse;  ///< that search's parameters

  // --- Image quality (measured on the coarsest pyramid level) ---
  double min_mean_grey = 12.0;     ///< darker on average: failure kTooDark, [0, 255]
  double min_contrast_grey = 2.0;  ///< smaller grey-level standard deviation: failure kTooDark, [0, 128]

  /// Empty if usable, otherwise every bad field with its allowed range, separated by "; ".
  std::string validate() const;
  /// The robust fitter's parameters that this configuration implies.
  RobustFitConfig fitConfig() const;
};

/// What the last registerNext() / registerPair() call did (for benchmarks and diagnostics).
struct KltDiagnostics {
  int features = 0;         ///< features of the previous image that were tracked
  int tracked = 0;          ///< tracks that converged, stayed in the image and passed the forward-backward check
  int detected = 0;         ///< new features detected in the current image (0 if there was no detection)
  double pyramid_ms = 0.0;  ///< building the current image's pyramid
  double track_ms = 0.0;    ///< forward and backward Lucas-Kanade
  double fit_ms = 0.0;      ///< robust fit
  double detect_ms = 0.0;   ///< feature detection (topping up the empty cells)
  bool prediction_trusted = false;  ///< the probes confirmed the prediction: most tracks on the fine levels only
  bool retracked = false;           ///< tracked again on the whole pyramid (KltConfig::retrack_fraction)
  double local_residual_px = 0.0;   ///< RobustFit::local_scale_px of the fit
  bool rigid_checked = false;       ///< the pair did not move as one plane and was checked for one rigid scene
  int rigid_consistent = 0;         ///< tracks on that scene's epipolar geometry
  double tracking_noise_px = 0.0;   ///< the tracking noise measured from the forward-backward distances then
  bool coarse_searched = false;     ///< the pair failed and the coarse search ran
  bool coarse_found = false;        ///< it found a motion, from which the pair was tracked again
  double coarse_ms = 0.0;           ///< its time
};

/**
 * @brief Frame-to-frame registration by feature tracking (KLT). One instance per image stream; not thread-safe.
 *
 * Failures are explicit: kTooDark (mean or contrast of either image below the thresholds), kTooLittleTexture (fewer
 * than min_features found in the previous image), kTooFewTracks, kTooFewInliers, kMotionTooLarge, kInconsistent
 * (residual scale above max_residual_px, neighbouring tracks disagreeing beyond max_local_residual_px, degenerate
 * fit), kNotConverged, kInvalidInput (type or size).
 */
class KltRegistrar : public FrameRegistrar {
 public:
  /// @throws std::invalid_argument with config.validate()'s message.
  explicit KltRegistrar(const KltConfig& config = KltConfig());

  void reset() override;
  MotionEstimate registerNext(const cv::Mat& gray,
                              const Eigen::Matrix3d& prediction_px = Eigen::Matrix3d::Identity()) override;
  MotionEstimate registerPair(const cv::Mat& previous, const cv::Mat& current,
                              const Eigen::Matrix3d& prediction_px = Eigen::Matrix3d::Identity()) override;
  RegistrationMethod method() const override { return RegistrationMethod::kKlt; }

  /**
   * Where the next image can be written so that registerNext() need not copy it (the pyramid's finest level, inside
   * its border): a CV_8UC1 image of `size`, to be filled and then passed as is to registerNext(). Any other image
   * is copied as usual. Valid until the next call of any other method.
   */
  cv::Mat nextImageBuffer(const cv::Size& size);
  const KltConfig& config() const { return config_; }
  const KltDiagnostics& lastDiagnostics() const { return diagnostics_; }
  /// Features held for the next registerNext() call (pixels of the last image).
  const std::vector<cv::Point2f>& features() const { return previous_.features; }

 private:
  /// One prepared image: its pyramid (with derivatives), its quality, its features.
  struct Frame {
    std::vector<cv::Mat> pyramid;  ///< cv::buildOpticalFlowPyramid's layout: level L image at 2L, derivatives at 2L+1
    int max_level = 0;             ///< coarsest level built
    // The images (interiors of image_buffers, which hold a reflected border), and the buffers whose interiors are
    // pyramid[2L + 1] (zero border). derivatives_on_demand: the derivatives are valid around every point of
    // `features` (and wholly on the levels flagged in complete_levels).
    std::vector<cv::Mat> images;
    std::vector<cv::Mat> image_buffers;
    std::vector<cv::Mat> derivative_buffers;
    unsigned complete_levels = 0;
    cv::Size size;
    bool usable = false;          ///< bright and contrasted enough
    std::string unusable_detail;  ///< why not
    std::vector<cv::Point2f> features;
    int detected_cells = 0;         ///< grid cells holding a feature after the last detection
    int detected_features = 0;      ///< features after the last detection
    float strongest_corner = 0.0f;  ///< largest detector response seen (reference of quality_level)
  };

  void prepare(const cv::Mat& gray, Frame* frame);
  /// The image levels of `frame` (images, image_buffers, max_level), each the [1 3 3 1] reduction of the one below.
  void buildImagePyramid(const cv::Mat& gray, Frame* frame);
  /// derivatives_on_demand: computes the derivatives around points[first...] on levels min_level ... max_level of
  /// `frame` (those that exist).
  void computeDerivatives(Frame* frame, const std::vector<cv::Point2f>& points, size_t first, int min_level,
                          int max_level);
  /// Detects features in the empty cells of `frame` (all cells if `frame` has none), keeping the existing ones.
  void topUpFeatures(Frame* frame);
  /// Whether the surviving tracks have thinned out enough to detect again.
  bool needsDetection(const Frame& frame) const;
  /// Registers `previous` (its features) to `current`, whose features it sets; both frames get derivatives. A failure
  /// for want of tracks or inliers, or an inconsistent one, is retried from a coarse search's motion.
  void estimate(Frame* previous, Frame* current, const Eigen::Matrix3d& prediction_px, MotionEstimate* result);
  /// One attempt of estimate() from `prediction_px`.
  void estimateFrom(Frame* previous, Frame* current, const Eigen::Matrix3d& prediction_px, MotionEstimate* result);
  /// Tracks the previous image's features forward into forward_ and status_, from where the prediction sends them:
  /// on the whole pyramid, or (with a prediction the probes confirm, and not whole_pyramid) mostly on the fine
  /// levels. Returns the coarsest level used.
  int trackForward(Frame* previous, const Frame& current, const Eigen::Matrix3d& prediction_px, int all_levels,
                   bool whole_pyramid, const cv::TermCriteria& criteria);
  /// Tracks to_ back from `from` to `to`, starting at backward_ (results in backward_ and back_status_), each track
  /// on as few levels as its start needs (fb_fine_start_px), at most `levels`.
  void trackBackward(Frame* from, const Frame& to, int levels, const cv::TermCriteria& criteria);
  MotionEstimate emptyEstimate(const cv::Size& size) const;

  KltConfig config_;
  RobustMotionFitter fitter_;
  cv::Size window_;
  Frame previous_, current_;
  bool has_previous_ = false;
  KltDiagnostics diagnostics_;

  // Scratch buffers, kept to avoid allocations per image.
  std::vector<cv::Point2f> forward_, backward_, from_, to_;
  std::vector<uchar> status_, back_status_, group_status_;
  std::vector<int> group_;
  std::vector<cv::Point2f> group_to_, group_start_;
  std::vector<float> probe_misses_;
  std::vector<uchar> is_probe_;
  std::vector<float> error_;
  std::vector<float> fb_;  ///< forward-backward distances of the kept tracks
  std::vector<int> kept_;
  cv::Mat eigen_;
  std::vector<cv::Rect> rois_;
  std::vector<int> cell_count_, occupancy_head_, occupancy_next_;
  struct Candidate {
    float strength;
    float x, y;
    int cell;
  };
  std::vector<Candidate> candidates_;
};

}  // namespace registration
}  // namespace exocet_mosaic
