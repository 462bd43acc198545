/**
 * @file fusion_ros.h
 * @brief ROS wrapper of the navigation fusion: image motion (/mosaic/motion), dead reckoning, USBL fixes, attitude
 * and altitude in; the fused camera position in UTM (nav_msgs/Odometry with covariance), tf, paths of the fused,
 * navigation-only and image-only tracks, and /diagnostics out. The node and the nodelet are a few lines over this.
 */
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>

#include <diagnostic_updater/diagnostic_updater.h>
#include <dynamic_reconfigure/server.h>
#include <exocet_mosaic/FusionConfig.h>
#include <exocet_msgs/Depth.h>
#include <exocet_msgs/GeoDatum.h>
#include <exocet_msgs/ImageMotion.h>
#include <exocet_msgs/PositionCorrections.h>
#include <exocet_msgs/SetInitialPose.h>
#include <nav_msgs/Odometry.h>
#include <nav_msgs/Path.h>
#include <ros/ros.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/CompressedImage.h>
#include <sensor_msgs/Imu.h>
#include <sensor_msgs/NavSatFix.h>
#include <sensor_msgs/Range.h>
#include <std_srvs/Trigger.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/static_transform_broadcaster.h>
#include <tf2_ros/transform_broadcaster.h>
#include <tf2_ros/transform_listener.h>

#include "exocet_common/utm_grid.h"
#include "exocet_mosaic/fusion/fusion_front_end.h"
#include "exocet_mosaic/fusion/saved_fusion_state.h"
#include "exocet_mosaic/graph/background_pose_graph.h"
#include "exocet_mosaic/graph/key_frame_feeder.h"
#include "exocet_mosaic/graph/loop_closer.h"
#include "exocet_mosaic/graph/recent_image_buffer.h"
#include "exocet_mosaic/ros/bounded_path.h"
#include "exocet_mosaic/ros/fusion_parameters.h"
#include "exocet_mosaic/ros/keyed_throttle.h"

namespace exocet_mosaic {

/**
 * @brief Fuses the registration's image motion with the vehicle's navigation (2D3 report, section 3.5): converts the
 * messages and hands them, in stamp order, to a fusion::FusionFrontEnd (attitude and height lookup, metric
 * conversion, the filter's start), then publishes its state.
 *
 * Inputs are processed in arrival order; USBL fixes, stamped at measurement and arriving late, are out-of-sequence
 * measurements the filter handles from its history. Navigation in latitude/longitude (NavSatFix) or UTM
 * (nav_msgs/Odometry in the `utm` frame) is accepted; the UTM zone is ~utm_zone's, /nav/datum's, or the first
 * latitude/longitude's. With no navigation, the operator gives the first position, heading and height
 * (~initial_* parameters or the ~set_initial_pose service) and the images carry the track on, its covariance growing.
 *
 * Bad input (NaN, out of range, a covariance that is not one, an unknown frame) is rejected, counted, logged
 * (throttled) and shown on /diagnostics; a stamp going back further than ~clock_jump_s (a bag replayed again, a
 * clock jump) resets the filter and the tracks. At shutdown the filtered and RTS-smoothed tracks are written to
 * CSV when ~track_csv / ~smoothed_track_csv are set.
 *
 * The last published state is kept in ~state_file (at most every ~state_save_period_s): a fusion restarted mid-dive
 * (a crash, a respawn) starts its filter from it, the gap predicted as one without image motion, when its first
 * sensor input comes within ~state_max_age_s after it (fusion::resumeRefusal); otherwise (a bag played again, another
 * dive) it ignores it and says why.
 */
class FusionRos {
 public:
  /// @throws std::invalid_argument for a bad parameter.
  FusionRos(ros::NodeHandle nh, ros::NodeHandle private_nh);
  ~FusionRos();

 private:
  // Inputs.
  void onMotion(const exocet_msgs::ImageMotionConstPtr& msg);
  void onOdometry(const nav_msgs::OdometryConstPtr& msg);
  void onNavFix(const sensor_msgs::NavSatFixConstPtr& msg);
  void onUsbl(const sensor_msgs::NavSatFixConstPtr& msg);
  void onImu(const sensor_msgs::ImuConstPtr& msg);
  void onAltitude(const sensor_msgs::RangeConstPtr& msg);
  void onDepth(const exocet_msgs::DepthConstPtr& msg);
  void onCameraInfo(const sensor_msgs::CameraInfoConstPtr& msg);
  void onDatum(const exocet_msgs::GeoDatumConstPtr& msg);
  bool onSetInitialPose(exocet_msgs::SetInitialPose::Request& request, exocet_msgs::SetInitialPose::Response& response);
  bool onSmooth(std_srvs::Trigger::Request& request, std_srvs::Trigger::Response& response);

  /// Inputs reach the filter in stamp order: each is held until inputs ~reorder_delay_s newer have arrived (the
  /// registration's motion arrives after navigation stamped later), or until the inputs stop. Fixes later than that
  /// go to the filter as out-of-sequence measurements. Once the registration runs, the images announced on
  /// camera_info also hold back every later input until their motion arrives (or ~motion_wait_s of wall time): at
  /// any replay speed the filter sees the image motion before the navigation that follows it.
  void enqueue(double stamp_s, std::function<void()> apply);
  void release(bool everything);
  void applyMotion(const exocet_msgs::ImageMotion& msg);

  /// Dead reckoning of base_link (position in the UTM grid, attitude) from either input format.
  void processDeadReckoning(const ros::Time& stamp, const Eigen::Vector3d& base_en_m,
                            const std::optional<Eigen::Quaterniond>& world_from_base,
                            const Eigen::Matrix2d& covariance_m2, const std::string& frame_id);
  /// Checks a stamp for a clock jump (resetting everything when the time goes back) and keeps the newest stamp.
  /// False if the message must be dropped.
  bool admitStamp(const ros::Time& stamp, const std::string& what, bool late_allowed);
  void resetAll(const std::string& why);
  void rejectInput(const std::string& kind, const std::string& why);
  /// False (the sample rejected) when a sample of the stream `kind` is stamped at or before the newest one.
  bool inStreamOrder(const std::string& kind, const ros::Time& stamp);
  void countResult(const std::string& kind, const fusion::UpdateResult& result);

  /// Counts and logs what became of an input the front-end took; publishes where the input calls for it.
  void handleOutcome(const std::string& kind, const fusion::InputOutcome& outcome);
  /// base_link -> frame from tf (static mounts); empty, with a throttled warning, when tf does not have it.
  std::optional<Eigen::Isometry3d> mountOf(const std::string& frame);
  /// The UTM grid of the dive, choosing it from a latitude/longitude when nothing fixed it yet.
  const exocet_common::UtmGrid* gridFor(double latitude_deg, double longitude_deg);
  /// The filter has just started (from `source`): the map origin and a log line.
  void onStarted(const std::string& source);
  void initializeFromParameters();
  /// Reads ~state_file (when set and present) for the first input to decide on.
  void loadSavedState();
  /// At the first sensor input (before anything reaches the filter): starts the filter from the saved state when
  /// that belongs to this dive.
  void maybeResume(double first_stamp_s);
  /// Writes the filter's state to ~state_file, at most every ~state_save_period_s unless `now`.
  void saveState(bool now);
  /// The map origin given (a resumed dive keeps its own), broadcast as ensureMapOrigin does.
  void setMapOrigin(const Eigen::Vector2d& origin_en_m);
  /// Images only and no first point: the dive is mapped from (0, 0) in the local frame ~map_frame (said once).
  void startInLocalFrame();

  // Outputs.
  void publishState(const ros::Time& stamp);
  /// Publishes the UTM zone in use (latched) when it is first known or changes.
  void publishDatum();
  /// In the map frame (fixing its origin at the first position).
  Eigen::Vector2d mapPosition(const Eigen::Vector2d& en_m);
  void publishPaths();
  void ensureMapOrigin(const Eigen::Vector2d& en_m);
  void writeTracks();
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& status);
  void onReconfigure(exocet_mosaic::FusionConfig& config, uint32_t level);

  ros::NodeHandle nh_, private_nh_;
  FusionNodeConfig config_;
  std::unique_ptr<fusion::FusionFrontEnd> front_end_;
  // The operator's knobs (gating). Node and nodelet run the callbacks on one thread (ST node handles).
  std::unique_ptr<dynamic_reconfigure::Server<exocet_mosaic::FusionConfig>> reconfigure_server_;
  boost::recursive_mutex reconfigure_mutex_;  // dynamic_reconfigure wants a boost mutex

  ros::Subscriber motion_sub_, odometry_sub_, nav_fix_sub_, usbl_sub_, imu_sub_, altitude_sub_, depth_sub_,
      camera_info_sub_, datum_sub_;
  ros::ServiceServer initial_pose_srv_, smooth_srv_;
  ros::Publisher odometry_pub_, fused_path_pub_, nav_path_pub_, image_path_pub_, smoothed_path_pub_;
  // The key frames' pose graph (~pose_graph): fed from the front-end's outcomes, solved in its worker thread.
  std::unique_ptr<graph::BackgroundPoseGraph> graph_;
  std::unique_ptr<graph::KeyFrameFeeder> feeder_;
  std::optional<double> graph_last_yaw_rad_;
  ros::Publisher graph_path_pub_, graph_odometry_pub_, graph_corrections_pub_;
  std::shared_ptr<const graph::GraphSnapshot> last_corrections_snapshot_;  ///< last sent on graph_corrections_pub_
  std::map<int64_t, Eigen::Vector2d> key_frame_filter_en_m_;  ///< the filter's position when each key frame was made
  /// The graph's correction (graph pose - filter position) at the latest solved key frame at or before `stamp_s`.
  std::optional<Eigen::Vector2d> graphCorrectionAt(double stamp_s) const;
  // ~loop_closure: the recent images by stamp, for the key frames the feeder makes.
  std::unique_ptr<graph::LoopCloser> loop_closer_;
  ros::Subscriber loop_image_sub_;
  graph::RecentImageBuffer<sensor_msgs::CompressedImageConstPtr> recent_images_{graph::RecentImageBufferLimits()};
  uint64_t loop_images_missing_ = 0;
  int64_t graph_navigation_ties_ = 0;  ///< key frames tied by the fused displacement (no image odometry)
  std::optional<Eigen::Matrix3d> last_camera_matrix_;  ///< K of the images (the motions' or camera_info's)
  void onLoopImage(const sensor_msgs::CompressedImageConstPtr& msg);
  void offerKeyFrame(int64_t id, double stamp_s, const std::optional<Eigen::Quaterniond>& attitude, double yaw_rad);
  void startGraph();
  void feedGraph(double stamp_s, const fusion::InputOutcome& outcome);
  void publishGraphPath();
  ros::Publisher camera_height_pub_, datum_pub_;
  int published_datum_zone_ = -1;  ///< zone * 2 + northern of the last /mosaic/datum, -1 before
  bool published_datum_has_origin_ = false;
  tf2_ros::Buffer tf_buffer_;
  tf2_ros::TransformListener tf_listener_;
  tf2_ros::TransformBroadcaster tf_broadcaster_;
  tf2_ros::StaticTransformBroadcaster static_broadcaster_;
  diagnostic_updater::Updater updater_;
  ros::SteadyTimer diagnostics_timer_, path_timer_;
  ros::SteadyTimer free_heap_timer_;
  static constexpr double kFreeHeapPeriod_s = 10.0;

  // Geography.
  std::optional<exocet_common::UtmGrid> grid_;
  std::string grid_source_;
  std::set<std::string> problems_told_;  ///< each distinct problem is logged once as an error, then throttled
  /// The frame of the fused positions: ~utm_frame, or the navigation's own frame when it is a local metric frame
  /// (no datum, no ~utm_zone, no latitude/longitude): the dive is then not geo-referenced.
  std::string world_frame_;
  bool local_world_ = false;
  /// No navigation is expected (no dead reckoning, no fixes): the operator's point or, failing one, (0, 0) in the
  /// local frame ~map_frame starts the filter.
  bool images_only_ = false;
  /// A first position was given (~initial_* or ~set_initial_pose): the images-only dive is geo-referenced.
  bool operator_start_given_ = false;
  std::optional<Eigen::Vector2d> map_origin_en_m_;  ///< utm -> map offset (rviz cannot draw UTM-sized floats)

  // Mounts on the vehicle, looked up once each from tf.
  std::map<std::string, Eigen::Isometry3d> mounts_;
  std::multimap<double, std::function<void()>> queue_;
  std::map<double, ros::SteadyTime> awaiting_motion_;  ///< image stamps (camera_info) whose motion has not arrived
  bool motion_seen_ = false;                           ///< the registration runs: images wait for their motion
  double newest_motion_stamp_s_ = -1e300;
  uint64_t motion_waits_timed_out_ = 0;
  ros::SteadyTime last_input_wall_;
  ros::Time last_published_stamp_;  // of the last fused pose: one pose per stamp (tf refuses a repeated one)
  ros::SteadyTimer flush_timer_;

  // Tracks.
  double newest_stamp_s_ = 0.0;
  bool have_stamp_ = false;
  /// Wall time since which every input came from more than ~clock_jump_s before the newest (none in order since).
  std::optional<ros::WallTime> late_since_;
  std::uint64_t late_inputs_ = 0;  ///< inputs dropped as late (the clock had not gone back)
  /// Wall seconds of inputs all from before the newest, none in order, that make a new dive (a source restarted
  /// without a clock); fewer: late inputs, dropped.
  static constexpr double kLateInputPatience_s = 3.0;
  // Bounded (~path_min_spacing_m, ~max_path_poses): a dive of any length keeps a few MB of paths.
  BoundedPath fused_path_, nav_path_, image_path_;
  ros::Time last_odometry_stamp_;

  // Counts for /diagnostics.
  uint64_t motions_ = 0, motion_failures_ = 0, dead_reckonings_ = 0, fixes_ = 0, resets_ = 0;
  std::map<std::string, uint64_t> applied_, gated_, too_old_, invalid_, rejected_inputs_;
  KeyedThrottle rejection_log_{2.0};                       ///< per kind of input
  std::map<std::string, ros::Time> newest_sample_stamps_;  ///< of the interpolated streams (imu, altitude, depth)
  std::string last_problem_;
  ros::WallTime last_nav_wall_, last_motion_wall_;

  // Restart mid-dive.
  std::optional<fusion::SavedFusionState> saved_state_;  ///< read at start, decided on at the first input
  std::string started_from_;                             ///< what started the filter last
  std::string resume_note_;                              ///< what became of the saved state
  ros::SteadyTime last_state_save_;
  uint64_t state_saves_ = 0, state_save_failures_ = 0;
};

}  // namespace exocet_mosaic
