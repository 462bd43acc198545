/**
 * @file ground_projection.h
 * @brief Where an image lies on the seabed: the projective map (homography) between image pixels and (easting,
 * northing) on the locally planar seabed, from the fused navigation pose of the camera. No ROS in it.
 */
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <opencv2/core.hpp>

namespace exocet_mosaic {
namespace compose {

/// Where the image lies on the seabed, from the fused navigation.
struct CameraGroundPose {
  Eigen::Vector2d camera_en_m = Eigen::Vector2d::Zero();  ///< fused camera position, UTM easting/northing (m)
  Eigen::Matrix2d position_cov_m2 = Eigen::Matrix2d::Identity() * 0.01;  ///< its covariance (m^2)
  /// ENU world (x east, y north, z up) <- camera optical (x right, y down, z forward).
  Eigen::Quaterniond world_from_camera = Eigen::Quaterniond(0, 1, 0, 0);  ///< default: nadir, image top = north
  double camera_height_m = 2.5;                    ///< camera height above the (locally planar) seabed, > 0
  cv::Matx33d camera_matrix = cv::Matx33d::eye();  ///< K of the (undistorted) image
};

/**
 * @brief The homography image pixel (u, v, 1) -> ground (E - origin_E, N - origin_N, 1) on the plane
 * z = camera_z - camera_height_m (metres, relative to origin_en_m so that the matrix stays well conditioned).
 * @param pose camera pose; @param image_size image size (px), whose corners must see the plane.
 * @param origin_en_m UTM point subtracted from the ground coordinates (m).
 * @param ground_from_px output (normalised so that its (2,2) element is positive for pixels that see the plane).
 * @return false if the plane is not in front of the camera for some image corner (horizon in the image) or the
 * height is not positive.
 */
bool groundFromPixel(const CameraGroundPose& pose, const cv::Size& image_size, const Eigen::Vector2d& origin_en_m,
                     cv::Matx33d* ground_from_px);

/// The inverse map of groundFromPixel: ground (E - origin_E, N - origin_N) -> pixel. Same conditions.
bool pixelFromGround(const CameraGroundPose& pose, const cv::Size& image_size, const Eigen::Vector2d& origin_en_m,
                     cv::Matx33d* px_from_ground);

/// Applies a homography to a 2-D point (divides by the third coordinate).
Eigen::Vector2d applyHomography(const cv::Matx33d& h, const Eigen::Vector2d& p);

/// Direction (rad, counter-clockwise from east) in which the image's +x axis lies on the ground at pixel at_px: how a
/// placement orients the image's content there.
double imageXDirectionRad(const cv::Matx33d& ground_from_px, const Eigen::Vector2d& at_px);

/// Scales a homography so that its (2,2) element is 1 (when it is not ~0): keeps products of chains conditioned.
cv::Matx33d normalizeHomography(const cv::Matx33d& h);

/// Ground sample distance of the image centre at nadir: height / focal length (m per pixel).
double nativeGsd(const CameraGroundPose& pose);

/// Rounds a positive length DOWN to a preferred number (ISO 3 R'10: 1, 1.25, 1.6, 2, 2.5, 3.2, 4, 5, 6.3, 8 x 10^k),
/// GIS-friendly pixel sizes within 25 % of the native one, e.g. 0.0047 -> 0.004, 0.0036 -> 0.0032.
double roundGsdDown(double gsd_m);

}  // namespace compose
}  // namespace exocet_mosaic
