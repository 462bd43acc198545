/**
 * @file chessboard_detection.h
 * @brief Chessboard inner corners with sub-pixel refinement (cv::findChessboardCorners then cv::cornerSubPix),
 * the measurements of a calibration (2D4 report section 3.1.1). No ROS in it.
 */
#pragma once

#include <string>
#include <vector>

#include <opencv2/core.hpp>

namespace exocet_stereo {
namespace geometry {

/// A planar chessboard: inner corners per row and column, and the square side.
struct ChessboardPattern {
  cv::Size inner_corners{9, 6};  ///< columns x rows of inner corners, each in [2, 100]
  double square_m = 0.025;       ///< side of a square, (0, 10] m

  std::string validate() const;
  /// Board coordinates (z = 0) of the inner corners, row-major, in metres.
  std::vector<cv::Point3f> objectPoints() const;
};

/// Parses "9x6" into inner corners. @throws std::invalid_argument on bad text.
cv::Size parsePatternSize(const std::string& text);

/**
 * @brief Inner corners of the board in an image (gray or BGR), refined to sub-pixel accuracy.
 * @return false if the board is not found entirely.
 */
bool detectChessboard(const cv::Mat& image, const ChessboardPattern& pattern, std::vector<cv::Point2f>& corners);

}  // namespace geometry
}  // namespace exocet_stereo
