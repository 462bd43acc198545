/**
 * @file frame_registrar.h
 * @brief Interface of a frame-to-frame registration method (KLT, RMR): a sequence of 8-bit grey images in, one motion
 * estimate per consecutive pair out. No ROS in it.
 */
#pragma once

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "exocet_mosaic/registration/motion_estimate.h"

namespace exocet_mosaic {
namespace registration {

class FrameRegistrar {
 public:
  virtual ~FrameRegistrar() = default;

  /// Forgets the previous image (after a time gap, a size change, a clock jump).
  virtual void reset() = 0;

  /**
   * Registers `gray` (CV_8UC1) against the image given to the previous call and keeps what it needs of `gray` (its
   * pyramid, its features) for the next call, so that each image is prepared once. The first call after reset()
   * returns a failure with FailureReason::kNoPreviousFrame. An image of another size than the previous one fails
   * with kInvalidInput and becomes the new previous image.
   * @param prediction_px predicted pixel matrix from the previous image to this one (identity when unknown): the
   *        starting point of the estimation, e.g. the previous motion after a dropped frame.
   */
  virtual MotionEstimate registerNext(const cv::Mat& gray,
                                      const Eigen::Matrix3d& prediction_px = Eigen::Matrix3d::Identity()) = 0;

  /// Registers one pair with no state kept (both images CV_8UC1, the same size): the motion from `previous` to
  /// `current`.
  virtual MotionEstimate registerPair(const cv::Mat& previous, const cv::Mat& current,
                                      const Eigen::Matrix3d& prediction_px = Eigen::Matrix3d::Identity()) = 0;

  virtual RegistrationMethod method() const = 0;
};

}  // namespace registration
}  // namespace exocet_mosaic
