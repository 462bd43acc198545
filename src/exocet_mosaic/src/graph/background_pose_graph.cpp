#include "exocet_mosaic/graph/background_pose_graph.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

#include "covariance_check.h"
#include "exocet_common/background_priority.h"
#include "exocet_common/cpu_time.h"

namespace exocet_mosaic {
namespace graph {

const KeyFramePose* GraphSnapshot::find(int64_t id) const {
  const auto it = std::lower_bound(key_frames.begin(), key_frames.end(), id,
                                   [](const KeyFramePose& k, int64_t v) { return k.id < v; });
  return it != key_frames.end() && it->id == id ? &*it : nullptr;
}

std::string BackgroundPoseGraphConfig::validate() const {
  std::ostringstream err;
  const std::string g = graph.validate();
  if (!g.empty()) err << "graph: " << g << "; ";
  if (!(idle_wait_s > 0.0) || !std::isfinite(idle_wait_s))
    err << "idle_wait_s = " << idle_wait_s << " out of range (0, inf); ";
  if (!(marginals_duty_cycle >= 0.0 && marginals_duty_cycle <= 1.0))
    err << "marginals_duty_cycle = " << marginals_duty_cycle << " out of range [0, 1]; ";
  if (marginals_max_key_frames < 2 || marginals_max_key_frames > 1000000)
    err << "marginals_max_key_frames = " << marginals_max_key_frames << " out of range [2, 1000000]; ";
  std::string s = err.str();
  if (!s.empty()) s.resize(s.size() - 2);
  return s;
}

namespace {
const BackgroundPoseGraphConfig& validated(const BackgroundPoseGraphConfig& config) {
  const std::string problem = config.validate();
  if (!problem.empty()) throw std::invalid_argument("BackgroundPoseGraphConfig: " + problem);
  return config;
}
}  // namespace

BackgroundPoseGraph::BackgroundPoseGraph(const BackgroundPoseGraphConfig& config, SnapshotCallback on_snapshot)
    : config_(validated(config)), on_snapshot_(std::move(on_snapshot)), graph_(config.graph) {
  std::atomic_store(&snapshot_, std::shared_ptr<const GraphSnapshot>(std::make_shared<GraphSnapshot>()));
  worker_ = std::thread([this] { run(); });
}

BackgroundPoseGraph::~BackgroundPoseGraph() { stop(); }

bool BackgroundPoseGraph::knownId(int64_t id) const {
  return std::binary_search(queued_ids_.begin(), queued_ids_.end(), id);
}

void BackgroundPoseGraph::push(Input input) {
  queue_.push_back(std::move(input));
  ++inputs_queued_;
  interrupt_ = true;  // a settling full solve gives way to the new input
}

void BackgroundPoseGraph::addKeyFrame(int64_t id, double stamp_s, const Pose2d& initial_pose) {
  if (!std::isfinite(stamp_s) || !initial_pose.position_en_m.allFinite() || !std::isfinite(initial_pose.yaw_rad))
    throw std::invalid_argument("addKeyFrame: key frame " + std::to_string(id) +
                                " has a non-finite stamp or initial pose");
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!queued_ids_.empty() && id <= queued_ids_.back())
      throw std::invalid_argument("addKeyFrame: id " + std::to_string(id) + " not greater than the last id " +
                                  std::to_string(queued_ids_.back()));
    if (!queued_ids_.empty() && !(stamp_s > last_stamp_s_))
      throw std::invalid_argument("addKeyFrame: key frame " + std::to_string(id) + " stamp " + std::to_string(stamp_s) +
                                  " s not after the last stamp " + std::to_string(last_stamp_s_) + " s");
    queued_ids_.push_back(id);
    last_stamp_s_ = stamp_s;
    push(KeyFrameInput{id, stamp_s, initial_pose});
  }
  wake_.notify_one();
}

void BackgroundPoseGraph::addOdometry(int64_t from_id, int64_t to_id, const RelativePose2d& delta,
                                      const Eigen::Matrix3d& covariance) {
  const std::string what = "addOdometry " + std::to_string(from_id) + " -> " + std::to_string(to_id);
  if (!(from_id < to_id)) throw std::invalid_argument(what + ": from id not before to id");
  if (!delta.translation_m.allFinite() || !std::isfinite(delta.yaw_rad))
    throw std::invalid_argument(what + ": non-finite delta");
  whiteningOf(covariance, what + " covariance");
  {
    std::lock_guard<std::mutex> lock(mutex_);
    for (const int64_t id : {from_id, to_id})
      if (!knownId(id)) throw std::invalid_argument(what + ": unknown key frame id " + std::to_string(id));
    push(OdometryInput{from_id, to_id, delta, covariance});
  }
  wake_.notify_one();
}

void BackgroundPoseGraph::addRelativePosition(int64_t from_id, int64_t to_id, const Eigen::Vector2d& translation_m,
                                              const Eigen::Matrix2d& covariance_m2) {
  const std::string what = "addRelativePosition " + std::to_string(from_id) + " -> " + std::to_string(to_id);
  if (!(from_id < to_id)) throw std::invalid_argument(what + ": from id not before to id");
  if (!translation_m.allFinite()) throw std::invalid_argument(what + ": non-finite translation");
  whiteningOf(covariance_m2, what + " covariance_m2");
  {
    std::lock_guard<std::mutex> lock(mutex_);
    for (const int64_t id : {from_id, to_id})
      if (!knownId(id)) throw std::invalid_argument(what + ": unknown key frame id " + std::to_string(id));
    push(RelativePositionInput{from_id, to_id, translation_m, covariance_m2});
  }
  wake_.notify_one();
}

void BackgroundPoseGraph::addPositionFix(double stamp_s, const Eigen::Vector2d& position_en_m,
                                         const Eigen::Matrix2d& covariance_m2, bool robust) {
  if (!std::isfinite(stamp_s) || !position_en_m.allFinite())
    throw std::invalid_argument("addPositionFix: non-finite stamp or position");
  whiteningOf(covariance_m2, "addPositionFix covariance_m2");
  {
    std::lock_guard<std::mutex> lock(mutex_);
    push(FixInput{stamp_s, position_en_m, covariance_m2, robust});
  }
  wake_.notify_one();
}

void BackgroundPoseGraph::addHeading(int64_t id, double yaw_rad, double sigma_rad) {
  const std::string what = "addHeading " + std::to_string(id);
  if (!std::isfinite(yaw_rad)) throw std::invalid_argument(what + ": non-finite yaw_rad");
  if (!(sigma_rad > 0.0) || !std::isfinite(sigma_rad))
    throw std::invalid_argument(what + ": sigma_rad = " + std::to_string(sigma_rad) + " out of range (0, inf)");
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!knownId(id)) throw std::invalid_argument(what + ": unknown key frame id " + std::to_string(id));
    push(HeadingInput{id, yaw_rad, sigma_rad});
  }
  wake_.notify_one();
}

int BackgroundPoseGraph::addLoop(int64_t from_id, int64_t to_id, const RelativePose2d& delta,
                                 const Eigen::Matrix3d& covariance) {
  const std::string what = "addLoop " + std::to_string(from_id) + " -> " + std::to_string(to_id);
  if (from_id == to_id) throw std::invalid_argument(what + ": from and to are the same key frame");
  if (!delta.translation_m.allFinite() || !std::isfinite(delta.yaw_rad))
    throw std::invalid_argument(what + ": non-finite delta");
  whiteningOf(covariance, what + " covariance");
  int index = 0;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    for (const int64_t id : {from_id, to_id})
      if (!knownId(id)) throw std::invalid_argument(what + ": unknown key frame id " + std::to_string(id));
    push(LoopInput{from_id, to_id, delta, covariance});
    index = loops_queued_++;
  }
  wake_.notify_one();
  return index;
}

std::shared_ptr<const GraphSnapshot> BackgroundPoseGraph::snapshot() const { return std::atomic_load(&snapshot_); }

bool BackgroundPoseGraph::waitIdle(double timeout_s) {
  std::unique_lock<std::mutex> lock(mutex_);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(std::max(0.0, timeout_s));
  return idle_.wait_until(lock, deadline, [&] { return stopping_ || (queue_.empty() && !busy_); }) && !stopping_;
}

void BackgroundPoseGraph::stop() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
  }
  stop_flag_ = true;
  wake_.notify_all();
  idle_.notify_all();
  if (worker_.joinable() && worker_.get_id() != std::this_thread::get_id()) worker_.join();
}

void BackgroundPoseGraph::publish(const SolveReport& report, bool settled) {
  auto s = std::make_shared<GraphSnapshot>();
  s->sequence = ++sequence_;
  s->inputs_applied = applied_;
  s->settled = settled;
  s->key_frames = graph_.keyFramePoses();
  s->loop_accepted.resize(graph_.numLoops());
  for (size_t i = 0; i < graph_.numLoops(); ++i) s->loop_accepted[i] = graph_.loopAccepted(static_cast<int>(i));
  s->report = report;
  s->last_error = last_error_;
  if (marginals_sequence_ > 0) {
    // Aligned with key_frames; both id lists increase.
    const Eigen::Matrix2d unknown = Eigen::Matrix2d::Constant(std::numeric_limits<double>::quiet_NaN());
    s->position_covariance_m2.reserve(s->key_frames.size());
    size_t m = 0;
    for (const KeyFramePose& k : s->key_frames) {
      while (m < marginals_ids_.size() && marginals_ids_[m] < k.id) ++m;
      s->position_covariance_m2.push_back(m < marginals_ids_.size() && marginals_ids_[m] == k.id ? marginals_m2_[m]
                                                                                                   : unknown);
    }
    s->marginals_sequence = marginals_sequence_;
    s->marginals_cpu_s = marginals_cpu_s_;
  }
  std::shared_ptr<const GraphSnapshot> published = s;
  std::atomic_store(&snapshot_, published);
  if (on_snapshot_) on_snapshot_(published);
}

bool BackgroundPoseGraph::marginalsDue() const {
  return config_.marginals_duty_cycle > 0.0 && settled_since_marginals_ &&
         std::chrono::steady_clock::now() >= next_marginals_;
}

void BackgroundPoseGraph::computeMarginals() {
  const auto wall0 = std::chrono::steady_clock::now();
  const double cpu0 = exocet_common::threadCpuSeconds();
  std::vector<Eigen::Matrix2d> marginals = graph_.positionCovariances(config_.marginals_max_key_frames);
  marginals_cpu_s_ = exocet_common::threadCpuSeconds() - cpu0;
  const auto wall1 = std::chrono::steady_clock::now();
  settled_since_marginals_ = false;
  next_marginals_ = wall1 + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                                (wall1 - wall0) * (1.0 / config_.marginals_duty_cycle));
  if (marginals.empty()) {
    last_error_ = "the marginals of the key frames could not be computed (rank-deficient graph)";
    return;
  }
  marginals_ids_ = graph_.keyFrameIds();
  marginals_m2_ = std::move(marginals);
  marginals_sequence_ = sequence_;  // the solution of the snapshot last published
  publish(last_report_, true);
}

void BackgroundPoseGraph::run() {
  // Solves may come late (bounded in time, the chain never waits for them); the chain's frames may not.
  exocet_common::lowerThisThreadPriority();
  const auto idle_wait = std::chrono::duration<double>(config_.idle_wait_s);
  bool need_settle = false;
  std::vector<Input> batch;
  while (true) {
    bool marginals = false;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      if (queue_.empty() && !need_settle) {
        marginals = marginalsDue();  // still busy: waitIdle() waits for marginals that are due
        if (!marginals) {
          busy_ = false;
          idle_.notify_all();
          wake_.wait_for(lock, idle_wait, [&] { return stopping_ || !queue_.empty(); });
        }
      }
      if (stopping_) break;
      if (!marginals) {
        if (queue_.empty() && !need_settle) continue;
        busy_ = true;
        batch.clear();
        batch.swap(queue_);
        interrupt_ = false;
      }
    }
    if (marginals) {
      computeMarginals();
      continue;
    }
    if (!batch.empty()) {
      for (const Input& input : batch) {
        try {
          std::visit(
              [&](const auto& in) {
                using T = std::decay_t<decltype(in)>;
                if constexpr (std::is_same_v<T, KeyFrameInput>) {
                  graph_.addKeyFrame(in.id, in.stamp_s, in.pose);
                } else if constexpr (std::is_same_v<T, OdometryInput>) {
                  graph_.addOdometry(in.from_id, in.to_id, in.delta, in.covariance);
                } else if constexpr (std::is_same_v<T, RelativePositionInput>) {
                  graph_.addRelativePosition(in.from_id, in.to_id, in.translation_m, in.covariance_m2);
                } else if constexpr (std::is_same_v<T, FixInput>) {
                  graph_.addPositionFix(in.stamp_s, in.position_en_m, in.covariance_m2, in.robust);
                } else if constexpr (std::is_same_v<T, HeadingInput>) {
                  graph_.addHeading(in.id, in.yaw_rad, in.sigma_rad);
                } else {
                  graph_.addLoop(in.from_id, in.to_id, in.delta, in.covariance);
                }
              },
              input);
        } catch (const std::exception& e) {
          last_error_ = e.what();  // checked by the producer already: should not happen
        }
        ++applied_;
      }
      graph_.setInterruptCheck([this] { return stop_flag_.load(); });
      const SolveReport report = graph_.solve();
      const bool settled = report.full && report.converged;
      need_settle = config_.settle_with_full_solve && !settled;
      publish(report, settled || !config_.settle_with_full_solve);
      last_report_ = report;
      settled_since_marginals_ = settled || !config_.settle_with_full_solve;
    } else {
      // The queue ran dry: settle the whole graph, giving way to new input.
      graph_.setInterruptCheck([this] { return stop_flag_.load() || interrupt_.load(); });
      const SolveReport report = graph_.solveFull();
      need_settle = false;  // an interrupted settle is redone after the new input's window
      {
        std::lock_guard<std::mutex> lock(mutex_);
        if (!queue_.empty()) need_settle = config_.settle_with_full_solve;
      }
      publish(report, report.converged);
      last_report_ = report;
      settled_since_marginals_ = report.converged;
    }
  }
  graph_.setInterruptCheck(nullptr);
}

}  // namespace graph
}  // namespace exocet_mosaic
