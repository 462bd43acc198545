/**
 * @file placed_image_renderer.h
 * @brief Draws images at given ground placements onto one north-up raster: how a tile is drawn again when its
 * images' poses change (live tiles that follow the pose graph, re-composition of a dive from its final graph). The
 * blending is the live composer's (feather weights, or multi-band). No ROS in it.
 */
#pragma once

#include <array>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

namespace exocet_mosaic {
namespace compose {

/// An image and where it lies on the ground.
struct PlacedImage {
  cv::Mat image;  ///< CV_8UC3 (BGR) or CV_8UC1, as it is to be drawn (undistorted, lighting-corrected)
  /// Image px -> ground (E - origin E, N - origin N), metres, origin the renderer's origin_en_m.
  cv::Matx33d ground_from_px = cv::Matx33d::eye();
};

/// What renderPlacedImages() drew.
struct PlacedRaster {
  cv::Mat image;  ///< CV_8UC(channels), north-up; empty when nothing could be drawn
  cv::Mat mask;   ///< CV_8UC1, 255 where data
  double origin_easting_m = 0, origin_northing_m = 0;  ///< top-left corner of the top-left pixel, on multiples of gsd
  double gsd_m = 0;
  std::vector<std::array<Eigen::Vector2d, 4>> footprints_en_m;  ///< each drawn image's corners (UTM)
  int images_drawn = 0;
  std::string problem;  ///< why an image was left out (the last one), empty if none
};

/// How to draw.
struct PlacedImageRenderConfig {
  double gsd_m = 0.005;          ///< pixel side (m), > 0
  std::string blend = "feather";  ///< "feather" | "multiband" | "none" (the last image drawn wins)
  double feather_power = 1.0;    ///< (0, 10]
  int multiband_bands = 5;       ///< [1, 10]
  int block_size_px = 256;       ///< canvas blocks, [16, 4096]

  /// Empty if usable, otherwise every bad field with its allowed range, separated by "; ".
  std::string validate() const;
};

/**
 * @brief Draws the images, in order, at their placements. Pixel edges lie on multiples of gsd_m in UTM (so that
 * versions of a tile and neighbouring tiles share one grid). Images of a channel count other than the first one's
 * are converted to it; a degenerate placement leaves the image out (PlacedRaster::problem).
 * @throws std::invalid_argument with config.validate()'s message.
 */
PlacedRaster renderPlacedImages(const std::vector<PlacedImage>& images, const Eigen::Vector2d& origin_en_m,
                                const PlacedImageRenderConfig& config);

}  // namespace compose
}  // namespace exocet_mosaic
