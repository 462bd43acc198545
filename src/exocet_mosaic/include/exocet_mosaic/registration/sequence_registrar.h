/**
 * @file sequence_registrar.h
 * @brief The registration front-end of a live or recorded image sequence: lens undistortion from the camera's
 * calibration, the restart policy (time gaps, stamps going back, size or calibration changes), the constant-velocity
 * prediction scaled to each frame interval, and the method fallback of the registrar it drives. No ROS in it.
 *
 * registration_node, the command-line tools and the benchmarks feed images through this one class, so that what a
 * benchmark measures is what the node runs.
 */
#pragma once

#include <array>
#include <memory>
#include <optional>
#include <string>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "exocet_mosaic/registration/frame_registrar.h"
#include "exocet_mosaic/registration/image_undistorter.h"
#include "exocet_mosaic/registration/motion_estimate.h"

namespace exocet_mosaic {
namespace registration {

/// The sequence policy; the estimators' own settings are in RegistrationConfig.
struct SequenceRegistrarConfig {
  /// A longer interval between two images restarts the sequence (0, 3600] s.
  double max_gap_s = 1.0;
  /// Undistort the images with the calibration's plumb_bob coefficients before registering them: the motion between
  /// two views of a flat seabed is a homography only without distortion.
  bool undistort = true;
  /// The constant-velocity prediction scales the previous motion by (this interval / previous interval), capped at
  /// this ratio: dropped frames are bridged, a long stall does not extrapolate far [1, 100].
  double max_prediction_ratio = 4.0;
  /// Images that come before any calibration, within this many seconds of the first one, are to be held back by the
  /// caller (holdForCalibration) and registered once the calibration comes: the fusion and the tile writer cannot
  /// place a motion without a camera matrix, and a live subscriber can receive its first images before the first
  /// camera_info. Past it, the images are registered without calibration (a camera that has none). 0 registers at
  /// once [0, 60] s.
  double calibration_wait_s = 0.0;

  /// Empty if usable, otherwise what is wrong (naming the field and its allowed range).
  std::string validate() const;
};

/// The camera's intrinsics as sensor_msgs/CameraInfo gives them (no ROS type here).
struct CameraCalibration {
  cv::Size size;                 ///< image size the calibration is for
  std::array<double, 9> k{};     ///< row-major camera matrix
  std::array<double, 5> d{};     ///< k1, k2, p1, p2, k3 (further coefficients are ignored)
  std::string distortion_model;  ///< plumb_bob, rational_polynomial (first five used) or empty
};

/// What became of one image.
struct SequenceStep {
  /// False for the first image of a sequence (after a start or a restart): it is kept as the first of the next pair
  /// and gives no motion.
  bool has_motion = false;
  MotionEstimate motion;          ///< the motion from the previous image to this one (when has_motion)
  double previous_stamp_s = 0.0;  ///< stamp of the image the motion starts from
  std::string restart_reason;     ///< non-empty when this image restarted the sequence, and why
  cv::Size image_size;            ///< of the registered (possibly undistorted) image
  bool undistorted = false;       ///< the image was undistorted before registration
  /// Intrinsics of the registered images: the undistorted camera's when undistorted, the calibration's otherwise;
  /// empty when no calibration of this image size is known.
  std::optional<Eigen::Matrix3d> camera_matrix;
  /// A problem with the calibration that did not stop the registration (unsupported model, other image size); the
  /// caller logs it.
  std::string calibration_warning;
};

/**
 * @brief Registers each image against the previous one and decides when the sequence must start again.
 *
 * The sequence restarts (no motion for that image) after a gap longer than max_gap_s, when the stamps go back (a bag
 * replayed again, a clock jump), when the image size changes and when the calibration changes the undistortion.
 * Dropped frames within the gap are bridged: the previous motion scaled to the interval is the starting guess.
 */
class SequenceRegistrar {
 public:
  /// @throws std::invalid_argument if `registrar` is null or `config` is not valid (the message names the field).
  SequenceRegistrar(std::unique_ptr<FrameRegistrar> registrar, const SequenceRegistrarConfig& config);

  /**
   * Registers `gray` (CV_8UC1), taken at `stamp_s`, against the previous image.
   * @throws std::invalid_argument for an empty or non-CV_8UC1 image, a stamp that is not finite and positive, or one
   *         equal to the previous image's (a duplicated stamp: the image is skipped); the sequence is unchanged then.
   */
  SequenceStep add(const cv::Mat& gray, double stamp_s);

  /// The calibration to undistort with from the next image on (it applies to images of its size only).
  void setCalibration(const CameraCalibration& calibration);
  bool hasCalibration() const { return calibration_.has_value(); }

  /**
   * Whether an image stamped `stamp_s` should be held back until the first calibration comes: true while none has
   * come and `stamp_s` is within calibration_wait_s of the first image asked about. Once the wait has run out it
   * does not start again. The caller registers the held images (add) when the calibration comes or the wait ends.
   */
  bool holdForCalibration(double stamp_s);

  /// Forgets the previous image: the next one starts a new sequence.
  void restart();

  /// Replaces the estimator (an operator's reconfiguration); the next image starts a new sequence.
  /// @throws std::invalid_argument if `registrar` is null.
  void replaceRegistrar(std::unique_ptr<FrameRegistrar> registrar);

  FrameRegistrar& registrar() { return *registrar_; }
  const ImageUndistorter& undistorter() const { return undistorter_; }
  const SequenceRegistrarConfig& config() const { return config_; }
  /// The prediction the next image would start from if it came `interval_s` after the last one (identity when there
  /// is no usable previous motion).
  Eigen::Matrix3d predictionFor(double interval_s) const;

 private:
  /// Rebuilds the undistorter when the calibration for this image size changed; the reason to restart, if any.
  std::string updateUndistorter(const cv::Size& size, std::string* warning);

  std::unique_ptr<FrameRegistrar> registrar_;
  SequenceRegistrarConfig config_;
  std::optional<CameraCalibration> calibration_;
  ImageUndistorter undistorter_;
  std::optional<double> first_uncalibrated_stamp_s_;  ///< stamp of the first image held back for the calibration
  bool calibration_wait_over_ = false;                ///< the wait ran out once: it does not start again

  bool have_previous_ = false;
  double previous_stamp_s_ = 0.0;
  cv::Size previous_size_;
  double previous_interval_s_ = 0.0;  ///< interval of the last motion; 0 before the second pair of a sequence
  MotionEstimate last_motion_;        ///< failed (the default) when there is none to predict from
};

}  // namespace registration
}  // namespace exocet_mosaic
