/**
 * @file image_motion_truth.h
 * @brief Ground truth of the motion between two images of a simulated dive: where a pixel of one image lands in the
 * other through the seabed. What the registration's accuracy is measured against. No ROS in it.
 */
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "exocet_common/camera_model.h"
#include "exocet_mosaic/sim/seabed_texture.h"

namespace exocet_mosaic {
namespace sim {

/**
 * @brief The pixel matrix H (x_B ~ H x_A) induced by the reference seabed plane z = 0 of the local frame between two
 * camera poses (local_from_camera). Exact for a flat seabed and a camera without distortion.
 */
Eigen::Matrix3d seabedPlaneHomography(const exocet_common::CameraModel& camera, const Eigen::Isometry3d& local_from_a,
                                      const Eigen::Isometry3d& local_from_b);

/**
 * @brief Where pixel `pixel_a` of camera A lands in camera B: the ray through the pixel (distortion included) meets
 * the seabed (relief included), and the seabed point is projected into B. False if the ray misses the seabed or the
 * point is behind B.
 */
bool transferThroughSeabed(const exocet_common::CameraModel& camera, const Eigen::Isometry3d& local_from_a,
                           const Eigen::Isometry3d& local_from_b, const SeabedRelief& relief,
                           const Eigen::Vector2d& pixel_a, Eigen::Vector2d* pixel_b);

}  // namespace sim
}  // namespace exocet_mosaic
