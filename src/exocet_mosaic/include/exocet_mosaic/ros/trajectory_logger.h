/**
 * @file trajectory_logger.h
 * @brief ROS node class that logs the trajectories of a dive (ground truth, dead reckoning, USBL fixes) to CSV.
 *
 * Files, in `~output_dir` (created if missing), one set per replay:
 * - `ground_truth.csv`: stamp_s, easting_m, northing_m, up_m, roll_deg, pitch_deg, yaw_deg
 * - `navigation.csv`: the same columns, then horizontal_sigma_m, up_sigma_m from the pose covariance
 * - `usbl_fixes.csv`: stamp_s, arrival_s, latitude_deg, longitude_deg, easting_m, northing_m, horizontal_sigma_m
 * - `datum.json`: the dive's geodetic datum (UTM zone, hemisphere, EPSG, origin), once it has arrived.
 *
 * Conventions: stamps are header stamps in seconds since the epoch, printed exactly (sec.nanosec); arrival_s is the
 * ROS clock (sim time in a replay) when the fix reached this node. Positions are UTM metres (z up). Angles are the
 * body-to-world rotation of the message as roll, pitch, yaw about x, y, z (tf2's getRPY convention); in the ENU
 * `utm` frame yaw is counter-clockwise from east (heading clockwise from grid north = 90 - yaw_deg). A sigma is the
 * per-axis 1-sigma in metres, sqrt((var_e + var_n) / 2) horizontally ("nan" when the covariance says unknown).
 * Numbers are printed in their shortest exact form, so reading a CSV back gives the message's doubles bit for bit.
 * USBL easting/northing are in the datum's zone; fixes that come before the datum wait for it (at shutdown without
 * one, they are written with nan easting/northing). USBL rows keep the arrival order, which a varying acoustic
 * latency may make differ slightly from the stamp order.
 *
 * The node never overwrites and never interleaves two timelines in one file. At start-up it takes the newest set of
 * files in the folder as possibly its own, restarted after a crash: the first message decides. Stamped at most a
 * second before the files' last row and at most `~resume_max_gap_s` after it, it continues that timeline and the rows
 * are appended (a partial last row, cut by the crash, is removed first); otherwise (a bag played again, another dive)
 * the node starts a new set with a suffix (`ground_truth_2.csv`, ...). The same happens when the ROS clock or a topic's
 * stamps jump back mid-run (`rosbag play --loop`). Rows go to the final file names as whole lines, flushed every
 * `~flush_period_s` and at shutdown, so after a crash every file holds whole rows up to the last flush.
 */
#pragma once

#include <cstdint>
#include <deque>
#include <memory>
#include <string>

#include <diagnostic_updater/diagnostic_updater.h>
#include <exocet_msgs/GeoDatum.h>
#include <nav_msgs/Odometry.h>
#include <ros/ros.h>
#include <sensor_msgs/NavSatFix.h>

#include "exocet_mosaic/dive/dive_records.h"
#include "exocet_mosaic/ros/dive_topics.h"

namespace exocet_mosaic {

/// Settings of TrajectoryLogger. Each is the private parameter of the same name (`~output_dir`, ...).
struct TrajectoryLoggerConfig {
  std::string output_dir;       ///< required: folder of the files, created if missing
  double flush_period_s = 1.0;  ///< wall-clock period between writes to disk, in (0, 60]
  std::string ground_truth_topic = topics::kGroundTruthOdometry;  ///< nav_msgs/Odometry
  std::string navigation_topic = topics::kNavOdometry;            ///< nav_msgs/Odometry
  std::string usbl_topic = topics::kNavUsbl;                      ///< sensor_msgs/NavSatFix
  std::string datum_topic = topics::kNavDatum;                    ///< exocet_msgs/GeoDatum
  std::string utm_frame = frames::kUtm;  ///< the only header.frame_id accepted on the odometry topics
  /// The newest set of files in the folder is appended to when the first message comes at most this long after its
  /// last row (s, (0, 1e6]): a restart mid-dive.
  double resume_max_gap_s = 600.0;
};

/**
 * @brief Reads and checks every parameter of the logger from `private_nh`.
 * @throws std::invalid_argument naming the parameter, its value and the allowed range, for a missing `~output_dir`,
 *         a value of the wrong type or out of range, or an invalid topic name.
 */
TrajectoryLoggerConfig readTrajectoryLoggerConfig(const ros::NodeHandle& private_nh);

/**
 * @brief Routes SIGINT and SIGTERM to TrajectoryLogger::spinUntilStopped() so that it can drain the messages
 * already received and flush before exiting. Call after ros::init(..., ros::init_options::NoSigintHandler).
 */
void installStopSignalHandlers();

/**
 * @brief Subscribes to the ground truth, navigation, USBL and datum topics and writes the CSV files described in
 * this file's header. Bad messages (NaN or infinite fields, a frame other than `~utm_frame`, unset or
 * out-of-order stamps, an invalid datum) are counted, warned about (throttled per topic) and skipped; disk errors
 * are reported and retried at the next flush. Counts, rates, rejections and files are published on /diagnostics.
 * Single-threaded: call spinUntilStopped() (or ros::spin()) from one thread.
 */
class TrajectoryLogger {
 public:
  /**
   * @brief Reads the parameters, creates the first set of files and subscribes.
   * @param nh node handle the topics are resolved in
   * @param private_nh node handle of the parameters (`~`)
   * @throws std::invalid_argument for a bad parameter; std::runtime_error if `~output_dir` cannot be written
   */
  TrajectoryLogger(ros::NodeHandle nh, ros::NodeHandle private_nh);

  /// Writes what is buffered and closes the files (fsync'ed), logging how many rows each received.
  ~TrajectoryLogger();

  TrajectoryLogger(const TrajectoryLogger&) = delete;
  TrajectoryLogger& operator=(const TrajectoryLogger&) = delete;

  /**
   * @brief Processes callbacks until ROS shuts down or a stop signal arrives (see installStopSignalHandlers()).
   * After a first stop signal it keeps processing for up to 2 s of wall time, until 0.3 s pass without a
   * message, so that the last messages of a bag that just ended are not lost; then it flushes.
   */
  void spinUntilStopped();

  /// Writes the buffered rows of every open file now (also done every `~flush_period_s`). Never throws.
  void flush();

  /// The settings in force.
  const TrajectoryLoggerConfig& config() const { return config_; }

 private:
  class CsvFile;
  struct FileSet;

  /// Lets a message through once per period of wall time. ROS_*_THROTTLE measure ROS time instead, which a fast
  /// replay speeds up (a warning every 0.25 s of wall time at -r 20) and a restarted replay sends back.
  struct Throttle {
    ros::WallTime last;
    uint64_t suppressed = 0;  ///< messages held back since the last one let through
    /// True if a message may be logged now; then `*held_back` is how many were suppressed before it.
    bool allow(double period_s, uint64_t* held_back);
  };

  /// Counters and time-order state of one input topic.
  struct Stream {
    std::string label;  ///< e.g. "ground truth"
    std::string topic;
    uint64_t received = 0;
    uint64_t logged = 0;
    uint64_t rejected = 0;
    std::string last_rejection;
    ros::Time last_stamp;     ///< latest header stamp accepted; zero before the first
    uint64_t generation = 0;  ///< file-set generation this stream's timeline belongs to
    // Since the last diagnostics report:
    uint64_t window_logged = 0;
    uint64_t window_rejected = 0;
    ros::Time window_first_stamp;
    ros::Time window_last_stamp;
    Throttle warnings;  ///< per topic, so that one noisy topic does not hide another's problems
  };

  /// A USBL fix that arrived before any datum: converted and written once the datum comes.
  struct PendingFix {
    ros::Time stamp;
    ros::Time arrival;
    double latitude_deg = 0.0;
    double longitude_deg = 0.0;
    double horizontal_sigma_m = 0.0;
  };

  void onGroundTruth(const nav_msgs::Odometry::ConstPtr& msg);
  void onNavigation(const nav_msgs::Odometry::ConstPtr& msg);
  void onUsbl(const sensor_msgs::NavSatFix::ConstPtr& msg);
  void onDatum(const exocet_msgs::GeoDatum::ConstPtr& msg);
  void onFlushTimer(const ros::SteadyTimerEvent& event);
  void onDiagnosticsTimer(const ros::SteadyTimerEvent& event);

  /// Validates and writes one odometry message; `with_sigma` adds the covariance columns (navigation.csv).
  void logOdometry(Stream* stream, const nav_msgs::Odometry& msg, bool with_sigma);
  /// Writes one fix into `set` with its easting/northing in the current datum's zone (NaN if there is none).
  void writeFix(Stream* stream, FileSet* set, const PendingFix& fix);
  /// Starts a new file set when the ROS clock has gone backwards (a replay restarted).
  void checkClock();
  /**
   * Places a message of `stream` stamped `stamp` in time: returns the file set it belongs to, or nullptr if it is
   * rejected as out of order. A jump back by more than a second starts a new file set; a message still in flight
   * from before a jump goes to the previous set. `reorder_ok` accepts small regressions (USBL fixes, whose
   * acoustic latency varies).
   */
  FileSet* placeInTime(Stream* stream, const ros::Time& stamp, bool reorder_ok);
  void startNewFileSet(const std::string& reason);
  std::unique_ptr<FileSet> openFileSet(int first_index);
  /// The newest complete set of files in the folder, opened for appending; nullptr when there is none.
  std::unique_ptr<FileSet> reopenNewestFileSet();
  /// At the first message (stamped `stamp`): appends to the reopened set, or starts a new one, and says which.
  void decideOnReopenedSet(const ros::Time& stamp);
  void writeDatumFile(FileSet* set);
  void closeFileSet(FileSet* set);
  void convertPendingFixes();
  void reject(Stream* stream, const std::string& field, const std::string& problem);
  void noteWriteError(const std::string& path, const std::string& error);
  void diagnoseStream(Stream* stream, diagnostic_updater::DiagnosticStatusWrapper& status);
  void diagnoseUsbl(diagnostic_updater::DiagnosticStatusWrapper& status);
  void diagnoseDatum(diagnostic_updater::DiagnosticStatusWrapper& status);
  void diagnoseFiles(diagnostic_updater::DiagnosticStatusWrapper& status);

  TrajectoryLoggerConfig config_;
  std::string output_dir_abs_;
  ros::NodeHandle nh_;
  ros::NodeHandle private_nh_;
  diagnostic_updater::Updater updater_;

  Stream ground_truth_;
  Stream navigation_;
  Stream usbl_;
  Stream datum_stream_;

  std::unique_ptr<FileSet> current_set_;
  std::unique_ptr<FileSet> previous_set_;  ///< kept open for messages still in flight when a replay restarted
  uint64_t generation_ = 0;                ///< incremented by each new file set
  uint64_t clock_generation_ = 0;          ///< generation the ROS clock's timeline belongs to
  ros::Time last_clock_;
  uint64_t clock_jumps_ = 0;
  bool reopened_pending_ = false;  ///< current_set_ is the folder's newest set, reopened; the first message decides
  ros::Time reopened_last_stamp_;  ///< the newest stamp of its rows (zero: none)
  std::string resume_note_;        ///< what became of it, for /diagnostics

  bool have_datum_ = false;
  exocet_msgs::GeoDatum datum_msg_;
  exocet_common::GeoReference datum_;
  std::deque<PendingFix> pending_fixes_;
  uint64_t fixes_written_unconverted_ = 0;

  Throttle pending_warnings_;
  Throttle write_error_messages_;
  uint64_t write_errors_ = 0;
  uint64_t window_write_errors_ = 0;
  std::string last_write_error_;

  ros::Subscriber ground_truth_sub_;
  ros::Subscriber navigation_sub_;
  ros::Subscriber usbl_sub_;
  ros::Subscriber datum_sub_;
  ros::SteadyTimer flush_timer_;
  ros::SteadyTimer diagnostics_timer_;
};

}  // namespace exocet_mosaic
