#include "exocet_mosaic/registration/image_undistorter.h"

#include <cmath>
#include <stdexcept>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

namespace exocet_mosaic {
namespace registration {

ImageUndistorter::ImageUndistorter(const cv::Size& size, const std::array<double, 9>& k, const std::array<double, 5>& d)
    : size_(size), k_(k), d_(d) {
  if (size.width <= 0 || size.height <= 0) throw std::invalid_argument("undistortion: image size is not set");
  for (double v : k)
    if (!std::isfinite(v)) throw std::invalid_argument("undistortion: the camera matrix has a non-finite value");
  for (double v : d)
    if (!std::isfinite(v)) throw std::invalid_argument("undistortion: a distortion coefficient is not finite");
  if (!(k[0] > 0.0 && k[4] > 0.0))
    throw std::invalid_argument("undistortion: focal lengths must be positive (camera matrix fx = " +
                                std::to_string(k[0]) + ", fy = " + std::to_string(k[4]) + ")");
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) camera_matrix_(r, c) = k[3 * r + c];
  bool distorted = false;
  for (double v : d) distorted = distorted || v != 0.0;
  if (!distorted) return;
  const cv::Mat kmat(3, 3, CV_64F, const_cast<double*>(k.data()));
  const cv::Mat dmat(1, 5, CV_64F, const_cast<double*>(d.data()));
  const cv::Mat new_k = cv::getOptimalNewCameraMatrix(kmat, dmat, size, 0.0, size);
  cv::initUndistortRectifyMap(kmat, dmat, cv::Mat(), new_k, size, CV_16SC2, map1_, map2_);
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) camera_matrix_(r, c) = new_k.at<double>(r, c);
}

bool ImageUndistorter::sameCalibration(const cv::Size& size, const std::array<double, 9>& k,
                                       const std::array<double, 5>& d) const {
  return size == size_ && k == k_ && d == d_;
}

cv::Mat ImageUndistorter::apply(const cv::Mat& image) const {
  if (!active()) return image;
  if (image.size() != size_)
    throw std::invalid_argument("undistortion: image is " + std::to_string(image.cols) + "x" +
                                std::to_string(image.rows) + ", its calibration is for " +
                                std::to_string(size_.width) + "x" + std::to_string(size_.height));
  cv::Mat out;
  cv::remap(image, out, map1_, map2_, cv::INTER_LINEAR, cv::BORDER_REPLICATE);
  return out;
}

}  // namespace registration
}  // namespace exocet_mosaic
