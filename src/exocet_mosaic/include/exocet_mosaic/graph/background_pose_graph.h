/**
 * @file background_pose_graph.h
 * @brief A PoseGraph solved in a worker thread: producers (the registration chain, the navigation inputs) add key
 * frames and factors without ever waiting for a solve, consumers read the latest solution as an immutable snapshot.
 * No ROS in it.
 *
 * Threading: add* checks its input, appends it to a queue under a mutex held for the append only, and wakes the
 * worker. The worker takes the whole queue, applies it to its PoseGraph and solves with the graph's window policy
 * (bounded by PoseGraphConfig::max_solver_time_s), then publishes a new snapshot (an atomic swap of a
 * std::shared_ptr<const GraphSnapshot>) and calls the snapshot callback. When the queue is empty after a windowed
 * solve it settles the graph with a full solve, which it abandons (keeping its progress) as soon as new input
 * arrives, so that a long dive's full solve never delays the next window. Every wait is bounded.
 */
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <variant>
#include <vector>

#include "exocet_mosaic/graph/pose_graph.h"

namespace exocet_mosaic {
namespace graph {

/// The solution after one solve of the worker; never changed once published.
struct GraphSnapshot {
  uint64_t sequence = 0;                 ///< 1, 2, ... in publication order
  uint64_t inputs_applied = 0;           ///< add* calls applied to the graph (accepted ones)
  bool settled = false;                  ///< the last solve was a converged full solve over every input applied
  std::vector<KeyFramePose> key_frames;  ///< increasing ids
  std::vector<char> loop_accepted;       ///< per loop index
  SolveReport report;                    ///< of the solve that made this snapshot
  std::string last_error;                ///< the last input the worker could not apply ("" normally)
  /// Marginal covariance of (E, N) of each key frame of key_frames (m^2), from the last marginals computed (on a
  /// settled graph, PoseGraph::positionCovariances()); NaN for key frames added since; empty when none computed yet.
  std::vector<Eigen::Matrix2d> position_covariance_m2;
  uint64_t marginals_sequence = 0;  ///< the snapshot whose solution they are of (0: none yet)
  double marginals_cpu_s = 0.0;     ///< CPU seconds the last computation of the marginals took
  /// The key frame `id`, nullptr when not in the snapshot.
  const KeyFramePose* find(int64_t id) const;
};

struct BackgroundPoseGraphConfig {
  PoseGraphConfig graph;
  double idle_wait_s = 0.05;           ///< longest sleep of the worker between checks, seconds, > 0
  bool settle_with_full_solve = true;  ///< full solve when the queue runs dry after windowed solves
  /// The marginals of the key frames' positions are computed after a settling solve when the queue is empty, at most
  /// this fraction of the time (a computation of c seconds waits c / fraction after the previous one), [0, 1]; 0:
  /// never. Not interruptible: new input waits for a computation under way.
  double marginals_duty_cycle = 0.1;
  /// Key frames whose marginals are computed, the others interpolated (PoseGraph::positionCovariances), [2, 1e6]:
  /// bounds a computation at about a second of CPU on an hour-long dive (9000 key frames).
  int marginals_max_key_frames = 500;
  std::string validate() const;        ///< "" or each bad field with its allowed range
};

/**
 * @brief Owns a PoseGraph and the worker thread that solves it. add* may be called from any thread; they check
 * their input (unknown key frame ids among those already added, covariances, NaN) and throw std::invalid_argument
 * at once.
 */
class BackgroundPoseGraph {
 public:
  using SnapshotCallback = std::function<void(const std::shared_ptr<const GraphSnapshot>&)>;

  /// Starts the worker. `on_snapshot` is called in the worker after each publication; it must be quick and must
  /// not call stop(). @throws std::invalid_argument when config.validate() is not empty
  explicit BackgroundPoseGraph(const BackgroundPoseGraphConfig& config = BackgroundPoseGraphConfig(),
                               SnapshotCallback on_snapshot = nullptr);
  /// stop()s.
  ~BackgroundPoseGraph();
  BackgroundPoseGraph(const BackgroundPoseGraph&) = delete;
  BackgroundPoseGraph& operator=(const BackgroundPoseGraph&) = delete;

  /// As PoseGraph's, queued.
  void addKeyFrame(int64_t id, double stamp_s, const Pose2d& initial_pose);
  void addOdometry(int64_t from_id, int64_t to_id, const RelativePose2d& delta, const Eigen::Matrix3d& covariance);
  void addRelativePosition(int64_t from_id, int64_t to_id, const Eigen::Vector2d& translation_m,
                           const Eigen::Matrix2d& covariance_m2);
  void addPositionFix(double stamp_s, const Eigen::Vector2d& position_en_m, const Eigen::Matrix2d& covariance_m2,
                      bool robust = true);
  void addHeading(int64_t id, double yaw_rad, double sigma_rad);
  /// @return the loop's index, as the graph will number it
  int addLoop(int64_t from_id, int64_t to_id, const RelativePose2d& delta, const Eigen::Matrix3d& covariance);

  /// The latest snapshot (an empty one before the first solve); never blocks on a solve.
  std::shared_ptr<const GraphSnapshot> snapshot() const;

  /**
   * @brief Waits until every input added so far is applied and the graph is settled (or, without
   * settle_with_full_solve, solved), at most `timeout_s` seconds.
   * @return true when idle, false on timeout or after stop()
   */
  bool waitIdle(double timeout_s);

  /// Stops the worker (interrupting a solve after its current iteration) and joins it; queued inputs not yet
  /// applied are dropped. Idempotent.
  void stop();

 private:
  struct KeyFrameInput {
    int64_t id;
    double stamp_s;
    Pose2d pose;
  };
  struct OdometryInput {
    int64_t from_id, to_id;
    RelativePose2d delta;
    Eigen::Matrix3d covariance;
  };
  struct RelativePositionInput {
    int64_t from_id, to_id;
    Eigen::Vector2d translation_m;
    Eigen::Matrix2d covariance_m2;
  };
  struct FixInput {
    double stamp_s;
    Eigen::Vector2d position_en_m;
    Eigen::Matrix2d covariance_m2;
    bool robust;
  };
  struct HeadingInput {
    int64_t id;
    double yaw_rad, sigma_rad;
  };
  struct LoopInput {
    int64_t from_id, to_id;
    RelativePose2d delta;
    Eigen::Matrix3d covariance;
  };
  using Input = std::variant<KeyFrameInput, OdometryInput, RelativePositionInput, FixInput, HeadingInput, LoopInput>;

  void push(Input input);          ///< under mutex_
  bool knownId(int64_t id) const;  ///< under mutex_
  void run();
  void publish(const SolveReport& report, bool settled);
  bool marginalsDue() const;  ///< worker
  void computeMarginals();    ///< worker

  const BackgroundPoseGraphConfig config_;
  SnapshotCallback on_snapshot_;
  PoseGraph graph_;  ///< the worker's only

  mutable std::mutex mutex_;
  std::condition_variable wake_;  ///< new input or stop
  std::condition_variable idle_;  ///< the worker finished a round
  std::vector<Input> queue_;
  std::vector<int64_t> queued_ids_;  ///< every key frame id accepted, increasing
  double last_stamp_s_ = 0.0;
  int loops_queued_ = 0;
  uint64_t inputs_queued_ = 0;
  bool busy_ = true;  ///< the worker has work in hand (cleared only when it waits for input)
  bool stopping_ = false;
  std::atomic<bool> interrupt_{false};  ///< read by the solver's iteration callback
  std::atomic<bool> stop_flag_{false};

  std::shared_ptr<const GraphSnapshot> snapshot_;  ///< std::atomic_load / std::atomic_store only
  uint64_t sequence_ = 0;                          ///< the worker's
  uint64_t applied_ = 0;                           ///< the worker's
  std::string last_error_;                         ///< the worker's
  // The worker's: the last marginals, for the key frames `marginals_ids_` of the snapshot `marginals_sequence_`.
  SolveReport last_report_;  ///< of the last solve, for the snapshot that carries new marginals
  std::vector<int64_t> marginals_ids_;
  std::vector<Eigen::Matrix2d> marginals_m2_;
  uint64_t marginals_sequence_ = 0;
  double marginals_cpu_s_ = 0.0;
  bool settled_since_marginals_ = false;  ///< a settled solution the marginals are not of
  std::chrono::steady_clock::time_point next_marginals_{};
  std::thread worker_;
};

}  // namespace graph
}  // namespace exocet_mosaic
