/**
 * @file fusion_front_end.h
 * @brief The navigation fusion's front-end: keeps the attitude and altitude histories, looks up the attitude and
 * camera height of each image, converts the registration's pixel motion to metres, moves navigation positions to the
 * camera by its lever arm, starts the filter from the right source, and hands every measurement to the
 * NavigationFilter. No ROS in it.
 *
 * fusion_node converts messages and calls this class; the benchmarks feed their simulated sensors through it, so that
 * a figure measures the node's code.
 */
#pragma once

#include <functional>
#include <limits>
#include <optional>
#include <string>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "exocet_mosaic/fusion/measurement_history.h"
#include "exocet_mosaic/fusion/metric_motion.h"
#include "exocet_mosaic/fusion/navigation_filter.h"
#include "exocet_mosaic/registration/motion_model.h"

namespace exocet_mosaic {
namespace fusion {

struct FusionFrontEndConfig {
  FilterConfig filter;
  bool keep_log = true;  ///< keep every filter step (RTS smoothing, track files)
  /// With keep_log: the file the steps older than the filter's history window are written to
  /// (NavigationFilter::setLogFile), so that memory does not grow with the dive; "": held in memory.
  std::string log_file;
  double attitude_max_gap_s = 0.5;  ///< attitude samples further apart are not interpolated between (0, 60] s
  double altitude_max_gap_s = 1.0;  ///< altimeter samples further apart are not interpolated between (0, 600] s
  double history_window_s = 30.0;   ///< how long attitude and altitude samples are kept [1, 3600] s
  /// Half-width of the window over which roll, pitch and the altimeter range are fitted (a quadratic in time) at an
  /// image's stamp: their noise is white, so the fit averages it. 0: interpolated between the samples around the
  /// stamp. With a window, an image's view is complete only `view_half_window_s` after its stamp: the caller hands
  /// the motion over that late (fusion_node: ~reorder_delay_s) [0, 10] s.
  double view_half_window_s = 0.0;
  /// 1-sigma of one altimeter range (m), from its datasheet; 0 = unknown (the height is then taken as exact) [0, 10].
  double altimeter_sigma_m = 0.0;
  /// Depth of the seabed below the surface (m), for a dive without an altimeter: the camera's height is then this
  /// minus the camera's depth (the depth sensor's, moved to the camera by the mount). NaN: not used; else (0, 12000].
  /// A flat-seabed assumption: the height's error is the seabed's relief under the camera.
  double seabed_depth_m = std::numeric_limits<double>::quiet_NaN();
  double depth_max_gap_s = 2.0;                 ///< depth samples further apart are not interpolated between (0, 600] s
  std::string base_frame = "base_link";         ///< the vehicle's body frame: positions of navigation refer to it
  std::string default_camera_frame = "camera";  ///< the camera's frame until a motion names its own

  /// Empty if usable, otherwise what is wrong (naming the field and its allowed range).
  std::string validate() const;
};

/// base_link -> frame (a rigid mount on the vehicle); empty when it is not known (yet).
using MountLookup = std::function<std::optional<Eigen::Isometry3d>(const std::string& frame)>;

/// The registration's estimate for one image pair, as exocet_msgs/ImageMotion carries it (no ROS type here).
struct ImageMotionInput {
  double previous_stamp_s = 0.0;
  double stamp_s = 0.0;
  bool failed = false;
  std::string model;           ///< motion model name (registration::toString)
  Eigen::VectorXd parameters;  ///< of the model, centred on centre_px (pixels)
  Eigen::MatrixXd covariance;  ///< of the parameters (pixel units)
  Eigen::Vector2d centre_px = Eigen::Vector2d::Zero();
  Eigen::Matrix3d pixel_matrix = Eigen::Matrix3d::Identity();  ///< previous-image pixels to current-image pixels
  std::optional<Eigen::Matrix3d> camera_matrix;                ///< of the registered images, when the message has it
};

/// What became of one input.
struct InputOutcome {
  std::optional<UpdateResult> update;  ///< the filter's verdict, when the input reached the filter
  /// Non-empty when the input itself is unusable (counted as rejected): why.
  std::string rejected;
  /// Non-empty when the input could not be used for want of something else (a mount, an attitude, a height): why.
  /// An image pair is then given to the filter as a failure (its time still passes).
  std::string problem;
  /// Non-empty when this input started the filter: from what.
  std::string started_from;
  /// Dead reckoning and fixes: the camera position they gave. Image motions: the image-only track's new position.
  std::optional<Eigen::Vector2d> camera_en_m;
  /// Image motions: the displacement in metres given to the filter.
  std::optional<MetricMotion> metric;
};

/**
 * @brief Everything between the sensors' values and the NavigationFilter.
 *
 * Inputs must come in stamp order (the caller reorders them; late USBL fixes are out-of-sequence measurements the
 * filter handles). The filter starts at the first of: the operator's first point (setOperatorStart) at the next
 * input, the dead reckoning, or (with no dead reckoning expected) the first fix. Without an attitude sensor the
 * operator's heading (setOperatorHeading) is carried on by the images' rotation, the vehicle taken as level.
 */
class FusionFrontEnd {
 public:
  /// @throws std::invalid_argument naming the bad setting.
  FusionFrontEnd(const FusionFrontEndConfig& config, MountLookup mounts);

  // ---- Sensor histories ----
  /// Attitude of base_link in the ENU world from an attitude sensor (preferred) or from the navigation.
  void addImuAttitude(double stamp_s, const Eigen::Quaterniond& world_from_base);
  void addNavigationAttitude(double stamp_s, const Eigen::Quaterniond& world_from_base);
  /// An altimeter range (m) along the body's -z from the mount `frame`.
  void addAltimeterRange(double stamp_s, double range_m, const std::string& frame);
  /// Depth of base_link below the surface (m, positive down), from the pressure sensor.
  void addDepth(double stamp_s, double depth_m);
  /// Intrinsics to use for motions that carry none (the camera_info's).
  void setCameraMatrix(const Eigen::Matrix3d& camera_matrix) { camera_matrix_ = camera_matrix; }
  /// The camera's frame, as named by the motions.
  void setCameraFrame(const std::string& frame);
  const std::string& cameraFrame() const;

  // ---- The operator ----
  /// First position (UTM grid, camera centre) and its 1-sigma, applied at the next input when the filter is not
  /// running (a re-seed during the dive: initialize()).
  void setOperatorStart(const Eigen::Vector2d& camera_en_m, double sigma_m);
  /// ENU yaw of base_link (counter-clockwise from east), used while no attitude sensor speaks.
  void setOperatorHeading(double enu_yaw_rad) { operator_heading_rad_ = enu_yaw_rad; }
  /// The operator's heading as the images' rotation has carried it on so far (ENU yaw, rad); empty when not set.
  const std::optional<double>& operatorHeading() const { return operator_heading_rad_; }
  /// Height of the camera above the seabed (m), used while no altimeter speaks.
  void setOperatorHeight(double camera_height_m) { operator_height_m_ = camera_height_m; }
  /// Starts the filter now at a given position and covariance (m^2), e.g. a re-seed, or a benchmark's start.
  void initialize(double stamp_s, const Eigen::Vector2d& camera_en_m, const Eigen::Matrix2d& covariance_m2);
  /// Starts the filter from a whole saved state (NavigationFilter::resume): a restart of the node mid-dive.
  void resume(double stamp_s, const StateVector& x, const StateMatrix& P, bool dr_offset_known);

  // ---- Measurements, in stamp order ----
  /// Dead reckoning of base_link (UTM grid position, metres; its covariance, m^2). It starts the filter when
  /// nothing else did.
  InputOutcome addDeadReckoning(double stamp_s, const Eigen::Vector3d& base_en_m, const Eigen::Matrix2d& covariance_m2);
  /// An absolute fix (USBL) of the transponder at `transponder_frame` (empty: base_link), stamped at measurement.
  /// @param may_start whether it may start the filter (no dead reckoning expected).
  InputOutcome addFix(double stamp_s, const Eigen::Vector2d& fix_en_m, const Eigen::Matrix2d& covariance_m2,
                      const std::string& transponder_frame, bool may_start);
  InputOutcome addImageMotion(const ImageMotionInput& motion);

  // ---- Lookups ----
  /// Attitude of base_link at a stamp: the attitude sensor's, else the navigation's; empty when neither covers it.
  std::optional<Eigen::Quaterniond> attitudeAt(double stamp_s) const;
  /// Stamp of the newest attitude sample (IMU or navigation); empty when none arrived.
  std::optional<double> newestAttitudeStamp() const;
  /// The view (attitude, camera height and its sigma) of an image at `stamp_s` for a camera mounted at
  /// `base_from_camera`, from the sensors' attitude (fitted over the view window when one is set); empty when the
  /// attitude or the height is unknown.
  std::optional<ViewGeometry> viewAt(double stamp_s, const Eigen::Isometry3d& base_from_camera) const;
  /// Camera height above the seabed at a stamp: the altimeter's, else the seabed depth minus the camera's depth (when
  /// seabed_depth_m is set), else the operator's; empty when unknown.
  std::optional<double> cameraHeightAt(double stamp_s, const Eigen::Quaterniond& world_from_base,
                                       const Eigen::Isometry3d& base_from_camera) const;
  /// The camera's mount (base_link -> camera frame), when known.
  std::optional<Eigen::Isometry3d> cameraMount() const { return mounts_(cameraFrame()); }

  const NavigationFilter& filter() const { return filter_; }
  NavigationFilter& filter() { return filter_; }
  const FusionFrontEndConfig& config() const { return config_; }
  /// The image-only track's position (dead reckoning by the images alone from the filter's start), when started.
  const std::optional<Eigen::Vector2d>& imageOnlyPosition() const { return image_only_en_m_; }

  /// Forgets the filter, the histories and the tracks (a clock jump, a new dive); the operator's settings stay.
  void reset();

 private:
  static constexpr double kAttitudeWaitS = 2.0;   // how long a first navigation sample waits for the attitude
  std::optional<double> first_unplaced_stamp_s_;  // the first one that could not be placed at the camera
  // Why the filter does not start from a navigation sample yet (the camera's place on the vehicle or the attitude).
  std::string waitingForLeverArm(bool mounts_known) const;
  /// Starts the filter from the operator's point when one is pending; true if the filter runs after the call.
  bool startFromOperator(double stamp_s, InputOutcome* outcome);
  void start(double stamp_s, const Eigen::Vector2d& camera_en_m, double sigma_m, const std::string& source,
             InputOutcome* outcome);
  /// Gives the filter an image failure for the pair (the time passes, the covariance grows).
  InputOutcome failImage(const ImageMotionInput& motion, InputOutcome outcome);
  std::optional<Eigen::Quaterniond> viewAttitudeAt(double stamp_s) const;
  std::optional<ViewGeometry> viewWith(double stamp_s, const Eigen::Quaterniond& world_from_base,
                                       const Eigen::Isometry3d& base_from_camera) const;
  std::optional<std::pair<double, double>> viewRangeAt(double stamp_s) const;

  FusionFrontEndConfig config_;
  MountLookup mounts_;
  NavigationFilter filter_;
  AttitudeHistory imu_attitude_, nav_attitude_;
  ScalarHistory altimeter_range_m_;
  ScalarHistory depth_m_;
  std::string altimeter_frame_;
  std::string camera_frame_;
  std::optional<Eigen::Matrix3d> camera_matrix_;
  std::optional<double> operator_heading_rad_;
  std::optional<double> operator_height_m_;
  std::optional<Eigen::Vector2d> pending_start_en_m_;
  double pending_start_sigma_m_ = 1.0;
  std::optional<Eigen::Vector2d> image_only_en_m_;
};

}  // namespace fusion
}  // namespace exocet_mosaic
