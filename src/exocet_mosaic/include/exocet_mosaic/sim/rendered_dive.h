/**
 * @file rendered_dive.h
 * @brief A simulated dive's images held in memory with the camera's true pose for each: the input of registration
 * tests and benchmarks. No ROS in it.
 */
#pragma once

#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "exocet_common/camera_model.h"
#include "exocet_mosaic/sim/dive_description.h"

namespace exocet_mosaic {
namespace sim {

struct RenderedDive {
  exocet_common::CameraModel camera;
  std::vector<cv::Mat> gray;                         ///< CV_8UC1 images (converted from the dive's encoding)
  std::vector<double> stamps_s;                      ///< frame times
  std::vector<Eigen::Isometry3d> local_from_camera;  ///< true camera poses (local frame, seabed plane z = 0)
  std::vector<double> light_gain;                    ///< the water's light gain at each frame (dark segments < 1)
  std::vector<double> turbidity;                     ///< the water's turbidity at each frame (turbid segments > 1)
};

/// Renders every frame of the dive (dropped frames are left out) with `threads` rendering threads.
RenderedDive renderDive(const DiveDescription& dive, int threads);

/**
 * @brief renderDive() through a cache: the frames are kept in `cache_dir` under a name derived from the complete
 * description (toYaml), so a benchmark run again on the same dive skips the rendering. A missing, partial or
 * unreadable cache file is rendered again; a cache that cannot be written is only a lost speed-up.
 */
RenderedDive renderDiveCached(const DiveDescription& dive, int threads, const std::string& cache_dir);

}  // namespace sim
}  // namespace exocet_mosaic
