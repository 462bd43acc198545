/**
 * @file key_frame_feeder.h
 * @brief The pose graph's inputs from the fusion's: key frames chosen along the image chain, odometry factors summed
 * from the metric image motions between them, position fixes and headings at their stamps. No ROS in it.
 *
 * Why a stage of the fusion: the graph's odometry is the registration chain converted to metres, and that conversion
 * (attitude, camera height, lever arms, the images' yaw) is what FusionFrontEnd already does for the filter; the
 * fixes reach the graph as the fusion received them, moved to the camera by the same mounts. Feeding the graph from
 * the front-end's outcomes keeps one copy of that plumbing. Loops come from a component that holds key-frame images.
 *
 * Key frames: the first image the feeder is started at, then an image whenever the camera moved keyframe_distance_m
 * since the last key frame or keyframe_max_interval_s passed. Between two key frames A and B the image motions are
 * summed: the displacement (world east/north) turned into A's axes by A's yaw, its covariance turned likewise (the
 * images' covariances add: each pair's registration error is independent), plus a floor per key frame for what the
 * metric conversion leaves out (the seabed's relief under the images); the yaw change is the sum of the images' yaw
 * changes with image_yaw_sigma_rad per pair. A registration failure (or an image the fusion could not convert: no
 * attitude, no height) leaves no image odometry across it: the next image starts a key frame tied to the last one by
 * the fused navigation's displacement between them, with the 1-sigma of the navigation's relative error over the gap
 * (gap_sigma_m + gap_drift_mps * its duration, gap_yaw_sigma_rad). A loose tie (a metre, or 5 cm + 5 cm/s) let the
 * part of the graph after a one-second gap float on the fixes alone (0.5 m USBL: 0.2 m off on the tiles benchmark
 * dive, 9 cm over 40 s of fixes in the test) while the filter, across the same second, moved by its dead reckoning
 * within a centimetre or two.
 *
 * Dead reckoning (the vehicle's DVL track moved to the camera): its position is interpolated at each key frame's stamp
 * (between the two samples around it, at most dr_max_gap_s apart). The first key frame that has one is anchored there
 * with the dead reckoning's own covariance (its launch error: a prior, not robust); each key frame after it is tied to
 * the one before by the dead reckoning's displacement between them, in the earlier key frame's axes as the odometry
 * (the DR and the attitude share the gyro's heading), with the filter's model of its relative error: white noise at
 * both ends plus a random walk per metre travelled and per second (FilterConfig's dr_* values). Without it the graph
 * rests between its fixes on the images alone, and its absolute position on the average of the USBL fixes (0.5 m /
 * sqrt(n): 6 cm on a one-minute dive), while the filter keeps the dead reckoning's centimetre start.
 */
#pragma once

#include <cstdint>
#include <deque>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "exocet_mosaic/graph/background_pose_graph.h"

namespace exocet_mosaic {
namespace graph {

/// Settings. validate() names a bad field and its allowed range.
struct KeyFrameFeederConfig {
  double keyframe_distance_m = 0.3;       ///< camera displacement that makes a key frame (0, 100] m
  double keyframe_max_interval_s = 2.0;   ///< or the time since the last key frame (0, 3600] s
  double image_yaw_sigma_rad = 0.002;     ///< 1-sigma of one image pair's yaw change (0, 1] rad
  double odometry_floor_m = 0.002;        ///< 1-sigma added to each key-frame odometry, per axis [0, 10] m
  /// 1-sigma of the fused displacement across a registration failure, per axis (0, 1000] m: the filter's jump at a
  /// fix (a 0.5 m USBL fix moves a 7 cm filter by ~1 cm)...
  double gap_sigma_m = 0.01;
  /// ...plus its dead reckoning's drift over the gap's duration [0, 100] m/s (a DVL: ~1 % of 0.5 m/s, taken 2x).
  double gap_drift_mps = 0.01;
  double gap_yaw_sigma_rad = 0.2;  ///< of its yaw (0, 10] rad
  /// Dead reckoning: white noise of one position, each axis (0, 100] m (FilterConfig::dr_measurement_sigma_m)...
  double dr_measurement_sigma_m = 0.01;
  double dr_noise_m2_per_m = 1e-3;  ///< ...its random walk per metre travelled [0, 100] m^2/m...
  double dr_noise_m2_per_s = 1e-6;  ///< ...and per second [0, 100] m^2/s
  /// Two dead-reckoning samples further apart than this do not give a key frame between them a position, (0, 3600] s.
  double dr_max_gap_s = 2.0;
  std::string validate() const;
};

/// A key frame as the feeder made it.
struct FeederKeyFrame {
  int64_t id = 0;
  double stamp_s = 0.0;
  Pose2d initial;  ///< the chain's estimate when it was made
  /// The dead reckoning's camera position at stamp_s, once known (interpolated between the samples around it).
  std::optional<Eigen::Vector2d> dead_reckoning_en_m;
};

/**
 * @brief Feeds a BackgroundPoseGraph (never waits for it). Inputs in stamp order; not thread-safe (one caller: the
 * fusion's thread).
 */
class KeyFrameFeeder {
 public:
  /// @throws std::invalid_argument with config.validate()'s message, or for a null graph.
  KeyFrameFeeder(const KeyFrameFeederConfig& config, BackgroundPoseGraph* graph);

  /// The first key frame: the camera at `camera_en_m` with yaw `yaw_rad` (ENU, rad) at `stamp_s`.
  /// @throws std::invalid_argument for non-finite values
  int64_t start(double stamp_s, const Eigen::Vector2d& camera_en_m, double yaw_rad);
  bool started() const { return !key_frames_.empty(); }

  /**
   * @brief One image pair's motion, to the image at `stamp_s`: the camera's displacement (world east, north, m) and
   * its covariance (m^2), and the yaw change read from the images (rad, ENU).
   * @param sensor_yaw_rad the attitude sensor's yaw at `stamp_s` (ENU, rad) with its 1-sigma, when there is one: it
   * becomes a heading factor if this image becomes a key frame
   * @return the id of the key frame this image became, if it did
   * @throws std::invalid_argument before start() or for non-finite values or a covariance that is not positive
   * semi-definite
   */
  std::optional<int64_t> addImageMotion(double stamp_s, const Eigen::Vector2d& displacement_en_m,
                                        const Eigen::Matrix2d& covariance_m2, double yaw_change_rad,
                                        std::optional<double> sensor_yaw_rad = std::nullopt,
                                        double sensor_yaw_sigma_rad = 0.02);

  /**
   * @brief A pair the registration could not measure, ending at `stamp_s`: the next key frame is made here, tied to
   * the last one by the fused navigation's displacement since it (`fused_displacement_en_m`: the fused camera
   * position now minus the fused position at the last key frame) and the yaw `fused_yaw_rad`.
   * @return the id of that key frame
   */
  int64_t addImageFailure(double stamp_s, const Eigen::Vector2d& fused_displacement_en_m, double fused_yaw_rad);

  /// A position fix of the camera (USBL moved to the camera), at its measurement time; `robust`: under the graph's
  /// Cauchy loss (PoseGraph::addPositionFix), false for a prior the caller trusts (the navigation's start).
  void addPositionFix(double stamp_s, const Eigen::Vector2d& camera_en_m, const Eigen::Matrix2d& covariance_m2,
                      bool robust = true);

  /**
   * @brief A dead-reckoning position of the camera (the DVL track moved to the camera) and its covariance (the
   * dead reckoning's absolute uncertainty, m^2), in stamp order; may come before start().
   * @throws std::invalid_argument for non-finite values or a covariance that is not positive definite
   */
  void addDeadReckoning(double stamp_s, const Eigen::Vector2d& camera_en_m, const Eigen::Matrix2d& covariance_m2);
  /// Relative-position factors given to the graph, and whether the dead reckoning anchored it.
  int64_t deadReckoningFactors() const { return dr_factors_; }
  bool deadReckoningAnchored() const { return dr_anchored_; }
  /// Key frames waiting for a dead-reckoning sample after their stamp (those of the last kDeadReckoningHistoryS).
  size_t keyFramesAwaitingDeadReckoning() const { return awaiting_dr_.size(); }

  const std::vector<FeederKeyFrame>& keyFrames() const { return key_frames_; }
  /// The chain's current camera position and yaw (the last key frame's plus the motions since).
  Pose2d chainPose() const;
  const KeyFrameFeederConfig& config() const { return config_; }

 private:
  int64_t makeKeyFrame(double stamp_s, const Eigen::Matrix3d& odometry_covariance,
                       std::optional<double> sensor_yaw_rad, double sensor_yaw_sigma_rad);
  struct DeadReckoningSample {
    double stamp_s;
    Eigen::Vector2d camera_en_m;
    Eigen::Matrix2d covariance_m2;
  };
  /// Gives key frame `index` its dead-reckoning position when two samples around its stamp are known; true when
  /// settled (given one, or never will: the samples around it too far apart).
  bool placeByDeadReckoning(size_t index);
  /// Puts key frame `index` on the list waiting for the dead reckoning; lets go of those older than it by more than
  /// kDeadReckoningHistoryS.
  void awaitDeadReckoning(size_t index);
  /// The anchor or the relative position of key frame `index`, which has just got its dead-reckoning position.
  void tieByDeadReckoning(size_t index, const Eigen::Matrix2d& covariance_m2);

  KeyFrameFeederConfig config_;
  BackgroundPoseGraph* graph_;
  std::vector<FeederKeyFrame> key_frames_;
  // Motion since the last key frame: world displacement and its covariance, yaw change, pairs summed.
  Eigen::Vector2d displacement_en_m_ = Eigen::Vector2d::Zero();
  Eigen::Matrix2d covariance_m2_ = Eigen::Matrix2d::Zero();
  double yaw_change_rad_ = 0.0;
  int pairs_ = 0;
  double last_stamp_s_ = 0.0;
  // Dead reckoning: the samples of the last kDeadReckoningHistoryS (the images may lag behind the navigation), key frames
  // (indices) waiting for a sample after their stamp.
  static constexpr double kDeadReckoningHistoryS = 10.0;
  static constexpr size_t kDeadReckoningHistoryMax = 1000;
  std::deque<DeadReckoningSample> dr_samples_;
  std::vector<size_t> awaiting_dr_;
  bool dr_anchored_ = false;
  int64_t dr_factors_ = 0;
};

}  // namespace graph
}  // namespace exocet_mosaic
