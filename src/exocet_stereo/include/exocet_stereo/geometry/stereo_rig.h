/**
 * @file stereo_rig.h
 * @brief A calibrated stereo rig (intrinsics and distortion of both cameras, right-from-left pose, calibration
 * figures) and its YAML file, written and read with cv::FileStorage under the keys of OpenCV's stereo_calib sample
 * (M1, D1, M2, D2, R, T, E, F) so that OpenCV tools read it and we read theirs. No ROS in it.
 */
#pragma once

#include <string>

#include <opencv2/core.hpp>

namespace exocet_stereo {
namespace geometry {

/// A calibrated pair. A point X_l in left-camera coordinates is X_r = R X_l + T in the right camera.
struct StereoRig {
  cv::Size image_size;                             ///< pixels
  cv::Mat K_left, dist_left, K_right, dist_right;  ///< CV_64F 3x3 and 1xN (OpenCV distortion order)
  cv::Mat R, T;                                    ///< right-from-left, CV_64F 3x3 and 3x1 (square-size units, m)
  cv::Mat E, F;                                    ///< essential and fundamental (OpenCV's conventions)
  bool has_extrinsics = false;                     ///< R and T known (a file with M1..D2 only has none)

  double baseline_m = 0.0;              ///< |T|
  double optical_axes_angle_deg = 0.0;  ///< angle between the two optical axes
  double rms_left_px = 0.0;             ///< calibrateCamera RMS, left
  double rms_right_px = 0.0;            ///< right
  double rms_stereo_px = 0.0;           ///< stereoCalibrate RMS
  int pairs_used = 0;
  /// calibrateCamera's standard deviations (fx, fy, cx, cy, k1, k2, p1, p2, k3, ...) per camera, Nx1 CV_64F.
  cv::Mat std_intrinsics_left, std_intrinsics_right;

  /// Recomputes baseline_m and optical_axes_angle_deg from R and T.
  void updateDerived();
};

/**
 * @brief Writes the rig (OpenCV keys M1 D1 M2 D2 R T E F plus image_width, image_height, rms_*, baseline_m,
 * optical_axes_angle_deg, pairs_used, std_intrinsics_*).
 * @throws std::runtime_error if the file cannot be written.
 */
void writeStereoRig(const StereoRig& rig, const std::string& path);

/**
 * @brief Reads a rig written by writeStereoRig() or OpenCV's intrinsics.yml / extrinsics.yml style (M1..D2 are
 * required; R and T optional, has_extrinsics says whether they were present).
 * @throws std::runtime_error naming the file and the missing key.
 */
StereoRig readStereoRig(const std::string& path);

}  // namespace geometry
}  // namespace exocet_stereo
