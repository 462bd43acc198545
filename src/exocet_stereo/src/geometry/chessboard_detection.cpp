#include "exocet_stereo/geometry/chessboard_detection.h"

#include <sstream>
#include <stdexcept>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

namespace exocet_stereo {
namespace geometry {

std::string ChessboardPattern::validate() const {
  std::ostringstream errors;
  auto check = [&errors](bool ok, const char* field, const char* range) {
    if (ok) return;
    if (errors.tellp() > 0) errors << "; ";
    errors << field << " must be in " << range;
  };
  check(inner_corners.width >= 2 && inner_corners.width <= 100, "inner_corners.width", "[2, 100]");
  check(inner_corners.height >= 2 && inner_corners.height <= 100, "inner_corners.height", "[2, 100]");
  check(square_m > 0.0 && square_m <= 10.0, "square_m", "(0, 10]");
  return errors.str();
}

std::vector<cv::Point3f> ChessboardPattern::objectPoints() const {
  std::vector<cv::Point3f> points;
  for (int r = 0; r < inner_corners.height; ++r)
    for (int c = 0; c < inner_corners.width; ++c)
      points.emplace_back(static_cast<float>(c * square_m), static_cast<float>(r * square_m), 0.0f);
  return points;
}

cv::Size parsePatternSize(const std::string& text) {
  int w = 0, h = 0;
  char x = 0, extra = 0;
  std::istringstream in(text);
  if (!(in >> w >> x >> h) || (x != 'x' && x != 'X') || (in >> extra) || w < 2 || h < 2 || w > 100 || h > 100)
    throw std::invalid_argument("pattern '" + text +
                                "' must be COLSxROWS of inner corners, each in [2, 100] (e.g. 9x6)");
  return {w, h};
}

bool detectChessboard(const cv::Mat& image, const ChessboardPattern& pattern, std::vector<cv::Point2f>& corners) {
  corners.clear();
  if (image.empty()) return false;
  cv::Mat gray = image;
  if (image.channels() == 3) cv::cvtColor(image, gray, cv::COLOR_BGR2GRAY);
  if (!cv::findChessboardCorners(gray, pattern.inner_corners, corners,
                                 cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE)) {
    corners.clear();
    return false;
  }
  // 11x11 window as in OpenCV's calibration samples: squares here are > 20 px wide.
  cv::cornerSubPix(gray, corners, cv::Size(11, 11), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 30, 0.01));
  return true;
}

}  // namespace geometry
}  // namespace exocet_stereo
