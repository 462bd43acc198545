/**
 * @file image_network_adjustment.h
 * @brief The images of a whole dive moved into agreement where they overlap: tie points between overlapping images
 * (patches of the two drawn on their common ground and phase-correlated, or SIFT keypoints matched where the current
 * placements predict them; RANSAC), one small similarity on the ground per image
 * (shift, rotation and scale about its centre) solved by robust linear least squares over every tie point, weak priors
 * keeping each image at the pose graph's placement. No ROS in it.
 *
 * The pose graph places each image within its navigation's error; where a return pass, a turn or a crossing overlaps
 * an earlier image, the two can still disagree by a few pixels, and the registration chain's rotation drifts inside a
 * tile. One similarity per tile (tile_network_adjustment.h) cannot remove what differs inside a tile; one per image
 * can, and the pairs of consecutive images keep each pass whole while it moves.
 */
#pragma once

#include <functional>
#include <map>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

namespace exocet_mosaic {
namespace tiles {

/// One image as placed on the ground.
struct AdjustableImage {
  std::string id;                                ///< unique
  /// The image's pixels (a file name): one image drawn in two tiles is given twice, once per tile with that tile's
  /// placement, with one source; the adjustment brings its two drawings together. Empty: the id.
  std::string source;
  double stamp_s = 0;                            ///< its time in the dive: orders the passes
  cv::Matx33d en_from_px = cv::Matx33d::eye();   ///< image px -> (E, N) in metres, one frame for every image
  cv::Size size_px;                              ///< the image's size
  double gsd_m = 0;                              ///< ground sample distance of the tiles it is drawn in (reports)
};

/// Parameters of the adjustment. validate() lists the allowed ranges.
struct ImageAdjustmentConfig {
  /// How the tie points of a pair are found: "patches", square patches of the two images drawn on their common ground,
  /// each one's offset by phase correlation (area-based: sub-pixel and not drawn by the lighting); "sift", SIFT
  /// keypoints matched where the placements predict them (feature-based).
  std::string tie_method = "patches";
  /// With "patches": side of a patch (px of the finer image), [16, 512]. Small: each patch a local tie; 128 left the
  /// sample out-and-back dive's recomposed tiles 1.9 px apart, 48 0.5 px.
  int patch_px = 48;
  double min_response = 0.2;  ///< with "patches": phase correlation peak a patch needs, [0, 1]
  int cached_images = 256;    ///< with "patches": images kept in memory while the pairs are measured, [2, 100000]
  int max_features = 2000;  ///< with "sift": keypoints per image, [50, 20000]
  /// With "sift": SIFT's contrast threshold, (0, 1]: OpenCV's 0.04 finds about 160 keypoints in a PAL image of a dim sandy seabed,
  /// too few at the edge of a footprint, where the passes overlap; 0.01 finds the 2000.
  double contrast_threshold = 0.01;
  /// Images closer in time than this are paired only with their next sequence_neighbours; images further apart in
  /// time are paired where their footprints overlap (s, (0, 1e6]). Short: the end of a lawnmower line meets the start
  /// of the next a few seconds later, in the turn.
  double same_pass_s = 3.0;
  int sequence_neighbours = 2;  ///< [1, 20]
  /// Pairs of an image with each other pass it overlaps (the largest overlaps first), [0, 50]: an image between two
  /// lines is tied to both.
  int max_cross_pairs_per_pass = 4;
  /// Common ground over the smaller footprint for a pair, (0, 1]: low, neighbouring lines of a survey overlap at the
  /// edges of their images only.
  double min_overlap_fraction = 0.05;
  /// What the placements may still disagree by (px): a keypoint's match is searched within it, a patch's offset must be
  /// within it, (0, 200].
  double search_radius_px = 12.0;
  double ratio = 0.8;  ///< with "sift": Lowe's ratio among the candidates in the radius, (0, 1]
  int min_ties = 8;    ///< tie points a pair needs, [3, 100000]
  /// RANSAC threshold of a pair's similarity between its ties (px): further ones are left out, (0, 100].
  double ransac_threshold_px = 2.0;
  double tie_sigma_px = 0.7;  ///< 1-sigma of one tie point's offset (px), (0, 100]
  /// Ties kept per pair, spread over the overlap (a pair's errors correlate: it weighs as at most this many), [3, 1e6].
  int max_ties_per_pair = 60;
  double rotation_prior_sigma_rad = 0.02;  ///< prior 1-sigma of an image's rotation, (0, 1]
  double scale_prior_sigma = 0.05;         ///< and of its scale change, (0, 1]
  /// Prior 1-sigma of an image's shift from the pose graph's placement (m), (0, 100]. The ties cannot tell a change of
  /// every image's scale about its centre from a shrinking of a group of images or the whole map; this prior, tight
  /// against the scale's, makes the first one win: the graph places the images' centres, the ties their edges and
  /// orientation. (With 0.05 m the PAL bench dive's map shrank by 1.5 %, its landmarks off by up to 0.14 m; with
  /// 0.01 m they were still 1-2 cm further off than without the adjustment.)
  double prior_sigma_m = 0.003;
  double huber_sigmas = 3.0;  ///< ties whose residual exceeds this many sigmas weigh less (Huber), (0, 100]
  /// A pair whose ties still disagree by more than this (RMS, px) after the solution is left out and the rest solved
  /// again (at most 3 times), (0, 100].
  double max_pair_rms_px = 2.0;
  /// Measure-and-solve passes, each on the drawings the previous one moved, [1, 10]: a patch's phase correlation reads
  /// a large offset short by a fraction of it (2 px read as 1.6 on the gtest's ortho-image).
  int passes = 2;
  /// Empty if usable, otherwise every bad field with its allowed range, separated by "; ".
  std::string validate() const;
};

/// A measured pair of images.
struct ImagePairTies {
  int a = -1, b = -1;       ///< indices into the images given
  bool cross_pass = false;  ///< further apart in time than same_pass_s
  /// Tie points kept (RANSAC inliers, at most max_ties_per_pair spread over the overlap): where a and where b put
  /// each on the ground (E, N in metres) before the adjustment.
  std::vector<Eigen::Vector2d> on_a_en_m, on_b_en_m;
  int matches = 0;          ///< raw ties (mutual matches, correlated patches) before RANSAC
  double before_px = 0;     ///< RMS of the ties' disagreement at the graph's placements, px of the finer image
  double after_px = 0;      ///< and after the adjustment (the last pass's ties)
  bool rejected = false;    ///< left out of the solution (after_px beyond max_pair_rms_px)
  /// Two drawings of one image (same source): ties at a grid of its pixels, held tight (0.05 px), never left out.
  bool same_image = false;
};

/// What adjustImages() found.
struct ImageAdjustment {
  /// Per image given: the move on the ground (E, N) -> (E, N) to compose after its placement (identity for the images
  /// in no pair), and its parts: shift of the image's centre, rotation (rad, counter-clockwise) and scale change.
  std::vector<cv::Matx33d> move_en;
  std::vector<Eigen::Vector2d> shift_en_m;
  std::vector<double> rotation_rad, scale_change;
  std::vector<ImagePairTies> pairs;  ///< every pair measured
  int images_with_features = 0;  ///< images read (and, with "sift", with keypoints)
  int pairs_tried = 0;
  int pairs_rejected = 0;
  int ties = 0;
  /// Largest RMS disagreement of a cross-pass pair (not rejected) before and after, px (0 without such pairs).
  double cross_before_max_px = 0, cross_after_max_px = 0;
  double shift_max_m = 0;
  double rotation_max_rad = 0;
  std::string problem;  ///< why nothing was adjusted; empty if adjusted
};

/**
 * @brief Measures every pair of overlapping images and solves one small similarity per image.
 * @param load_gray the image's pixels as 8-bit grey (empty: left out)
 */
ImageAdjustment adjustImages(const std::vector<AdjustableImage>& images,
                             const std::function<cv::Mat(const std::string& id)>& load_gray,
                             const ImageAdjustmentConfig& config = ImageAdjustmentConfig());

/**
 * @brief A placement in a frame whose origin is at `frame_origin_en_m` (a tile's ground: E - origin E, N - origin N)
 * moved by `move_en` (given in absolute E, N).
 */
cv::Matx33d movedPlacement(const cv::Matx33d& frame_from_px, const cv::Matx33d& move_en,
                           const Eigen::Vector2d& frame_origin_en_m);

}  // namespace tiles
}  // namespace exocet_mosaic
