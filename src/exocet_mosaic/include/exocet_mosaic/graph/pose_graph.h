/**
 * @file pose_graph.h
 * @brief A 2-D pose graph of a dive's key frames, solved with Ceres, incrementally: the camera's position on the
 * seabed plane (east, north, metres, UTM or a local grid) and its yaw (rad, ENU: counter-clockwise from east) per key
 * frame. No ROS in it; not thread-safe (BackgroundPoseGraph, background_pose_graph.h, runs one in a worker thread).
 *
 * Factors, each whitened by its covariance (checked symmetric positive definite and finite):
 *  - odometry: the pose of a key frame in the frame of an earlier one (dx, dy along the earlier frame's axes, dyaw),
 *    3x3 covariance, from the registration chain;
 *  - position fixes (USBL): (E, N) at a stamp with a 2x2 covariance; a fix stamped between two key frames constrains
 *    the linear interpolation of their positions, one after the last key frame waits for the next key frame; a
 *    Cauchy loss (PoseGraphConfig::position_fix_cauchy_scale) so that an outlier has little pull, unless the fix is
 *    added as not robust (a prior the caller trusts: the navigation's start, whose error a Cauchy loss at the USBL's
 *    scale would read as an outlier once the fixes' average pulls a few sigmas away from it);
 *  - relative positions (dead reckoning): the position of a key frame in the frame of an earlier one (dx, dy along the
 *    earlier frame's axes, no yaw), 2x2 covariance, under the fixes' Cauchy loss (a reset of the vehicle's dead
 *    reckoning is a jump the images contradict);
 *  - headings (attitude sensor): yaw of a key frame with a 1-sigma, the difference wrapped to (-pi, pi];
 *  - loop closures: the relative pose of two non-consecutive key frames, 3x3 covariance, switchable (below);
 *  - gauge: while no position fix is attached, a weak prior holds the first key frame at its initial pose, so that
 *    the problem is never singular.
 *
 * Loop closures are switchable constraints (Sunderhauf & Protzel, IROS 2012): each loop has a switch s in [0, 1]
 * that scales its whitened residual, r = s W e, plus a prior residual sqrt(loop_gate_chi2) (1 - s). For a fixed map
 * the optimal switch is s = gate / (gate + chi2), chi2 = |W e|^2 the loop's squared Mahalanobis error, so the loop
 * keeps more than half its weight (s > 0.5, "accepted") exactly when its error at the optimum is below the
 * chi-square gate: the switch prior's weight is the gate, chosen as a chi-square quantile with 3 degrees of freedom
 * (11.34: 99 %). Switches were chosen over a robust loss (Cauchy, DCS) because the switch is an explicit, reportable
 * decision per loop, and because the optimiser decides it jointly with the map: a false loop's switch goes to ~0 and
 * leaves a pull of s^2 of its weight (a 1 m error at 2 cm 1-sigma keeps ~1e-5 of it), while a true loop bends the
 * map until its error is small and keeps s near 1.
 *
 * Switchable constraints alone have a weakness: started at s = 1 far from a true loop (a long drift between its
 * ends), the optimiser can cut the switch before the map has bent, and stay there (s^2 removes the loop's pull).
 * Each new loop is therefore first tested for consistency with the graph: its window is solved without it (switch
 * held at 0), then with it enforced (switch held at 1), over its span widened by loop_margin_keyframes; the increase of
 * the graph's chi2 is the loop's Mahalanobis error including the map's own uncertainty, chi-square with 3 degrees of
 * freedom for a true loop. The switch starts at 1 (and the map bent) when that increase is below loop_gate_chi2, at 0
 * (the map restored) otherwise; then every switch is optimised jointly with the map, so that later evidence can still
 * turn a loop on or off.
 *
 * Incremental solving: every factor remembers the key frames it touches; solve() with WindowPolicy::kAffected
 * re-optimises only the key frames touched by factors added since the last solve, widened by
 * window_margin_keyframes on each side, and every key frame between the two ends of a new loop (the span a loop
 * bends), widened by loop_margin_keyframes. Every factor touching one of them is included; the other key frames it
 * touches are held constant. Each solve is bounded in time (max_solver_time_s) and iterations. solveFull() re-optimises
 * everything.
 */
#pragma once

#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace ceres {
class CostFunction;
class LossFunction;
class Problem;
}  // namespace ceres

namespace exocet_mosaic {
namespace graph {

/// A key frame's pose on the seabed plane.
struct Pose2d {
  Eigen::Vector2d position_en_m = Eigen::Vector2d::Zero();  ///< camera centre (east, north), metres
  double yaw_rad = 0.0;                                     ///< heading of the key frame's x axis, ENU, rad
};

/// A key frame's current estimate.
struct KeyFramePose {
  int64_t id = 0;
  double stamp_s = 0.0;
  Pose2d pose;
  /// pose - initial pose: the correction of the graph to the chain's estimate (metres; yaw wrapped, rad)
  Eigen::Vector2d correction_en_m = Eigen::Vector2d::Zero();
  double correction_yaw_rad = 0.0;
};

/// The pose of a key frame B in the frame of a key frame A.
struct RelativePose2d {
  Eigen::Vector2d translation_m = Eigen::Vector2d::Zero();  ///< p_B - p_A along A's axes (x, y), metres
  double yaw_rad = 0.0;                                     ///< yaw_B - yaw_A, rad
};

/// `angle_rad` wrapped to (-pi, pi].
double wrapAngle(double angle_rad);
/// The pose of `to` in the frame of `from`.
RelativePose2d between(const Pose2d& from, const Pose2d& to);
/// The pose at `delta` from `from` (the inverse of between()).
Pose2d compose(const Pose2d& from, const RelativePose2d& delta);

struct PoseGraphConfig {
  /// Which key frames solve() re-optimises.
  enum class WindowPolicy {
    kFull,      ///< all of them, every time
    kAffected,  ///< those touched by factors added since the last solve, and the span of each new loop
  };
  WindowPolicy window_policy = WindowPolicy::kAffected;
  int window_margin_keyframes = 10;  ///< key frames added on each side of an affected one, >= 0
  /// Key frames added on each side of a new loop's span, in the window of the solve and of its consistency test,
  /// >= 0: the map beyond them is held, so a small margin makes the map stiffer than it is and the test stricter.
  int loop_margin_keyframes = 100;
  /// Cauchy scale of the position fixes, in whitened units (sigmas), >= 0; 0: plain least squares. 3: a fix within
  /// 3 sigmas keeps at least half its weight, a 10-sigma outlier 8 % of it.
  double position_fix_cauchy_scale = 3.0;
  /// Chi-square gate of the loop closures (3 degrees of freedom), > 0: the weight of each switch's prior, a loop is
  /// accepted when its switch ends above 0.5, i.e. its Mahalanobis error squared below the gate. 11.34: 99 %.
  double loop_gate_chi2 = 11.34;
  double gauge_sigma_m = 100.0;     ///< 1-sigma of the gauge prior's position, metres, > 0 (weak)
  double gauge_sigma_rad = 3.0;     ///< 1-sigma of the gauge prior's yaw, rad, > 0 (weak)
  double max_solver_time_s = 1.0;   ///< wall-time bound of one solve, seconds, > 0
  int max_iterations = 100;         ///< Levenberg-Marquardt iterations per solve, >= 1
  double moved_threshold_m = 1e-3;  ///< a key frame "moved" in a solve when its position changed more, metres, >= 0
  int threads = 1;                  ///< Ceres threads, >= 1
  std::string validate() const;     ///< "" or each bad field with its allowed range
};

/// What one solve did.
struct SolveReport {
  bool full = false;            ///< every key frame was free (solveFull, or the window covered the graph)
  int keyframes_optimized = 0;  ///< free key frames
  int keyframes_held = 0;       ///< key frames outside the window held constant by the factors included
  int factors = 0;              ///< residual blocks in the problem
  int keyframes_moved = 0;      ///< free key frames whose position changed by more than moved_threshold_m
  double max_move_m = 0.0;      ///< largest change of position of a key frame
  int loops_tested = 0;         ///< new loops put through the consistency test in this solve
  int loops_passed = 0;         ///< of which consistent with the graph (switch started at 1)
  int iterations = 0;
  double cpu_s = 0.0;  ///< CPU seconds of the calling thread: the new loops' tests, building and solving
  double wall_s = 0.0;
  double initial_cost = 0.0, final_cost = 0.0;
  bool converged = false;  ///< Ceres reached a tolerance (not the time or iteration bound)
  int loops_accepted = 0;  ///< over the whole graph, after the solve
  int loops_rejected = 0;
  std::string message;  ///< Ceres' brief report, or why nothing was solved
};

/// A loop closure after the last solve that included it.
struct LoopStatus {
  int64_t from_id = 0, to_id = 0;
  double switch_value = 1.0;  ///< in [0, 1]
  double chi2 = 0.0;          ///< |W e|^2 of the unscaled residual at the current poses
  bool accepted = true;       ///< switch_value > 0.5
  /// Increase of the graph's chi2 when the loop was enforced (switch 1) in its first solve, against the graph
  /// without it: the loop's Mahalanobis error including the map's uncertainty. Its switch started at 1 when below
  /// loop_gate_chi2, at 0 otherwise.
  double consistency_chi2 = 0.0;
};

/**
 * @brief The key frames, the factors between them and their solution. Not thread-safe.
 *
 * Key frame ids and stamps strictly increase. Every add* checks its input and throws std::invalid_argument naming
 * the problem (unknown key frame id, non-finite value, covariance not symmetric positive definite) without changing
 * the graph.
 */
class PoseGraph {
 public:
  /// @throws std::invalid_argument when config.validate() is not empty
  explicit PoseGraph(const PoseGraphConfig& config = PoseGraphConfig());
  ~PoseGraph();
  PoseGraph(const PoseGraph&) = delete;
  PoseGraph& operator=(const PoseGraph&) = delete;

  /**
   * @brief Adds a key frame.
   * @param id greater than every id added before
   * @param stamp_s greater than every stamp added before, seconds
   * @param initial_pose the first estimate (e.g. the chain's), also the reference of GraphSnapshot's correction
   */
  void addKeyFrame(int64_t id, double stamp_s, const Pose2d& initial_pose);

  /**
   * @brief Adds an odometry factor: the pose of `to_id` in the frame of `from_id` (from_id < to_id, usually
   * consecutive key frames).
   * @param covariance 3x3 of (dx m, dy m, dyaw rad)
   */
  void addOdometry(int64_t from_id, int64_t to_id, const RelativePose2d& delta, const Eigen::Matrix3d& covariance);

  /**
   * @brief Adds a relative position (dead reckoning): the position of `to_id` in the frame of `from_id`
   * (from_id < to_id), without its yaw.
   * @param translation_m p_to - p_from along from's axes (x, y), metres
   * @param covariance_m2 2x2 of (dx, dy), m^2
   */
  void addRelativePosition(int64_t from_id, int64_t to_id, const Eigen::Vector2d& translation_m,
                           const Eigen::Matrix2d& covariance_m2);

  /**
   * @brief Adds a position fix at `stamp_s`, interpolated between the two key frames around it. A fix after the
   * last key frame waits for the next one; a fix before the first key frame is dropped.
   * @param covariance_m2 2x2 of (E, N), m^2
   * @param robust under the Cauchy loss (position_fix_cauchy_scale); false: plain least squares
   * @return false when dropped
   */
  bool addPositionFix(double stamp_s, const Eigen::Vector2d& position_en_m, const Eigen::Matrix2d& covariance_m2,
                      bool robust = true);

  /// Adds a heading of key frame `id`: yaw (rad, ENU) with a 1-sigma `sigma_rad` > 0.
  void addHeading(int64_t id, double yaw_rad, double sigma_rad);

  /**
   * @brief Adds a switchable loop closure: the pose of `to_id` in the frame of `from_id` (distinct key frames).
   * @param covariance 3x3 of (dx m, dy m, dyaw rad)
   * @return the loop's index (0, 1, ... in the order added), for loop() and loopAccepted()
   */
  int addLoop(int64_t from_id, int64_t to_id, const RelativePose2d& delta, const Eigen::Matrix3d& covariance);

  /// Re-optimises according to config().window_policy.
  SolveReport solve();
  /// Re-optimises every key frame.
  SolveReport solveFull();
  /// Re-optimises the key frames `ids` (each widened by window_margin_keyframes); the others are held constant.
  /// Factors added since the last solve stay pending for the next solve() (new
  /// loops touching these key frames are tested here already). @throws std::invalid_argument on an
  /// unknown id
  SolveReport solveAround(const std::vector<int64_t>& ids);

  /// The current estimate of key frame `id`. @throws std::invalid_argument on an unknown id
  Pose2d pose(int64_t id) const;
  /// The pose given to addKeyFrame. @throws std::invalid_argument on an unknown id
  Pose2d initialPose(int64_t id) const;
  double stamp(int64_t id) const;
  bool hasKeyFrame(int64_t id) const;
  /// Ids in increasing order.
  std::vector<int64_t> keyFrameIds() const;
  /// Every key frame's estimate and correction, increasing ids.
  std::vector<KeyFramePose> keyFramePoses() const;
  size_t numKeyFrames() const { return keyframes_.size(); }
  size_t numLoops() const { return loops_.size(); }
  size_t numPositionFixes() const { return fixes_attached_; }
  size_t numRelativePositions() const { return relative_positions_; }
  size_t numPendingPositionFixes() const { return pending_fixes_.size(); }
  size_t numFactors() const { return factors_.size(); }
  /// Factors added since the last solve() or solveFull().
  bool hasPendingChanges() const { return !dirty_.empty() || !dirty_loops_.empty(); }

  /// The status of loop `index`. @throws std::invalid_argument on a bad index
  LoopStatus loop(int index) const;
  bool loopAccepted(int index) const { return loop(index).accepted; }

  /**
   * @brief The 3x3 marginal covariance of (E m, N m, yaw rad) of key frame `id` at the current estimate, the loop
   * switches taken as known and a weak prior on every key frame (covarianceBlocks; ceres::Covariance over the
   * whole graph: expensive on a long dive, opt-in).
   * @return std::nullopt when Ceres cannot compute it (rank-deficient problem)
   */
  std::optional<Eigen::Matrix3d> covariance(int64_t id) const;

  /**
   * @brief The 2x2 marginal covariance of (E m, N m) of every key frame, in increasing id order, at the current
   * estimate, the loop switches taken as known and a weak prior on every key frame (a direction nothing constrains
   * has the prior's 1-sigma, not none): one ceres::Covariance over the whole graph.
   *
   * Its cost grows with the key frames asked for times the size of the factorisation (bench_pose_graph: 0.13 s of
   * CPU for 1000 key frames, 10 s for 9000). With `max_computed` > 0 at most that many are computed, evenly spread
   * in index (the first and the last always), and the covariance of each key frame between two computed ones is
   * interpolated linearly in index between theirs; 0: every one computed.
   * @return an empty vector when Ceres cannot compute them (rank-deficient problem) or the graph is empty
   */
  std::vector<Eigen::Matrix2d> positionCovariances(int max_computed = 0) const;

  const PoseGraphConfig& config() const { return config_; }

  /// A check made after each solver iteration: when it returns true the solve ends there, keeping its progress
  /// (SolveReport::converged false). nullptr: none.
  void setInterruptCheck(std::function<bool()> check) { interrupt_check_ = std::move(check); }

 private:
  enum class FactorType { kOdometry, kRelativePosition, kPositionFix, kHeading, kLoop, kGauge };
  struct KeyFrame {
    int64_t id;
    double stamp_s;
    Pose2d initial;
    double state[3];  ///< east, north relative to origin_en_m_, yaw: the Ceres parameter block
    std::vector<int> factors;
  };
  struct Factor {
    FactorType type;
    int a, b;  ///< key frame indices; b = -1 when the factor has a single key frame
    int loop = -1;
    std::unique_ptr<ceres::CostFunction> cost;
    ceres::LossFunction* loss = nullptr;  ///< owned by the graph
  };
  struct Loop {
    int from, to;  ///< key frame indices
    Eigen::Vector3d measured;
    Eigen::Matrix3d whitening;
    double switch_value = 1.0;  ///< the Ceres parameter block of the switch
    bool held = false;          ///< switch held constant (while testing new loops)
    bool tested = false;
    double consistency_chi2 = 0.0;
  };
  struct SolverRun {
    int iterations = 0;
    double initial_cost = 0.0, final_cost = 0.0;
    bool converged = true;
    std::string message;
    int factors = 0, held = 0;
  };
  struct PendingFix {
    double stamp_s;
    Eigen::Vector2d position_en_m;
    Eigen::Matrix2d whitening;
    bool robust;
  };

  int indexOf(int64_t id) const;  ///< -1 when unknown
  int requireIndex(int64_t id, const char* what) const;
  void addFactor(FactorType type, int a, int b, ceres::CostFunction* cost, ceres::LossFunction* loss, int loop = -1);
  void attachFix(const PendingFix& fix, int a, int b, double weight_b);
  void markDirty(int index);
  SolveReport solveWindow(const std::vector<char>& active);
  /// Solves over the `active` key frames (switches free unless held).
  SolverRun optimize(const std::vector<char>& active);
  /// The consistency test of the untested loops touching `active` (see the file comment); sets their switches.
  void testNewLoops(const std::vector<char>& active, SolveReport* report);
  /// Adds the factors touching `active` key frames to `problem`; returns how many.
  int buildProblem(const std::vector<char>& active, bool switches_free, ceres::Problem* problem, int* held);
  /// The 3x3 marginal covariances of the key frames at `indices` (ceres::Covariance over the whole graph with a weak
  /// prior, the gauge's sigmas, on every key frame at its estimate: Ceres needs a full-rank Jacobian, and a direction
  /// nothing constrains, a graph that one fix and no heading leave free to turn, then has the prior's 1-sigma instead
  /// of none; against centimetre factors the prior changes a marginal by about 1e-5 of itself). nullopt when Ceres
  /// cannot compute them.
  std::optional<std::vector<Eigen::Matrix3d>> covarianceBlocks(const std::vector<int>& indices) const;

  PoseGraphConfig config_;
  std::unique_ptr<ceres::LossFunction> fix_loss_;
  Eigen::Vector2d origin_en_m_ = Eigen::Vector2d::Zero();  ///< first key frame's initial position
  std::deque<KeyFrame> keyframes_;                         ///< a deque: the parameter blocks must not move
  std::deque<Loop> loops_;
  std::vector<Factor> factors_;
  std::vector<PendingFix> pending_fixes_;
  size_t fixes_attached_ = 0;
  size_t relative_positions_ = 0;
  int gauge_factor_ = -1;
  std::vector<int> dirty_;             ///< key frames touched by factors added since the last solve
  std::vector<int> dirty_loops_;       ///< loops added since the last solve
  std::vector<unsigned> factor_mark_;  ///< scratch: the build that last included each factor
  unsigned build_count_ = 0;
  std::function<bool()> interrupt_check_;
};

}  // namespace graph
}  // namespace exocet_mosaic
