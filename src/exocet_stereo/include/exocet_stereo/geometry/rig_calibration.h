/**
 * @file rig_calibration.h
 * @brief Stereo rig calibration from chessboard image pairs (2D4 report section 3.1.1): corners in both images,
 * cv::calibrateCamera for each camera (with the standard deviations of the intrinsics), then cv::stereoCalibrate
 * starting from those intrinsics for the right-from-left pose. OpenCV's functions are the algorithm; this file
 * chooses the flags, keeps the pairs in which both boards are found and fills a StereoRig. No ROS in it.
 */
#pragma once

#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "exocet_stereo/geometry/chessboard_detection.h"
#include "exocet_stereo/geometry/stereo_rig.h"

namespace exocet_stereo {
namespace geometry {

/// Settings. validate() lists every bad field with its allowed range.
struct RigCalibrationConfig {
  ChessboardPattern pattern;
  int min_pairs = 5;                      ///< fewer usable pairs is an error, [3, 1000]
  bool fix_intrinsics_in_stereo = false;  ///< true: stereoCalibrate keeps the per-camera intrinsics
  bool zero_tangential = false;           ///< CALIB_ZERO_TANGENT_DIST for both cameras
  bool fix_k3 = false;                    ///< CALIB_FIX_K3 for both cameras

  std::string validate() const;
};

/// What happened to each pair.
struct RigCalibrationLog {
  std::vector<std::string> used;      ///< left image names of the pairs used
  std::vector<std::string> rejected;  ///< pairs where a board was not found (with the reason)
};

/**
 * @brief Calibrates a rig from image files listed pairwise (left_paths[i] with right_paths[i]).
 * @throws std::invalid_argument on mismatched lists or an invalid config; std::runtime_error if an image cannot be
 * read, the images differ in size, or fewer than min_pairs pairs show the board in both images.
 */
StereoRig calibrateStereoRig(const std::vector<std::string>& left_paths, const std::vector<std::string>& right_paths,
                             const RigCalibrationConfig& config = RigCalibrationConfig(),
                             RigCalibrationLog* log = nullptr);

}  // namespace geometry
}  // namespace exocet_stereo
