/**
 * @file depth_map.h
 * @brief Depth from the disparity of a rectified pair (Z = f B / (d + doffs)) and back-projection of a depth map to a
 *        coloured point cloud in the world frame of a calibrated view. Input of the image mesher. No ROS.
 */
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "exocet_stereo/geometry/pinhole_view.h"

namespace exocet_stereo {
namespace mesh {

/// Geometry of a rectified pair needed to turn disparity into depth.
struct RectifiedPairGeometry {
  double focal_px = 0.0;          ///< focal length of the rectified views, (0, inf) pixels
  double baseline_m = 0.0;        ///< distance between the optical centres, (0, inf) metres
  double doffs_px = 0.0;          ///< x difference of the principal points (Middlebury "doffs"), finite
  double min_disparity_px = 0.0;  ///< d + doffs at or below this is "unknown" (points at infinity), >= 0
  /// Empty if usable, otherwise every bad field with its allowed range.
  std::string validate() const;
};

/**
 * @brief Depth map (CV_32F, metres) Z = f B / (d + doffs) from a CV_32F disparity map (NaN/inf = unknown).
 *        Pixels with an unknown disparity or d + doffs <= min_disparity_px are NaN.
 * @throws std::invalid_argument on a bad type or geometry.
 */
cv::Mat depthFromDisparity(const cv::Mat& disparity_px, const RectifiedPairGeometry& geometry);

/// Points back-projected from a depth map, with their pixel and colour.
struct PointCloud {
  std::vector<Eigen::Vector3d> points;  ///< world frame of the view
  std::vector<Eigen::Vector2d> pixels;  ///< pixel (x, y) of each point in the reference image
  std::vector<cv::Vec3b> colors;        ///< RGB, empty if no image was given
};

/**
 * @brief Back-projects every step_px-th pixel (x, y multiples of step_px) with a finite positive depth:
 *        X = R^T (Z K^-1 [x y 1]^T - t).
 * @param depth_m  CV_32F or CV_64F depth along the optical axis (NaN = unknown).
 * @param image    optional colour (CV_8UC3 BGR) or grey (CV_8UC1) image of the same size, for the colours.
 * @throws std::invalid_argument on bad types, sizes or step_px < 1.
 */
PointCloud backProjectDepth(const cv::Mat& depth_m, const geometry::PinholeView& view, const cv::Mat& image = cv::Mat(),
                            int step_px = 1);

}  // namespace mesh
}  // namespace exocet_stereo
