/**
 * @file image_undistorter.h
 * @brief Removes lens distortion (OpenCV's plumb_bob model, as in sensor_msgs/CameraInfo) before registration, so
 * that the motion between two views of the seabed is a homography. No ROS in it.
 */
#pragma once

#include <array>

#include <Eigen/Core>
#include <opencv2/core.hpp>

namespace exocet_mosaic {
namespace registration {

/**
 * The undistorted image keeps the input's size and shows only valid pixels (OpenCV's alpha = 0): no black border to
 * mislead the estimators. Its intrinsics are cameraMatrix(). Maps are computed once (fixed-point, fast remap).
 */
class ImageUndistorter {
 public:
  ImageUndistorter() = default;
  /// @param k 3x3 row-major camera matrix; @param d k1, k2, p1, p2, k3. @throws std::invalid_argument if unusable.
  ImageUndistorter(const cv::Size& size, const std::array<double, 9>& k, const std::array<double, 5>& d);

  bool active() const { return !map1_.empty(); }
  const cv::Size& size() const { return size_; }
  /// Intrinsics of the undistorted images (those of the input when no distortion is set).
  const Eigen::Matrix3d& cameraMatrix() const { return camera_matrix_; }
  /// Whether `k` and `d` are the ones this undistorter was made from.
  bool sameCalibration(const cv::Size& size, const std::array<double, 9>& k, const std::array<double, 5>& d) const;

  /// The undistorted image (the input itself when there is no distortion). @throws std::invalid_argument on size.
  cv::Mat apply(const cv::Mat& image) const;

  /**
   * @brief The same undistortion for the images reduced by `reduction` (2, 4 or 8; 1 gives a copy): it takes an
   * image decoded at 1/reduction, ceil(size / reduction) (libjpeg's scaled decoding; pixel x centred on full px
   * r x + (r - 1) / 2), and gives floor(size / reduction) px whose intrinsics are this one's cameraMatrix() reduced
   * the same way: the undistorted reduced image is the undistorted image reduced. @throws std::invalid_argument.
   */
  ImageUndistorter reducedBy(int reduction) const;
  /// Size of the images apply() takes (size() for the full-resolution undistorter).
  const cv::Size& inputSize() const { return input_size_; }

 private:
  cv::Size size_;
  cv::Size input_size_;
  std::array<double, 9> k_{};
  std::array<double, 5> d_{};
  Eigen::Matrix3d camera_matrix_ = Eigen::Matrix3d::Identity();
  cv::Mat map1_, map2_;
};

}  // namespace registration
}  // namespace exocet_mosaic
