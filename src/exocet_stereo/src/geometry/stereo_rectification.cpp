#include "exocet_stereo/geometry/stereo_rectification.h"

#include <stdexcept>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

namespace exocet_stereo {
namespace geometry {

double Rectification::baseline() const {
  // P2(0, 3) = -f * B for a horizontal rectified pair (P2(1, 3) for a vertical one).
  const double f = P2.at<double>(0, 0);
  return std::hypot(P2.at<double>(0, 3), P2.at<double>(1, 3)) / f;
}

Rectification computeRectification(const StereoRig& rig, double alpha) {
  if (!rig.has_extrinsics) throw std::invalid_argument("computeRectification: the rig has no R and T");
  if (!(alpha == -1.0 || (alpha >= 0.0 && alpha <= 1.0)))
    throw std::invalid_argument("computeRectification: alpha must be -1 or in [0, 1], got " + std::to_string(alpha));
  if (rig.image_size.empty()) throw std::invalid_argument("computeRectification: the rig has no image size");
  Rectification rect;
  rect.image_size = rig.image_size;
  cv::stereoRectify(rig.K_left, rig.dist_left, rig.K_right, rig.dist_right, rig.image_size, rig.R, rig.T, rect.R1,
                    rect.R2, rect.P1, rect.P2, rect.Q, cv::CALIB_ZERO_DISPARITY, alpha, rig.image_size,
                    &rect.valid_left, &rect.valid_right);
  cv::initUndistortRectifyMap(rig.K_left, rig.dist_left, rect.R1, rect.P1, rig.image_size, CV_32FC1, rect.map_left_x,
                              rect.map_left_y);
  cv::initUndistortRectifyMap(rig.K_right, rig.dist_right, rect.R2, rect.P2, rig.image_size, CV_32FC1, rect.map_right_x,
                              rect.map_right_y);
  return rect;
}

void rectifyPair(const Rectification& rect, const cv::Mat& left, const cv::Mat& right, cv::Mat& left_rect,
                 cv::Mat& right_rect) {
  cv::remap(left, left_rect, rect.map_left_x, rect.map_left_y, cv::INTER_LINEAR);
  cv::remap(right, right_rect, rect.map_right_x, rect.map_right_y, cv::INTER_LINEAR);
}

std::vector<cv::Point2f> rectifyPoints(const StereoRig& rig, const Rectification& rect,
                                       const std::vector<cv::Point2f>& pixels, bool right) {
  std::vector<cv::Point2f> out;
  if (pixels.empty()) return out;
  if (right)
    cv::undistortPoints(pixels, out, rig.K_right, rig.dist_right, rect.R2, rect.P2);
  else
    cv::undistortPoints(pixels, out, rig.K_left, rig.dist_left, rect.R1, rect.P1);
  return out;
}

}  // namespace geometry
}  // namespace exocet_stereo
