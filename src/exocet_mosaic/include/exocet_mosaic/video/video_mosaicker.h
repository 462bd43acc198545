/**
 * @file video_mosaicker.h
 * @brief The live mosaicking chain in one process, without ROS: each frame goes through the registration front-end
 * (registration::SequenceRegistrar), the navigation fusion front-end (fusion::FusionFrontEnd, images only or with a
 * navigation table) and the mosaic composer (compose::MosaicComposer), and every closed mosaic is written as a
 * GeoTIFF tile (tiles::GeoTiffTileWriter), as registration_node, fusion_node and tile_writer_node do on topics.
 *
 * `mosaic_video` drives it from a video file and its benchmark and tests drive the same class, so that a figure
 * measures what the tool runs.
 */
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "exocet_common/camera_model.h"
#include "exocet_mosaic/compose/mosaic_composer.h"
#include "exocet_mosaic/dive/dive_import.h"
#include "exocet_mosaic/fusion/fusion_front_end.h"
#include "exocet_mosaic/registration/sequence_registrar.h"
#include "exocet_mosaic/tiles/geotiff_tile_writer.h"
#include "exocet_mosaic/video/mosaic_presets.h"

namespace exocet_mosaic {
namespace video {

/// base_link -> camera_optical of a downward camera whose image top points forward (image x to starboard): the
/// simulator's camera, and dive_import's `--camera-pose 0,0,0,180,0,-90`.
Eigen::Isometry3d downwardCameraMount();

/// Everything the chain needs. validate() names a bad field.
struct VideoMosaickerConfig {
  RegistrationPreset registration;  ///< the registration preset (the model: homography, as mosaic_chain.launch)
  TilesPreset tiles;                ///< composer and files; tiles.files.output_dir must be an existing folder
  exocet_common::CameraModel camera;  ///< intrinsics (and plumb_bob distortion) of the video's frames
  double camera_height_m = 2.5;       ///< camera height above the seabed while no altimeter speaks, (0, 1000] m
  /// Camera position of the first frame (UTM grid, or the local frame) and its 1-sigma (m). Empty: (0, 0).
  std::optional<Eigen::Vector2d> start_en_m;
  double start_sigma_m = 1.0;
  /// Vehicle heading at the first frame, ENU yaw (counter-clockwise from grid east, rad); used while no navigation
  /// attitude covers the frames. 0 when unknown (the image's top then points east).
  double start_enu_yaw_rad = 0.0;
  /// UTM zone of the tiles (1..60; 0: UPS) when local_frame is empty.
  int utm_zone = 31;
  bool northern_hemisphere = true;
  /// Non-empty: the tiles are in this local metric frame (engineering CRS, EPSG 0), not geo-referenced.
  std::string local_frame;
  Eigen::Isometry3d base_from_camera = downwardCameraMount();
  double dead_reckoning_sigma_m = 0.5;  ///< 1-sigma of a navigation row's position (m), as fusion_node's default
  /// The tiles' scale rests on a guessed focal length: said in each tile's metadata (EXOCET_SCALE_APPROXIMATE).
  bool scale_approximate = false;
  std::string dive_name;                ///< written into each tile's metadata
  int overview_max_side_px = 1200;      ///< each closed mosaic is kept downscaled to this for overview()

  std::string validate() const;
};

/// What became of one frame.
struct FramePlacement {
  int frame = 0;
  double stamp_s = 0.0;
  bool registered = false;  ///< registered against the previous frame
  bool placed = false;      ///< composed into a mosaic at a fused pose
  std::optional<Eigen::Vector2d> camera_en_m;  ///< fused camera position (empty before the filter starts)
  double sigma_m = 0.0;     ///< its 1-sigma (largest axis)
};

/// A closed mosaic kept small for the overview picture.
struct MosaicThumbnail {
  cv::Mat image, mask;  ///< north-up
  double origin_easting_m = 0.0, origin_northing_m = 0.0, gsd_m = 0.0;
};

/**
 * @brief Registers, fuses, composes and writes tiles, frame by frame. Not thread-safe.
 */
class VideoMosaicker {
 public:
  /// @throws std::invalid_argument naming the bad setting.
  explicit VideoMosaicker(const VideoMosaickerConfig& config);
  ~VideoMosaicker();

  /// Navigation rows (dive_import's NavigationTable, in its world frame) fed to the fusion as dead reckoning, depth,
  /// altitude and attitude as the frames' stamps pass them. Call before the first frame.
  void setNavigation(const std::vector<dive::NavigationRow>& rows, bool has_orientation);

  /**
   * Adds the next frame (CV_8UC3 BGR or CV_8UC1, the camera's size) taken at `stamp_s` (> 0, increasing).
   * A closed mosaic is written as a tile at once. @throws std::invalid_argument for an image of another size.
   */
  FramePlacement addFrame(const cv::Mat& image, double stamp_s);

  /// Closes the open mosaic into a last tile (end of the video, an interruption). Idempotent.
  void finish(const std::string& reason);

  const std::vector<FramePlacement>& track() const { return track_; }
  const std::vector<tiles::WrittenTile>& tilesWritten() const { return written_; }
  const std::vector<std::string>& writeErrors() const { return write_errors_; }
  const std::vector<MosaicThumbnail>& thumbnails() const { return thumbnails_; }
  int framesRead() const { return static_cast<int>(track_.size()); }
  int framesRegistered() const { return frames_registered_; }
  int framesPlaced() const { return frames_placed_; }
  compose::ComposerStats composerStats() const { return composer_->stats(); }
  const VideoMosaickerConfig& config() const { return config_; }

 private:
  void feedNavigationUpTo(double stamp_s);
  void writeTile(compose::ClosedMosaic mosaic);
  std::optional<Eigen::Quaterniond> vehicleAttitudeAt(double stamp_s) const;

  VideoMosaickerConfig config_;
  std::unique_ptr<registration::SequenceRegistrar> registrar_;
  std::unique_ptr<fusion::FusionFrontEnd> fusion_;
  std::unique_ptr<compose::MosaicComposer> composer_;
  std::unique_ptr<tiles::GeoTiffTileWriter> writer_;
  std::vector<dive::NavigationRow> navigation_;
  bool navigation_has_orientation_ = false;
  std::size_t next_navigation_ = 0;
  std::vector<FramePlacement> track_;
  std::vector<tiles::WrittenTile> written_;
  std::vector<std::string> write_errors_;
  std::vector<MosaicThumbnail> thumbnails_;
  std::vector<double> tile_fused_sigmas_m_;
  std::optional<double> last_composed_stamp_s_;
  int frames_registered_ = 0;
  int frames_placed_ = 0;
  bool finished_ = false;
};

}  // namespace video
}  // namespace exocet_mosaic
