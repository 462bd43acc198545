/**
 * @file acquisition_bag.h
 * @brief Reads the bag of exocet_servo's acquisition_sequencer_node: at each stop, at one stamp, left|right
 * image_raw, camera_info and pose (geometry_msgs/PoseStamped, the camera in the arm's base frame).
 */
#pragma once

#include <string>
#include <vector>

#include "exocet_stereo/mesh/pair_depth.h"

namespace exocet_stereo {

/// The complete stops of the bag as calibrated pairs (8-bit gray); an incomplete or unreadable stop is left out
/// with a line in `warnings`. @throws std::runtime_error when the bag cannot be read.
std::vector<mesh::CalibratedPair> readAcquisitionBag(const std::string& path, std::vector<std::string>* warnings);

}  // namespace exocet_stereo
