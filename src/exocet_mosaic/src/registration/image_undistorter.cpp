#include "exocet_mosaic/registration/image_undistorter.h"

#include <cmath>
#include <stdexcept>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

namespace exocet_mosaic {
namespace registration {

ImageUndistorter::ImageUndistorter(const cv::Size& size, const std::array<double, 9>& k, const std::array<double, 5>& d)
    : size_(size), input_size_(size), k_(k), d_(d) {
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
  if (image.size() != input_size_)
    throw std::invalid_argument("undistortion: image is " + std::to_string(image.cols) + "x" +
                                std::to_string(image.rows) + ", its calibration is for " +
                                std::to_string(input_size_.width) + "x" + std::to_string(input_size_.height));
  cv::Mat out;
  cv::remap(image, out, map1_, map2_, cv::INTER_LINEAR, cv::BORDER_REPLICATE);
  return out;
}

ImageUndistorter ImageUndistorter::reducedBy(int reduction) const {
  if (reduction != 1 && reduction != 2 && reduction != 4 && reduction != 8)
    throw std::invalid_argument("undistortion: reduction must be 1, 2, 4 or 8, got " + std::to_string(reduction));
  if (reduction == 1) return *this;
  if (size_.width < reduction || size_.height < reduction)
    throw std::invalid_argument("undistortion: image of " + std::to_string(size_.width) + "x" +
                                std::to_string(size_.height) + " px cannot be reduced by " + std::to_string(reduction));
  const double r = reduction, c = 0.5 * (reduction - 1);
  Eigen::Matrix3d reduced_from_full;
  reduced_from_full << 1.0 / r, 0, -c / r, 0, 1.0 / r, -c / r, 0, 0, 1;
  ImageUndistorter out;
  out.size_ = cv::Size(size_.width / reduction, size_.height / reduction);
  out.input_size_ = cv::Size((size_.width + reduction - 1) / reduction, (size_.height + reduction - 1) / reduction);
  Eigen::Matrix3d k;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) k(i, j) = k_[3 * i + j];
  const Eigen::Matrix3d k_reduced = reduced_from_full * k;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) out.k_[3 * i + j] = k_reduced(i, j);
  out.d_ = d_;
  out.camera_matrix_ = reduced_from_full * camera_matrix_;
  if (!active()) return out;
  cv::Mat kin(3, 3, CV_64F), knew(3, 3, CV_64F);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      kin.at<double>(i, j) = k_reduced(i, j);
      knew.at<double>(i, j) = out.camera_matrix_(i, j);
    }
  const cv::Mat dmat(1, 5, CV_64F, const_cast<double*>(d_.data()));
  cv::initUndistortRectifyMap(kin, dmat, cv::Mat(), knew, out.size_, CV_16SC2, out.map1_, out.map2_);
  return out;
}

}  // namespace registration
}  // namespace exocet_mosaic
