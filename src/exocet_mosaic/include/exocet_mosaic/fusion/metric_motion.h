/**
 * @file metric_motion.h
 * @brief Image motion (pixels) -> displacement of the camera over the seabed (metres): the 2D3 report's metric
 * conversion (section 3.3, size of a pixel on the seabed l = h / alpha), extended with the camera's lever arm and
 * mounting and the vehicle's roll and pitch. No ROS in it.
 *
 * Frames: the world is the dive's UTM grid, ENU (x east, y north, z up, metres); base_link is x forward, y left,
 * z up; the camera optical frame has z along the optical axis (OpenCV). The seabed is locally a horizontal plane.
 */
#pragma once

#include <string>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "exocet_mosaic/registration/motion_model.h"

namespace exocet_mosaic {
namespace fusion {

/// The downward camera: its intrinsics and where it sits on the vehicle.
struct CameraMount {
  /// K of the images the motion refers to (pixels): [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (undistorted images).
  Eigen::Matrix3d camera_matrix = Eigen::Matrix3d::Identity();
  /// Camera optical frame (z along the optical axis) in base_link (x forward, y left, z up); translation = lever arm.
  Eigen::Isometry3d base_from_camera = Eigen::Isometry3d::Identity();
};

/// The view of one image, at its stamp.
struct ViewGeometry {
  /// Vehicle attitude in the ENU world (UTM grid) frame: base_link to world.
  Eigen::Quaterniond world_from_base = Eigen::Quaterniond::Identity();
  /// Height of the camera's optical centre above the (locally flat) seabed (metres, vertical), > 0.
  double camera_height_m = 0.0;
  /// 1-sigma of camera_height_m (metres, >= 0; 0 = exact): adds the scale uncertainty it causes to the
  /// displacement's covariance. The altimeter's noise is white from image to image, so it does not cancel.
  double camera_height_sigma_m = 0.0;
};

/// The camera's displacement between two images, in metres on the world grid.
struct MetricMotion {
  bool valid = false;
  std::string error;  ///< why not valid: names what is wrong
  /// Camera centre motion from the previous image to the current one (east, north), metres.
  Eigen::Vector2d camera_displacement_en_m = Eigen::Vector2d::Zero();
  /// Its covariance (m^2): the registration's parameter covariance (and the heights' sigmas) propagated.
  Eigen::Matrix2d covariance_m2 = Eigen::Matrix2d::Zero();
  /// Size of a pixel on the seabed at the previous image: camera_height_m / sqrt(fx * fy) (metres).
  double ground_sample_distance_m = 0.0;
  /// Vertical motion of the camera (current height - previous height above the seabed), metres: for information.
  double height_change_m = 0.0;
};

/**
 * @brief The report's l = h / alpha: size (metres) of one pixel on the seabed for a nadir camera at height h with
 * focal length alpha (pixels). @throws std::invalid_argument naming camera_height_m (> 0, finite) or alpha_px
 * (> 0, finite).
 */
double pixelSize_m(double camera_height_m, double alpha_px);

/**
 * @brief Height of the camera's optical centre above the seabed from an altimeter range measured along the body's
 * -z axis from `altimeter_in_base_m`, for a camera at `camera_in_base_m` (both in base_link, metres), the seabed
 * being locally a horizontal plane.
 * @throws std::invalid_argument naming range_m (finite, > 0), the attitude (finite, non-zero quaternion; the
 *         altimeter's beam must point downwards) or the resulting height (must be > 0).
 */
double cameraHeightFromAltimeter_m(double range_m, const Eigen::Quaterniond& world_from_base,
                                   const Eigen::Vector3d& altimeter_in_base_m, const Eigen::Vector3d& camera_in_base_m);

/**
 * @brief Camera displacement on the seabed from a registration estimate.
 *
 * `parameters` of `model`, centred on `centre_px`, with `parameter_covariance` in pixel units, as in
 * registration/motion_model.h and exocet_msgs/ImageMotion: the motion maps previous-image pixels to current-image
 * pixels. Method: the current image's principal point is mapped back to the previous image through the inverse
 * motion; that pixel's ray from the previous camera (its attitude, its height) meets the seabed plane at a ground
 * point; the current camera is placed so that this ground point projects onto its principal point given its own
 * attitude and height. The displacement is the difference of the two camera centres (exact for a flat seabed, an
 * undistorted camera and exact attitudes and heights). Its covariance propagates the parameter covariance through
 * a numerical Jacobian (and the heights' sigmas when given).
 *
 * The attitude's own noise is NOT added: the attitude of an image enters the pair before and the pair after it
 * with opposite signs, so its error does not accumulate along the track (it telescopes).
 *
 * Invalid (with `error`) for: a parameter vector or covariance of the wrong size or non-finite, a non-finite or
 * non-symmetric covariance, a singular motion, an invalid camera matrix, a non-finite attitude, a height <= 0 or
 * non-finite, a ray that misses the seabed (pointing at or above the horizon).
 */
MetricMotion toMetricMotion(registration::MotionModel model, const Eigen::VectorXd& parameters,
                            const Eigen::MatrixXd& parameter_covariance, const Eigen::Vector2d& centre_px,
                            const CameraMount& mount, const ViewGeometry& previous, const ViewGeometry& current);

/// Camera optical centre in the world from a base_link position and attitude: base + R * lever arm.
Eigen::Vector3d cameraPosition(const Eigen::Vector3d& base_position_m, const Eigen::Quaterniond& world_from_base,
                               const Eigen::Isometry3d& base_from_camera);

}  // namespace fusion
}  // namespace exocet_mosaic
