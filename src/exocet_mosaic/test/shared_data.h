/**
 * @file shared_data.h
 * @brief Readers of the real data under ../shared/data used by tests and benchmarks.
 */
#pragma once

#include <filesystem>
#include <iomanip>
#include <sstream>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>

#include "exocet_mosaic/registration/image_undistorter.h"
#include "exocet_common/camera_model.h"

namespace exocet_mosaic {
namespace testing_data {

/**
 * The Sparus AUV frames (8-bit grey), undistorted with the dataset's camera_intrinsics.yaml when `undistort` (its
 * k1 = -0.37 moves the corners by pixels, which no homography between two frames can represent). Empty when the
 * data is missing.
 */
inline std::vector<cv::Mat> loadSparusFrames(const std::string& shared_data_dir, bool undistort) {
  std::vector<cv::Mat> frames;
  const std::string folder = shared_data_dir + "/sparus_auv";
  for (int i = 0;; ++i) {
    std::ostringstream name;
    name << folder << "/frames/frame_" << std::setw(4) << std::setfill('0') << i << ".png";
    if (!std::filesystem::exists(name.str())) break;
    frames.push_back(cv::imread(name.str(), cv::IMREAD_GRAYSCALE));
  }
  if (!undistort || frames.empty()) return frames;
  const exocet_common::CameraModel camera = exocet_common::loadCameraModelYaml(folder + "/camera_intrinsics.yaml");
  const registration::ImageUndistorter undistorter(
      cv::Size(camera.width, camera.height), {camera.fx, 0.0, camera.cx, 0.0, camera.fy, camera.cy, 0.0, 0.0, 1.0},
      camera.distortion);
  for (cv::Mat& f : frames) f = undistorter.apply(f);
  return frames;
}

}  // namespace testing_data
}  // namespace exocet_mosaic
