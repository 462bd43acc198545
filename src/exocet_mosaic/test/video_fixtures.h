/**
 * @file video_fixtures.h
 * @brief A simulated dive rendered into a video file, with its ground truth: the input of mosaic_video's tests.
 * Header only, no ROS.
 */
#pragma once

#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "exocet_common/utm_grid.h"
#include "exocet_mosaic/sim/dive_description.h"
#include "exocet_mosaic/sim/rendered_dive.h"

namespace exocet_mosaic {
namespace testing {

/// A rendered dive written as a video, and what is true about it.
struct RenderedVideo {
  std::string path;
  exocet_common::CameraModel camera;
  double fps = 0.0;
  int frames = 0;
  std::vector<Eigen::Vector2d> camera_local_m;  ///< true camera centre of each frame (local frame: x east, y north)
  double origin_latitude_deg = 0.0, origin_longitude_deg = 0.0;
  double true_heading_deg = 0.0;  ///< the first leg's heading from true north (the description's is from grid north)
};

/**
 * @brief Writes the frames of `dive` (rendered from `description`) to `path` (MJPG in AVI, quality 95). With
 * `ping_pong_times` > 1 the frames are written forward, backward, forward... that many times (a longer clip from a
 * short rendering).
 */
inline RenderedVideo writeVideo(const sim::RenderedDive& dive, const sim::DiveDescription& description,
                                const std::string& path, int ping_pong_times = 1) {
  RenderedVideo video;
  video.path = path;
  video.camera = dive.camera;
  video.fps = description.synthesis.rig.fps;
  video.origin_latitude_deg = description.origin_latitude_deg;
  video.origin_longitude_deg = description.origin_longitude_deg;
  const exocet_common::UtmGrid grid = exocet_common::UtmGrid::forLatLon(video.origin_latitude_deg,
                                                                        video.origin_longitude_deg);
  const Eigen::Vector2d origin_en = grid.toGrid(video.origin_latitude_deg, video.origin_longitude_deg);
  video.true_heading_deg = description.synthesis.trajectory.heading_deg +
                           grid.convergence_rad(origin_en.x(), origin_en.y()) * 180.0 / M_PI;
  cv::VideoWriter writer(path, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), video.fps,
                         cv::Size(dive.camera.width, dive.camera.height), true);
  if (!writer.isOpened()) throw std::runtime_error("cannot write the video " + path);
  writer.set(cv::VIDEOWRITER_PROP_QUALITY, 95);
  const int n = static_cast<int>(dive.gray.size());
  cv::Mat bgr;
  for (int pass = 0; pass < std::max(1, ping_pong_times); ++pass) {
    for (int j = 0; j < n; ++j) {
      const int i = pass % 2 == 0 ? j : n - 1 - j;
      cv::cvtColor(dive.gray[i], bgr, cv::COLOR_GRAY2BGR);
      writer.write(bgr);
      video.camera_local_m.push_back(dive.local_from_camera[i].translation().head<2>());
      ++video.frames;
    }
  }
  return video;
}

}  // namespace testing
}  // namespace exocet_mosaic
