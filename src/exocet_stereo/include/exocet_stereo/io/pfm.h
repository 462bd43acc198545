/**
 * @file pfm.h
 * @brief Portable Float Map I/O (the Middlebury disparity format): "Pf" (grey) or "PF" (colour) header, width and
 *        height, a scale whose sign gives the byte order (negative = little-endian), rows stored bottom to top.
 */
#pragma once

#include <string>

#include <opencv2/core.hpp>

namespace exocet_stereo {
namespace io {

/// Write CV_32FC1 (or CV_32FC3) little-endian; NaN is written as +inf (Middlebury's "unknown").
/// @throws std::invalid_argument on another type, std::runtime_error if the file cannot be written.
void writePfm(const std::string& path, const cv::Mat& image);

/// Read a PFM (either byte order) into CV_32FC1 / CV_32FC3, top row first. @throws std::runtime_error on bad files.
cv::Mat readPfm(const std::string& path);

}  // namespace io
}  // namespace exocet_stereo
