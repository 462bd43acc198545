/**
 * @file video_camera.h
 * @brief The camera of a video without a calibration file: self-calibration from the clip itself (Mendonca-Cipolla
 * over relief, the plane's homographies over a flat seabed), or a pinhole from a field of view when the clip cannot
 * calibrate. No ROS in it.
 */
#pragma once

#include <atomic>
#include <string>

#include <nlohmann/json.hpp>

#include "exocet_common/camera_model.h"

namespace exocet_mosaic {
namespace video {

/// Where the intrinsics came from.
struct CameraChoice {
  exocet_common::CameraModel camera;
  std::string source;              ///< "file", "selfcal" or "hfov"
  bool scale_approximate = false;  ///< the focal length is a guess (hfov): the tiles' scale is approximate
  std::string summary;             ///< one or more lines for the user (the intrinsics with their 1-sigma, or why not)
  nlohmann::ordered_json details;  ///< for the run's summary.json
};

/// A pinhole without distortion of the given size and horizontal field of view (degrees), principal point centred.
exocet_common::CameraModel pinholeFromHfov(int width_px, int height_px, double hfov_deg);

/**
 * @brief Self-calibrates from the first `max_frames` frames of a video (key frames every `step` frames), deciding
 * between the relief and the flat-seabed methods as self_calibrate does with `--planar`: Mendonca-Cipolla unless most
 * pairs are planar. When the clip cannot calibrate (too little rotation or relief, too few tracks, an unconstrained
 * result), falls back on pinholeFromHfov(hfov_deg) and says why in one line.
 * @param stop checked between frames; when set, returns the fallback with source "hfov" and summary "interrupted".
 * @throws std::runtime_error when the video cannot be read.
 */
CameraChoice selfCalibrateVideo(const std::string& video_path, int max_frames, double hfov_deg,
                                const std::atomic<bool>& stop);

}  // namespace video
}  // namespace exocet_mosaic
