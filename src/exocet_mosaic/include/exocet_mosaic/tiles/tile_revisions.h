/**
 * @file tile_revisions.h
 * @brief Tiles that follow the pose graph: what a written tile is made of (its images on disk and where it drew
 * them), the graph's position corrections over time, how far they move a tile's images, and the tile drawn again at
 * them, per image. The live tile writer draws a tile again when its images moved by more than half a ground sample
 * distance; recompose_tiles draws every tile of a dive at the final graph. No ROS in it.
 *
 * Each image keeps the shape the registration chain gave it inside its tile; it is moved by the change of the
 * graph's correction at its own time (not one shift per tile), so that a tile crossed by a loop closure bends with
 * the graph.
 */
#pragma once

#include <array>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "exocet_mosaic/compose/image_gains.h"
#include "exocet_mosaic/compose/lighting_corrector.h"
#include "exocet_mosaic/compose/placed_image_renderer.h"
#include "exocet_mosaic/tiles/tile_raster.h"

namespace exocet_mosaic {
namespace tiles {

/// The pose graph's corrections of the fused positions (graph key frame minus the filter there) over time.
class PositionCorrectionTrack {
 public:
  /// Replaces the track. Pairs whose stamp does not increase or whose values are not finite are left out.
  /// @return how many pairs were left out
  int set(const std::vector<double>& stamps_s, const std::vector<Eigen::Vector2d>& corrections_m);
  /// Linear interpolation in time; the nearest end outside the track; zero for an empty track.
  Eigen::Vector2d at(double stamp_s) const;
  bool empty() const { return stamps_s_.empty(); }
  std::size_t size() const { return stamps_s_.size(); }
  const std::vector<double>& stamps() const { return stamps_s_; }
  const std::vector<Eigen::Vector2d>& corrections() const { return corrections_m_; }

 private:
  std::vector<double> stamps_s_;
  std::vector<Eigen::Vector2d> corrections_m_;
};

/// One image of a written tile.
struct RecordedImage {
  int frame = -1;
  double stamp_s = 0;
  std::string file;  ///< image file name in the tile records' folder (JPEG, before the lighting correction)
  int width_px = 0, height_px = 0;
  /// Image px -> ground (E - origin E, N - origin N) in metres, as the tile's first version drew it (the chain's
  /// placement, fitted to the navigation at close).
  cv::Matx33d closed_ground_from_px = cv::Matx33d::eye();
  Eigen::Vector2d closed_correction_m = Eigen::Vector2d::Zero();  ///< the graph's correction in the pose then
  /// Where the image's fused pose put its centre then (same ground frame, the correction included); none: no pose.
  std::optional<Eigen::Vector2d> closed_navigation_m;
  /// With closed_navigation_m: the direction (rad, counter-clockwise from east) in which that pose laid the image's +x
  /// axis on the ground at its centre (compose::ComposedImage::navigation_heading_rad).
  std::optional<double> closed_navigation_heading_rad;
  cv::Matx33d ground_from_px = cv::Matx33d::eye();  ///< as the tile's current version drew it
  /// Gain per channel (BGR; grey: [0]) the image is drawn with after the lighting correction: its share of the
  /// dive's gain compensation (compose::ImageGains); 1 until one is solved.
  std::array<double, 3> gain{1.0, 1.0, 1.0};
};

/// What a written tile is made of.
struct TileRecord {
  int index = -1;
  int version = 1;
  Eigen::Vector2d ground_origin_en_m = Eigen::Vector2d::Zero();
  double gsd_m = 0;
  int utm_zone = 0;
  bool northern_hemisphere = true;
  std::string local_frame;  ///< TileRaster::local_frame
  TileMetadata metadata;
  std::vector<RecordedImage> images;
  /// A similarity on the tile's ground (E - origin E, N - origin N) after the images' placements: the registration of
  /// the tile with its overlapping neighbours (applyTileAdjustment); identity until one is made.
  cv::Matx33d adjustment = cv::Matx33d::eye();
};

/// The record as JSON (the tile writer keeps one file per tile beside the images).
nlohmann::json tileRecordToJson(const TileRecord& record);
/// @throws std::invalid_argument naming the missing or bad field.
TileRecord tileRecordFromJson(const nlohmann::json& json);

/// The name a composed image is kept under: "<prefix>_<stamp ns>.jpg" (unique across restarts of the writer).
std::string recordedImageName(const std::string& prefix, double stamp_s);

/**
 * @brief Writes `image` (CV_8UC1 / CV_8UC3) as JPEG of `jpeg_quality` [50, 100] to `folder`/`name`, atomically.
 * @return empty on success, otherwise what failed (the path and the OS error, e.g. a full disk)
 */
std::string writeRecordedImage(const std::string& folder, const std::string& name, const cv::Mat& image,
                               int jpeg_quality);

/**
 * @brief Composes the tile network adjustment's move of this tile (tiles::AdjustedTile: p -> p + shift + [s -r; r s]
 * (p - centre), UTM) onto the record's adjustment: measured on the tile as currently drawn, it is a further move.
 */
void applyTileAdjustment(TileRecord* record, const Eigen::Vector2d& centre_en_m, const Eigen::Vector2d& shift_en_m,
                         double rotation_rad, double scale_change);

/// How a tile is placed again at the graph's corrections.
struct RevisionConfig {
  /// 1-sigma of an image's navigation target (m): weighs the targets against the priors below, (0, 10].
  double target_sigma_m = 0.01;
  double scale_prior_sigma = 0.002;     ///< prior 1-sigma of the tile's scale change, (0, 1]
  double rotation_prior_sigma = 0.002;  ///< and of its rotation (rad), (0, 1]
  /// Each image's residual after the tile's similarity is averaged over this many neighbouring images (odd, [1,
  /// 101]) and applied to it: the tile bends with the graph without taking each pose's noise; 0: the similarity only.
  int residual_window_images = 5;
  /// The images' orientation follows the heading sensor: each image turns about its centre by the trend along the
  /// tile (a line in time, robust least squares) of the disagreement between the chain's placement at close and its
  /// pose's heading, taken relative to mid-tile, and the similarity above moves the images' centres without turning
  /// their content. The registration chain's rotation drifts over a tile (about 18 mrad over the 120 images of the
  /// sample out-and-back dive's first tile, where the gyro drifted 4); the graph's positions say how the track turned,
  /// not how each image's content is turned. false: the content turns with the similarity (the chain's orientation
  /// kept). A tile with fewer than 3 headings keeps the chain's orientation.
  bool content_follows_heading = true;
  std::string validate() const;
};

/**
 * @brief Where the images of the tile go at the track's corrections: the chain's placement of each image (as at
 * close) moved by the similarity that best carries their centres onto their navigation targets (each image's fused
 * centre at close, moved by the change of the graph's correction at its time; priors on scale and rotation; a second
 * pass without the targets beyond 3 median residuals), then by its neighbours' mean residual. An image without a
 * target follows the similarity. No target at all: each image moves by its own correction change.
 * @return one ground_from_px per image (the record's order)
 */
std::vector<cv::Matx33d> placementsAt(const TileRecord& record, const PositionCorrectionTrack& track,
                                      const RevisionConfig& config = RevisionConfig());

/// Largest move (m) of the tile's image corners from where its current version drew them to placementsAt().
double tileDisplacementM(const TileRecord& record, const PositionCorrectionTrack& track,
                         const RevisionConfig& config = RevisionConfig());

/// A tile drawn again.
struct RevisedTile {
  TileRaster raster;       ///< empty image when nothing could be drawn
  TileRecord record;       ///< the record of the new drawing (version + 1, current placements updated)
  double moved_max_m = 0;  ///< largest image corner move
  int images_missing = 0;  ///< images that could not be read (left out)
  std::string problem;     ///< the last problem met, empty if none
};

/**
 * @brief Adds each image of the record to `placements` (keyed by its file) for compose::ImageGains::solve(): where it
 * lies, in UTM, at `ground_from_px` (one per image in the record's order; empty: as the current version drew it), and
 * the gain the lighting correction gives its blocks (`lighting` null or not ready: none).
 */
void addImagePlacements(const TileRecord& record, const std::vector<cv::Matx33d>& ground_from_px,
                        const compose::LightingCorrector* lighting, const cv::Size& grid,
                        std::map<std::string, compose::ImagePlacement>* placements);

/// The image (8-bit, 1 or 3 channels) times a gain per channel, saturated; other images unchanged.
cv::Mat withGain(const cv::Mat& image, const std::array<double, 3>& gain);

/**
 * @brief Draws the tile's images at the given placements (one ground_from_px per image, the record's order; the
 * record's current ones for a tile drawn again only for its images' gains), read from `images_dir`, on the same GSD
 * grid; `prepare` and the gains as renderTileAt().
 */
RevisedTile renderTileWith(const TileRecord& record, const std::vector<cv::Matx33d>& placements,
                           const std::string& images_dir, compose::PlacedImageRenderConfig render,
                           const std::function<cv::Mat(const cv::Mat&)>& prepare = nullptr);

/**
 * @brief Draws the tile at placementsAt(), the images read from `images_dir`, on the same GSD grid.
 * @param render blending; its gsd_m is replaced by the record's.
 * @param prepare applied to each image read before it is drawn (the lighting correction); none: drawn as read.
 * Each image is then multiplied by its RecordedImage::gain.
 */
RevisedTile renderTileAt(const TileRecord& record, const PositionCorrectionTrack& track, const std::string& images_dir,
                         compose::PlacedImageRenderConfig render, const RevisionConfig& config = RevisionConfig(),
                         const std::function<cv::Mat(const cv::Mat&)>& prepare = nullptr);

}  // namespace tiles
}  // namespace exocet_mosaic
