/**
 * @file frame_assembler.h
 * @brief Gathers, per image stamp, what the tile writer needs from several topics (the image, its registration to
 * the previous image, the fused pose and the camera height) and releases complete frames in stamp order. No ROS
 * types in it, so it is tested without a master.
 */
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <opencv2/core.hpp>

namespace exocet_mosaic {

/// Registration of an image to the previous one (exocet_msgs/ImageMotion).
struct MotionPart {
  std::int64_t previous_stamp_ns = 0;
  bool failed = true;
  cv::Matx33d current_from_previous_px = cv::Matx33d::eye();  ///< previous px -> current px
  cv::Matx33d camera_matrix = cv::Matx33d::eye();             ///< intrinsics of the registered (undistorted) images
  bool has_camera_matrix = false;
  bool undistorted = false;  ///< the registration undistorted the images
};

/// Fused camera pose (nav_msgs/Odometry of the fusion node) at an image stamp.
struct PosePart {
  Eigen::Vector2d camera_en_m = Eigen::Vector2d::Zero();
  Eigen::Matrix2d position_cov_m2 = Eigen::Matrix2d::Identity();
  Eigen::Quaterniond world_from_camera = Eigen::Quaterniond::Identity();
};

/// Decodes an image at 1/reduction (1, 2, 4, 8) of its size where the format allows it (a JPEG's scaled decoding),
/// otherwise at full size. Throws what is wrong with the message.
using ImageDecoder = std::function<cv::Mat(int reduction)>;

/// What is known of one image stamp. The image is decoded only when the frame is used.
struct AssembledFrame {
  std::int64_t stamp_ns = 0;
  ImageDecoder decode_image;  ///< empty: no image received for this stamp
  cv::Size image_size;                    ///< of the decoded image, when known without decoding (else empty)
  int image_channels = 0;                 ///< of the decoded image, when known without decoding (else 0)
  std::optional<MotionPart> motion;
  std::optional<PosePart> pose;
  std::optional<double> camera_height_m;
  double image_arrival_s = 0.0;  ///< wall time the image arrived
  bool complete() const { return decode_image && motion && pose && camera_height_m; }
};

/**
 * @brief Frames keyed by stamp; released in stamp order when complete (then every older frame goes too, with what it
 * has), when their image waited longer than timeout_s, or when more than max_pending images wait.
 */
class FrameAssembler {
 public:
  /// @param timeout_s wall seconds an image waits for its parts, > 0; @param max_pending images waiting, >= 1
  FrameAssembler(double timeout_s, std::size_t max_pending);

  /// Each returns false when the stamp was already released (a late part, counted in lateParts()); addImage also when
  /// an image of that stamp is already waiting (a duplicated stamp: the first image is kept, counted in
  /// duplicateImages()).
  /// image_size and image_channels: the decoded image's shape when the message tells it (else leave them empty).
  bool addImage(std::int64_t stamp_ns, ImageDecoder decode_image, double now_s,
                cv::Size image_size = cv::Size(), int image_channels = 0);
  bool addMotion(std::int64_t stamp_ns, const MotionPart& motion, double now_s);
  bool addPose(std::int64_t stamp_ns, const PosePart& pose, double now_s);
  bool addHeight(std::int64_t stamp_ns, double camera_height_m, double now_s);

  /// Frames ready to use, in stamp order (only stamps that have an image; the others are dropped silently: the
  /// fusion also publishes between images).
  std::vector<AssembledFrame> popReady(double now_s);
  /// Every waiting frame that has an image, in stamp order (shutdown).
  std::vector<AssembledFrame> popAll();
  /// Forgets everything (clock jump).
  void reset();

  std::size_t pendingImages() const;
  std::int64_t lateParts() const { return late_parts_; }
  std::int64_t duplicateImages() const { return duplicate_images_; }
  std::int64_t timedOut() const { return timed_out_; }

 private:
  AssembledFrame* slot(std::int64_t stamp_ns, double now_s);
  void release(std::map<std::int64_t, AssembledFrame>::iterator end, std::vector<AssembledFrame>* out);

  double timeout_s_;
  std::size_t max_pending_;
  std::map<std::int64_t, AssembledFrame> frames_;
  std::optional<std::int64_t> last_released_ns_;
  std::int64_t late_parts_ = 0;
  std::int64_t duplicate_images_ = 0;
  std::int64_t timed_out_ = 0;
};

}  // namespace exocet_mosaic
