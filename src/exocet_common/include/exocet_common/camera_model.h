/**
 * @file camera_model.h
 * @brief Pinhole camera with OpenCV's plumb_bob distortion (k1, k2, p1, p2, k3), as in sensor_msgs/CameraInfo.
 */
#pragma once

#include <array>
#include <string>

#include <Eigen/Core>
#include <opencv2/core.hpp>

namespace exocet_common {

/**
 * @brief Intrinsics of one camera. Pixel (u, v) = (0, 0) is the centre of the top-left pixel (OpenCV).
 */
struct CameraModel {
  int width = 720;   ///< image width (pixels)
  int height = 576;  ///< image height (pixels)
  double fx = 0.0, fy = 0.0;  ///< focal lengths (pixels): alpha_u, alpha_v
  double cx = 0.0, cy = 0.0;  ///< principal point (pixels): u0, v0
  std::array<double, 5> distortion{{0, 0, 0, 0, 0}};  ///< k1, k2, p1, p2, k3

  /// 720x576 PAL camera with the given horizontal field of view (degrees), square pixels, centred.
  static CameraModel pal(double hfov_deg = 60.0);
  /// 1920x1080 HD camera with the given horizontal field of view (degrees).
  static CameraModel hd(double hfov_deg = 60.0);
  /// 3840x2160 4K UHD camera with the given horizontal field of view (degrees).
  static CameraModel uhd(double hfov_deg = 60.0);

  cv::Matx33d K() const { return cv::Matx33d(fx, 0, cx, 0, fy, cy, 0, 0, 1); }
  cv::Mat distortionCoeffs() const { return cv::Mat(1, 5, CV_64F, const_cast<double*>(distortion.data())).clone(); }
  bool hasDistortion() const;

  /// Projects a point in the camera's optical frame (z forward, metres) to a distorted pixel. False if z <= 0.
  bool project(const Eigen::Vector3d& p_cam, Eigen::Vector2d* pixel) const;
  /// Applies the distortion to normalised coordinates (x/z, y/z).
  Eigen::Vector2d distortNormalized(const Eigen::Vector2d& xy) const;
  /// Inverse of distortNormalized by Newton iterations (converges to 1e-12 for realistic distortion).
  Eigen::Vector2d undistortNormalized(const Eigen::Vector2d& xy_distorted) const;
  /// Normalised ray (x, y, 1) of every pixel centre, CV_32FC2 holding (x, y): the renderer's per-pixel rays.
  cv::Mat rayMap() const;

  /// Empty string if the model is usable, otherwise what is wrong (naming the field and its allowed range).
  std::string validate() const;
};

/**
 * @brief Reads a camera_calibration_parsers YAML (image_width, camera_matrix, distortion_coefficients...) or the
 * short form (image_width, image_height, K: [9], D: [4..8]). Throws std::runtime_error naming the file and field.
 */
CameraModel loadCameraModelYaml(const std::string& path);

/// Writes the camera_calibration_parsers YAML format (readable by camera_calibration_parsers::readCalibration).
void saveCameraModelYaml(const std::string& path, const CameraModel& camera, const std::string& camera_name);

}  // namespace exocet_common
