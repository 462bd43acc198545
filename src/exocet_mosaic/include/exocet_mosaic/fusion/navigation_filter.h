/**
 * @file navigation_filter.h
 * @brief The 2D3 report's Kalman filter (section 3.5: UTM position of the camera + pixel-size correction, corrected
 * by the navigation), extended: heading error of the attitude, dead-reckoning offset, late (out-of-sequence) USBL
 * fixes, gating with recovery. No ROS in it.
 *
 * ## State (filter_log.h, StateIndex)
 * x = [E, N, c, psi, psi_dot, dE, dN, s]: camera centre (UTM), pixel-size correction, heading error of the attitude
 * and its drift rate (gyro bias), dead-reckoning (DR) offset, and the DR's velocity scale-factor error.
 *
 * ## Models (an extended Kalman filter)
 * - Image motion m (metres, from toMetricMotion, covariance R_m) between the previous image's stamp a and the
 *   current one b is the filter's prediction (the report's control input): over a part [u, v] of [a, b], with
 *   f = (v - u) / (b - a) (constant velocity between two images):
 *     p' = p + (1 + c) R(-psi) f m,   noise (1 + c)^2 R(-psi) (f R_m) R(-psi)^T + f S(m)
 *                                       + position_noise_m2_per_s (v - u) I,
 *   S(m) = image_step_noise_along_m^2 u u^T + image_step_noise_across_m^2 (I - u u^T), u = m / |m|: the extra
 *   noise of one step along and across its own motion (a registration's error is not isotropic: with the image
 *   moving along one axis, the overlap, the motion blur and the altitude's error all differ along and across it).
 *   R(-psi) undoes the heading error: the attitude that turned the image motion into east/north has yaw + psi.
 * - Heading: psi' = psi + psi_dot dt, psi_dot a random walk (integrated random walk, exact discretisation);
 *   c a slow random walk.
 * - Dead-reckoning offset: d' = d + dr_offset_noise (variance dr_offset_noise_m2_per_m per metre travelled
 *   + dr_offset_noise_m2_per_s per second). When the DR and the camera attitude share their heading (the same gyro:
 *   FilterConfig::dr_shares_heading), the DR's heading error moves the offset deterministically:
 *     d' = d + (1 + c) (I - R(-psi)) f m,
 *   so that the DR and the images, which see the same heading error, are not counted as independent evidence.
 * - DR scale factor: the DR integrates a velocity (DVL) with a scale error s, so its offset also grows by s times
 *   each displacement, d' += s (1 + c) R(-psi) f m; s is a slow random walk. Without it the scale error (0.3 % is
 *   15 cm over 50 m, back to zero on the return) has to be modelled as a random walk that is far too loose on
 *   short distances and too tight on long ones; with it the DR is the precise relative sensor it is.
 * - No image motion over an interval (registration failure, a gap in the images, dead reckoning or fixes ahead of
 *   the image stream): p is kept with a large random walk (no_motion_position_noise_m2_per_s): the next DR update,
 *   z_DR = p + d + v, then carries the position by the DR's increments (d is known from before), with the
 *   covariance they deserve; without DR, the covariance just grows.
 * - Dead reckoning (camera centre from the DR track): z = p + d + v, v ~ N(0, dr_measurement_sigma_m^2 I). The
 *   first DR after initialize()/reset() (or after a DR recovery) initialises d = z - p exactly (no information on p).
 *   The DR's reported covariance is checked but not used as measurement noise: it is the DR's absolute drift,
 *   correlated over the whole dive, which the offset state models instead.
 * - Absolute fix (USBL camera centre): z = p + v, v ~ N(0, covariance given).
 *
 * ## Time
 * Events come in ARRIVAL order. The filter processes them in stamp order: it keeps a history (history_s) of its
 * steps and events, and an event whose stamp is older than the latest processed stamp is inserted and the later
 * events are processed again (rewind). So a USBL fix arriving 1.5 s late, or dead reckoning a little ahead of the
 * image stream, gives exactly the result of in-order processing (the filter's result depends only on the set of
 * events, not on their arrival order).
 * - Fixes may come in any order: older than the history window (or the initialisation) -> kTooOld.
 * - Image events and DR must each be in increasing stamp order within their own stream (they may interleave with
 *   each other and with fixes); a stamp going back within its stream -> kInvalid. A stamp going back further than
 *   the window, or jumping forward by more than max_prediction_gap_s, is a clock jump: kInvalid with a detail; the
 *   caller should reset().
 *
 * ## Gating and recovery
 * Fixes and DR are gated on their Mahalanobis distance (chi-square, 2 dof, gate_probability). After
 * `recovery_rejections` consecutive rejected fixes the filter declares itself lost (e.g. after a long dropout in
 * which its position drifted beyond its covariance) and re-anchors at the fix: p = z with the fix's covariance,
 * heading, drift and pixel size kept, the DR offset re-initialised at the next DR (the step is marked as a
 * discontinuity for the smoother). After `recovery_rejections` consecutive rejected DR positions (the DR track
 * jumped, e.g. reset by the vehicle), the DR offset is re-initialised at that DR.
 */
#pragma once

#include <cstdint>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "exocet_mosaic/fusion/filter_log.h"
#include "exocet_mosaic/fusion/filter_step_file.h"
#include "exocet_mosaic/fusion/metric_motion.h"

namespace exocet_mosaic {
namespace fusion {

struct FilterConfig {
  // --- Image motion and position ---
  /// Position random walk with image motion (m^2/s, >= 0): unmodelled motion errors per second.
  double position_noise_m2_per_s = 1e-6;
  /// Extra 1-sigma per image step (m, >= 0) along the step's motion: errors the registration's covariance does not
  /// hold (flat-seabed conversion, relief, refraction, the altitude's error).
  double image_step_noise_along_m = 0.001;
  /// The same across the step's motion (m, >= 0).
  double image_step_noise_across_m = 0.001;
  /// Position random walk when no image motion covers an interval (m^2/s, > 0): the vehicle's motion is unknown
  /// there (0.25 = 0.5 m/s of unknown speed over one second).
  double no_motion_position_noise_m2_per_s = 0.25;
  /// Assumed speed over ground (m/s, >= 0) for the DR offset's growth where no image motion measures the distance.
  double no_motion_speed_mps = 0.5;

  // --- Pixel-size correction c ---
  double initial_pixel_size_correction_sigma = 0.02;     ///< 1-sigma at initialisation (relative, >= 0)
  double pixel_size_correction_noise_per_sqrt_s = 1e-4;  ///< random walk (1/sqrt(s), >= 0)

  // --- Heading error of the attitude ---
  double initial_heading_sigma_rad = 0.02;           ///< 1-sigma at initialisation (rad, >= 0)
  double initial_heading_drift_sigma_rps = 2e-4;     ///< 1-sigma of the gyro bias at initialisation (rad/s, >= 0)
  double heading_noise_rad_per_sqrt_s = 1e-4;        ///< angle random walk (rad/sqrt(s), >= 0)
  double heading_drift_noise_rps_per_sqrt_s = 2e-5;  ///< bias instability (rad/s/sqrt(s), >= 0)

  // --- Dead reckoning ---
  double dr_measurement_sigma_m = 0.01;     ///< white noise of one DR position, each axis (m, > 0)
  double dr_offset_noise_m2_per_m = 1e-3;   ///< DR offset random walk per metre travelled (m^2/m, >= 0)
  double dr_offset_noise_m2_per_s = 1e-6;   ///< DR offset random walk per second (m^2/s, >= 0)
  double initial_dr_scale_sigma = 0.01;     ///< 1-sigma of the DR's velocity scale error at the start ([0, 0.5))
  double dr_scale_noise_per_sqrt_s = 1e-5;  ///< random walk of the DR's scale error (1/sqrt(s), >= 0)
  /// The DR's heading comes from the same gyro as the attitude used for the images (the usual ROV set-up, and the
  /// simulator's): its heading error moves the DR offset through psi (see the file comment).
  bool dr_shares_heading = true;

  // --- Gating ---
  /// Probability of the chi-square (2 dof) gate on fixes and DR, in (0, 1): 0.999 -> Mahalanobis^2 <= 13.8.
  double gate_probability = 0.999;
  /// Consecutive rejections (>= 1) of one source (fixes, or DR) after which the filter recovers (see above).
  int recovery_rejections = 5;

  // --- Time ---
  /// How long (s, > 0) the filter keeps its steps and events for out-of-sequence fixes (USBL latency + margin).
  double history_s = 10.0;
  /// Largest forward jump (s, > 0) between the latest processed stamp and a new event; larger is a clock jump.
  double max_prediction_gap_s = 300.0;

  /// "" or each problem, naming the field and its allowed range.
  std::string validate() const;
  /// S(m) of the file comment, for a step's motion m (m, east/north); isotropic (the mean of the two variances) for
  /// a motion shorter than 1 micrometre, whose direction means nothing.
  Eigen::Matrix2d imageStepNoiseCovariance(const Eigen::Vector2d& motion_m) const;
  /// Mahalanobis^2 threshold of the gate: the chi-square (2 dof) quantile -2 ln(1 - gate_probability).
  double gateThreshold() const;
};

enum class UpdateStatus { kApplied, kRejectedByGate, kTooOld, kInvalid, kNotInitialized };
/// "applied", "rejected_by_gate", "too_old", "invalid", "not_initialized".
std::string toString(UpdateStatus status);

struct UpdateResult {
  UpdateStatus status = UpdateStatus::kInvalid;
  double mahalanobis_sq = 0.0;  ///< of the innovation (fixes and DR; 0 for image events)
  std::string detail;           ///< what happened: the distance against the gate, why invalid or too old
};

class NavigationFilter {
 public:
  /// @throws std::invalid_argument with validate()'s text.
  explicit NavigationFilter(const FilterConfig& config);

  const FilterConfig& config() const { return config_; }
  /// Changes the gate mid-dive (dynamic_reconfigure): it applies to the next event, and to events re-processed
  /// after a late fix. @throws std::invalid_argument naming the value and its allowed range.
  void setGating(double gate_probability, int recovery_rejections);

  /// Starts (or restarts) the filter at a camera position with its covariance (m^2), e.g. the operator's first
  /// position or the first fix. Heading, drift and pixel size start at 0 with their configured sigmas.
  /// @throws std::invalid_argument for a non-finite stamp or position, or a covariance not symmetric positive
  ///         definite.
  void initialize(double stamp_s, const Eigen::Vector2d& camera_en_m, const Eigen::Matrix2d& covariance_m2);
  /**
   * @brief Starts the filter from a whole saved state at its stamp (a restart of the node mid-dive): x and P as
   * FilterState::x / P gave them. With `dr_offset_known` the dead-reckoning offset in x is taken as known, so the
   * first dead reckoning after the gap carries the position by its own increments (no image motion covers the gap:
   * the position's covariance grows with the no-motion random walk up to the next input).
   * @throws std::invalid_argument for a non-finite stamp or state, or a covariance not symmetric positive
   *         semi-definite (its position block definite).
   */
  void resume(double stamp_s, const StateVector& x, const StateMatrix& P, bool dr_offset_known);
  bool initialized() const { return initialized_; }
  /// The dead-reckoning offset is known at the latest stamp (a first dead reckoning has set it).
  bool drOffsetKnown() const;
  /// Forgets everything (clock jump, new dive): initialize() again before adding events.
  void reset();

  /// Image motion between the images stamped previous_stamp_s and stamp_s (see the file comment).
  UpdateResult addImageMotion(double previous_stamp_s, double stamp_s, const MetricMotion& motion);
  /// Registration failed for this pair: no image motion over [previous_stamp_s, stamp_s].
  UpdateResult addImageFailure(double previous_stamp_s, double stamp_s);
  /// Dead-reckoning camera centre (UTM) at stamp_s; its reported covariance (m^2) must be finite and positive
  /// definite (it is not used as measurement noise, see the file comment).
  UpdateResult addDeadReckoning(double stamp_s, const Eigen::Vector2d& camera_en_m,
                                const Eigen::Matrix2d& covariance_m2);
  /// Absolute fix (USBL) of the camera centre, stamped at measurement time (it may arrive late).
  UpdateResult addAbsoluteFix(double stamp_s, const Eigen::Vector2d& camera_en_m, const Eigen::Matrix2d& covariance_m2);

  /// At the latest stamp processed (default FilterState before initialisation).
  FilterState current() const;
  /// The posterior of the last step at or before stamp_s (the state at an input's stamp even when later inputs were
  /// processed before it, e.g. a late image motion); current() when stamp_s is before every step kept.
  FilterState stateAt(double stamp_s) const;
  /// Extrapolated to a later stamp (no state change): with the velocity of the latest image motion when it ends
  /// within one second of the latest stamp (its covariance scaled to the time), else kept in place with the
  /// no-motion random walk. A stamp at or before the latest returns current().
  FilterState predictedAt(double stamp_s) const;

  /// The steps kept: every step since initialize() when the log is kept (default), otherwise only those within the
  /// history window (what the out-of-sequence handling needs).
  const FilterLog& log() const { return log_; }
  void setKeepLog(bool keep);
  bool keepLog() const { return keep_log_; }
  /**
   * @brief With a kept log, writes the steps that leave the history window to `path` (a FilterStepFile, created or
   * truncated) instead of holding them: memory stays bounded however long the dive. "" holds them in memory.
   * Steps a write fails on (disk full) stay in memory and are written with the next ones.
   * @throws std::runtime_error when the file cannot be created
   */
  void setLogFile(const std::string& path);
  /// Every step since initialize() when the log is kept: the written ones read back, then log(). A copy: for the
  /// smoother and the track files. @throws std::runtime_error when the file cannot be read back
  FilterLog wholeLog() const;
  /// Steps written to the log file (0 without one), and its last write error ("" if none).
  uint64_t loggedToFile() const;
  std::string logFileError() const;

  /// Counters since initialize(), after re-processing (a fix first applied may be rejected on a rewind, and back).
  struct Counters {
    long image_motions = 0, image_failures = 0, rewinds = 0, steps_processed = 0, recoveries = 0;
  };
  const Counters& counters() const { return counters_; }

 private:
  enum class EventKind { kImage = 0, kDeadReckoning = 1, kFix = 2 };
  struct Event {
    EventKind kind = EventKind::kImage;
    double stamp_s = 0.0;
    double previous_stamp_s = 0.0;                    ///< images: start of the interval
    bool image_failed = false;                        ///< images: registration failed (no motion over the interval)
    Eigen::Vector2d value = Eigen::Vector2d::Zero();  ///< image displacement, DR or fix position (m)
    Eigen::Matrix2d covariance = Eigen::Matrix2d::Zero();
    uint64_t sequence = 0;  ///< arrival order, to order same-kind events at one stamp
  };
  struct Working {  ///< the filter's state while processing
    double stamp_s = 0.0;
    StateVector x;
    StateMatrix P;
    int consecutive_fix_rejections = 0;
    int consecutive_dr_rejections = 0;
    bool dr_initialized = false;
  };

  UpdateResult addImageEvent(const Event& event);
  /// Inserts the event, re-processes every step from the first one it affects (steps after `affected_from_s`, or
  /// at it when `inclusive`), and returns the event's own result.
  UpdateResult insertAndProcess(Event* event, double affected_from_s, bool inclusive);
  void processFrom(const Working& start, bool from_prior, uint64_t watched_sequence, UpdateResult* watched);
  /// Prediction to `to_s` through the image motions (and gaps) that cover the interval.
  void predict(Working* w, double to_s, StateMatrix* transition) const;
  /// One linearised prediction over dt_s: with a fraction of an image motion (motion_m and motion_cov already
  /// scaled by image_fraction), or with no motion information when motion_m is null.
  void predictSegment(Working* w, double dt_s, double image_fraction, const Eigen::Vector2d* motion_m,
                      const Eigen::Matrix2d* motion_cov, StateMatrix* transition) const;
  UpdateResult applyUpdate(Working* w, const Event& event, FilterStep* step);
  void prune();
  std::string checkStamp(double stamp_s) const;
  double latestStamp() const;
  double windowStart() const { return latestStamp() - config_.history_s; }
  Working workingFrom(const FilterStep& step, bool prior) const;
  void startAt(double stamp_s, const StateVector& x, const StateMatrix& P, bool dr_offset_known);

  FilterConfig config_;
  bool initialized_ = false;
  bool keep_log_ = true;
  FilterLog log_;
  std::unique_ptr<FilterStepFile> log_file_;  ///< the steps written out (setLogFile), or null
  std::vector<Event> events_;                 ///< within the history window, sorted by (stamp, kind, sequence)
  uint64_t next_sequence_ = 0;
  double initial_stamp_s_ = 0.0;
  bool initial_dr_known_ = false;  ///< resume(): the offset was known at the first step
  /// Stamp of the oldest state a rewind may restart from (-inf: the initial state itself, nothing pruned yet).
  double rewind_floor_s_ = -std::numeric_limits<double>::infinity();
  double last_image_stamp_s_ = 0.0, last_dr_stamp_s_ = 0.0;
  bool have_image_ = false, have_dr_ = false;
  Counters counters_;
};

}  // namespace fusion
}  // namespace exocet_mosaic
