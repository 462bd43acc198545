/**
 * @file overview_picture.h
 * @brief One north-up picture of a run's mosaics with the fused camera track drawn over them (the C++ counterpart
 * of scripts/tiles_overview, drawn from the mosaics kept in memory). No ROS in it.
 */
#pragma once

#include <vector>

#include <opencv2/core.hpp>

#include "exocet_mosaic/video/video_mosaicker.h"

namespace exocet_mosaic {
namespace video {

/**
 * @brief Pastes every mosaic at its place (later ones over earlier ones) on a north-up canvas whose larger side is
 * at most `max_side_px`, draws the track of the frames that have a fused position (green start, red end) and a 1 m
 * scale bar. Empty when there is neither a mosaic nor a position.
 */
cv::Mat drawOverview(const std::vector<MosaicThumbnail>& mosaics, const std::vector<FramePlacement>& track,
                     int max_side_px);

}  // namespace video
}  // namespace exocet_mosaic
