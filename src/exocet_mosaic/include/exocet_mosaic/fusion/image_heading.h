/**
 * @file image_heading.h
 * @brief The vehicle's heading change read from the image motion: with no attitude sensor (the 2D3 report's
 * simplest case) the operator gives the first heading and the images carry it on. No ROS in it.
 */
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace exocet_mosaic {
namespace fusion {

/**
 * @brief Change of the vehicle's yaw (radians, counter-clockwise seen from above, as an ENU yaw) between two images
 * of a camera looking (nearly) along the body's vertical axis.
 *
 * The rotation about the optical axis is the rotation part of K^-1 H K, where H maps previous-image pixels to the
 * current image; a camera looking down sees the seabed turn the opposite way to the vehicle.
 * @param pixel_matrix H, previous -> current pixels
 * @param camera_matrix K of both images
 * @param base_from_camera the camera's pose in base_link (its optical axis nearly along base_link's -z or +z)
 */
double yawChangeFromImageMotion_rad(const Eigen::Matrix3d& pixel_matrix, const Eigen::Matrix3d& camera_matrix,
                                    const Eigen::Isometry3d& base_from_camera);

}  // namespace fusion
}  // namespace exocet_mosaic
