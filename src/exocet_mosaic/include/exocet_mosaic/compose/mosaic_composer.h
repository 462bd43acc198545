/**
 * @file mosaic_composer.h
 * @brief Live mosaic composition (2D3 report, sections 2-4): each incoming image is composed into the open mosaic at
 * its place, every N images (or at an extent / memory limit, or a navigation jump) the mosaic is closed and handed
 * out geo-referenced. No ROS in it.
 *
 * Placement: LOCAL precision from the registration chain, GLOBAL position from the fused navigation. Within a mosaic,
 * C_i (frame i px -> first frame px) is the product of the registration homographies; the local ground frame is
 * L_i = P_first o C_i (P_first: ground projection of the first image's fused pose). The canvas is north-up in that
 * local frame. At close, a 2-D similarity (or translation) S: local -> UTM is fitted by weighted, Huber-robust least
 * squares between L_i(image centre) and the fused ground points P_i(image centre) of every image of the mosaic (the
 * centre rather than the nadir: it is inside the image however the camera is tilted, and the pose's attitude is
 * accounted for). The fused positions' errors are correlated over many images (a filter's), so the N images of a
 * mosaic weigh together as a few (navigation_samples_per_mosaic, 4) independent fused positions, not N. S's translation goes into
 * the tile's origin; its rotation/scale are applied (one resampling) only when they move the tile's corners by more
 * than resample_threshold_px.
 *
 * Consecutive mosaics share one image. The next mosaic's fit follows where the closed one put that image (a 3 x 3
 * grid of its points, together one position known within tile_continuity_sigma_m), so that the navigation's errors
 * do not misalign neighbouring tiles; each tile moves towards the navigation by 4 s^2 / (4 s^2 + sigma^2) of their
 * disagreement (s the slack, sigma the fused 1-sigma): the navigation holds the chain of tiles globally over about
 * (sigma / 2 s)^2 tiles, the chain holds it meanwhile (its anchor_sigma_m accounts for the closed tile's uncertainty
 * that the tie carries over). After a navigation jump or a flush the next mosaic starts untied.
 */
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "exocet_mosaic/compose/composer_config.h"
#include "exocet_mosaic/compose/ground_projection.h"

namespace exocet_mosaic {
namespace compose {

/// One image handed to the composer.
struct ComposerFrame {
  int index = -1;      ///< frame number (for the tile's metadata)
  double stamp_s = 0;  ///< acquisition time (s)
  cv::Mat image;       ///< CV_8UC3 BGR or CV_8UC1, undistorted
  /// Instead of `image`, for images costly to decode (compressed streams): called only for the images the composer
  /// draws (key frames, a mosaic's first and last) or samples for the lighting, at most once per frame, with the
  /// reduction the composer draws it at (ComposerConfig::max_image_reduction). It gives image_channels channels,
  /// either at image_size (the composer reduces it) or already reduced (between floor and ceil of image_size /
  /// reduction: a scaled JPEG decode, see image_reduction.h); if it throws or gives another shape, the frame is
  /// skipped and the problem reported in the stats.
  std::function<cv::Mat(int reduction)> load_image;
  cv::Size image_size;     ///< with load_image
  int image_channels = 0;  ///< with load_image: 1 or 3
  /// Registration: previous frame's px -> this frame's px; empty = failed / none.
  std::optional<cv::Matx33d> current_from_previous_px;
  std::optional<CameraGroundPose> pose;  ///< fused pose at this image; empty = not available
};

/// An image of a closed mosaic and where it was drawn.
struct ComposedImage {
  int index = -1;      ///< frame number
  double stamp_s = 0;  ///< acquisition time (s)
  /// CV_8UC3 or CV_8UC1, the mosaic's channels, undistorted, BEFORE the lighting correction: a tile drawn again later
  /// corrects it with the lighting field as it is then (lightingSnapshot()), the field of the dive's first minutes
  /// being the least settled. At the resolution it was composed at (1/reduction of the camera's).
  cv::Mat image;
  int reduction = 1;  ///< the camera's pixels per pixel of `image`, per axis (image_reduction.h)
  /// Pixel of `image` -> ground (E - ground_origin E, N - ground_origin N) in metres, as the tile placed it.
  cv::Matx33d ground_from_px = cv::Matx33d::eye();
  /// Where the image's own fused pose puts its centre (same ground frame); empty when it had no pose or its pose was
  /// left out of the tile's fit (an outlier).
  std::optional<Eigen::Vector2d> navigation_m;
  /// With navigation_m: the direction (rad, counter-clockwise from east) in which the image's own pose lays its +x
  /// axis on the ground at its centre. The chain's placement drifts in rotation over a tile; the heading sensor's
  /// does not as much (tiles::placementsAt).
  std::optional<double> navigation_heading_rad;
};

/// A closed, geo-referenced mosaic.
struct ClosedMosaic {
  cv::Mat image;  ///< CV_8UC3 (or CV_8UC1 if the inputs were grey), north-up: x east, y south
  cv::Mat mask;   ///< CV_8UC1, 255 where data
  double origin_easting_m = 0, origin_northing_m = 0;  ///< UTM of the top-left corner of the top-left pixel
  double gsd_m = 0;                                    ///< pixel size (m)
  int first_frame = -1, last_frame = -1, frames_added = 0, frames_composed = 0;
  double start_time_s = 0, end_time_s = 0;
  double mean_camera_height_m = 0;  ///< over the images with a pose
  std::string close_reason;         ///< "frames" | "extent" | "memory" | "navigation_jump" | "flush"
  std::vector<std::array<Eigen::Vector2d, 4>> footprints_en_m;    ///< corners of each composed image, UTM
  Eigen::Vector2d anchor_correction_m = Eigen::Vector2d::Zero();  ///< shift the fused positions applied (at the tile
                                                                  ///< centre) to the chain placement
  double anchor_sigma_m = 0;  ///< 1-sigma (per axis) of the tile's global position after that fit
  bool resampled = false;     ///< the fit's rotation/scale were applied by resampling
  std::string blend;          ///< blending actually used
  /// With ComposerConfig::keep_composed_images: the images drawn into the tile, in order, so that the tile can be
  /// drawn again at other poses (tiles that follow a pose graph, re-composition after the dive).
  std::vector<ComposedImage> images;
  Eigen::Vector2d ground_origin_en_m = Eigen::Vector2d::Zero();  ///< UTM origin of the images' ground_from_px
};

/// Counters and state of the composer, for diagnostics.
struct ComposerStats {
  std::int64_t frames_added = 0;             ///< images given to add()
  std::int64_t frames_composed = 0;          ///< composed into a canvas (key frames and last images)
  std::int64_t frames_skipped_no_pose = 0;   ///< no mosaic open and no pose to start one
  std::int64_t frames_skipped_no_chain = 0;  ///< neither registration to the previous image nor a pose
  std::int64_t registration_fallbacks = 0;   ///< chain bridged with the pose
  std::int64_t navigation_jumps = 0;
  int mosaics_closed = 0;
  std::size_t open_memory_bytes = 0;  ///< canvas + kept key frames of the open mosaic
  double open_extent_m = 0;           ///< larger of the open mosaic's east / north extents
  int open_frames = 0;                ///< images added to the open mosaic
  bool lighting_ready = false;
  int image_reduction = 1;  ///< the reduction images are composed at now (ComposerConfig::max_image_reduction)
  std::string last_problem;  ///< last skipped image or jump, in words
};

/**
 * @brief Composes images into mosaics and closes them into geo-referenced tiles. Not thread-safe: call from one
 * thread (or guard).
 */
class MosaicComposer {
 public:
  /// Throws std::invalid_argument with config.validate()'s text.
  explicit MosaicComposer(const ComposerConfig& config);
  ~MosaicComposer();
  MosaicComposer(const MosaicComposer&) = delete;
  MosaicComposer& operator=(const MosaicComposer&) = delete;

  /**
   * @brief Adds an image; returns the mosaic it closed, if any (the image then also starts the next mosaic, so that
   * consecutive tiles overlap by at least one image; after a navigation jump the image starts the next mosaic only).
   */
  std::optional<ClosedMosaic> add(const ComposerFrame& frame);

  /// Closes the open mosaic (shutdown, end of a line); nullopt if none is open.
  std::optional<ClosedMosaic> flush(const std::string& reason = "flush");

  /// The open mosaic, downscaled so that its larger side is at most max_side_px, BGR; empty when nothing is open.
  cv::Mat preview(int max_side_px) const;

  ComposerStats stats() const;

  /**
   * @brief Live reconfigure: frames_per_mosaic, limits, blending, key frames and lighting take effect at once, the
   * geometric fields (gsd_m, anchor, block size...) from the next mosaic. Throws std::invalid_argument.
   */
  void setConfig(const ComposerConfig& config);
  const ComposerConfig& config() const { return config_; }

  /// The lighting corrector (its field, for diagnostics and tests).
  const LightingCorrector& lighting() const;
  /// A deep copy of the lighting corrector, for another thread; with the lighting correction disabled, one that is
  /// never ready (its correct() returns the image unchanged).
  LightingCorrector lightingSnapshot() const;

 private:
  // drawn: the frame's image at 1/reduction of image_size; continued: tied to the mosaic just closed.
  void startMosaic(const ComposerFrame& frame, const cv::Mat& drawn, int reduction, const cv::Size& image_size,
                   bool continued);
  std::optional<ClosedMosaic> closeMosaic(const std::string& reason);

  struct Impl;
  ComposerConfig config_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace compose
}  // namespace exocet_mosaic
