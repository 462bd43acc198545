#include "exocet_mosaic/graph/pose_graph.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include <ceres/ceres.h>
#include <Eigen/Dense>

#include "covariance_check.h"
#include "exocet_common/cpu_time.h"

namespace exocet_mosaic {
namespace graph {
namespace {

constexpr double kPi = 3.14159265358979323846;

/// (-pi, pi]; ceil acts on the scalar part of a Jet, so the derivative is that of the identity.
template <typename T>
T wrap(const T& angle) {
  using std::ceil;
  return angle - T(2.0 * kPi) * ceil((angle - T(kPi)) / T(2.0 * kPi));
}

/// e = [R(-yaw_a) (p_b - p_a) - t; wrap(yaw_b - yaw_a - dyaw)].
template <typename T>
Eigen::Matrix<T, 3, 1> relativeError(const T* a, const T* b, const Eigen::Vector3d& measured) {
  using std::cos;
  using std::sin;
  const T c = cos(a[2]), s = sin(a[2]);
  const T dx = b[0] - a[0], dy = b[1] - a[1];
  Eigen::Matrix<T, 3, 1> e;
  e(0) = c * dx + s * dy - T(measured(0));
  e(1) = -s * dx + c * dy - T(measured(1));
  e(2) = wrap(T(b[2] - a[2] - T(measured(2))));
  return e;
}

struct OdometryResidual {
  Eigen::Vector3d measured;
  Eigen::Matrix3d whitening;
  template <typename T>
  bool operator()(const T* a, const T* b, T* r) const {
    Eigen::Map<Eigen::Matrix<T, 3, 1>> out(r);
    out = whitening.cast<T>() * relativeError(a, b, measured);
    return true;
  }
};

/// W [R(-yaw_a) (p_b - p_a) - t]: the translation of the odometry's error alone.
struct RelativePositionResidual {
  Eigen::Vector3d measured;  ///< (tx, ty, 0)
  Eigen::Matrix2d whitening;
  template <typename T>
  bool operator()(const T* a, const T* b, T* r) const {
    const Eigen::Matrix<T, 3, 1> e = relativeError(a, b, measured);
    Eigen::Map<Eigen::Matrix<T, 2, 1>> out(r);
    out = whitening.cast<T>() * e.template head<2>();
    return true;
  }
};

/// [s W e; sqrt(gate) (1 - s)]: the switchable loop with its switch prior.
struct LoopResidual {
  Eigen::Vector3d measured;
  Eigen::Matrix3d whitening;
  double sqrt_gate;
  template <typename T>
  bool operator()(const T* a, const T* b, const T* s, T* r) const {
    Eigen::Map<Eigen::Matrix<T, 3, 1>> out(r);
    out = s[0] * (whitening.cast<T>() * relativeError(a, b, measured));
    r[3] = T(sqrt_gate) * (T(1.0) - s[0]);
    return true;
  }
};

/// W ((1 - w) p_a + w p_b - z): a fix between two key frames.
struct InterpolatedFixResidual {
  Eigen::Vector2d measured;
  Eigen::Matrix2d whitening;
  double weight_b;
  template <typename T>
  bool operator()(const T* a, const T* b, T* r) const {
    Eigen::Matrix<T, 2, 1> e;
    e(0) = (1.0 - weight_b) * a[0] + weight_b * b[0] - measured(0);
    e(1) = (1.0 - weight_b) * a[1] + weight_b * b[1] - measured(1);
    Eigen::Map<Eigen::Matrix<T, 2, 1>> out(r);
    out = whitening.cast<T>() * e;
    return true;
  }
};

struct FixResidual {
  Eigen::Vector2d measured;
  Eigen::Matrix2d whitening;
  template <typename T>
  bool operator()(const T* a, T* r) const {
    Eigen::Matrix<T, 2, 1> e(a[0] - measured(0), a[1] - measured(1));
    Eigen::Map<Eigen::Matrix<T, 2, 1>> out(r);
    out = whitening.cast<T>() * e;
    return true;
  }
};

struct HeadingResidual {
  double yaw_rad, sigma_rad;
  template <typename T>
  bool operator()(const T* a, T* r) const {
    r[0] = wrap(T(a[2] - yaw_rad)) / sigma_rad;
    return true;
  }
};

struct PriorResidual {
  Eigen::Vector3d pose;
  double sigma_m, sigma_rad;
  template <typename T>
  bool operator()(const T* a, T* r) const {
    r[0] = (a[0] - pose(0)) / sigma_m;
    r[1] = (a[1] - pose(1)) / sigma_m;
    r[2] = wrap(T(a[2] - pose(2))) / sigma_rad;
    return true;
  }
};

using exocet_common::threadCpuSeconds;

void configureSolver(const PoseGraphConfig& config, ceres::Solver::Options* solver_options) {
  ceres::Solver::Options& options = *solver_options;
  options.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  options.sparse_linear_algebra_library_type =
      ceres::IsSparseLinearAlgebraLibraryTypeAvailable(ceres::SUITE_SPARSE) ? ceres::SUITE_SPARSE : ceres::EIGEN_SPARSE;
  options.max_num_iterations = config.max_iterations;
  options.max_solver_time_in_seconds = config.max_solver_time_s;
  options.num_threads = config.threads;
  // Tight: a windowed and a full solve of the same data must agree to well below a millimetre.
  options.function_tolerance = 1e-14;
  options.gradient_tolerance = 1e-14;
  options.parameter_tolerance = 1e-12;
  options.logging_type = ceres::SILENT;
}

std::string idText(int64_t id) { return std::to_string(id); }

class InterruptCallback : public ceres::IterationCallback {
 public:
  explicit InterruptCallback(const std::function<bool()>& check) : check_(check) {}
  ceres::CallbackReturnType operator()(const ceres::IterationSummary&) override {
    return check_() ? ceres::SOLVER_TERMINATE_SUCCESSFULLY : ceres::SOLVER_CONTINUE;
  }

 private:
  const std::function<bool()>& check_;
};

}  // namespace

double wrapAngle(double angle_rad) { return wrap(angle_rad); }

RelativePose2d between(const Pose2d& from, const Pose2d& to) {
  const double c = std::cos(from.yaw_rad), s = std::sin(from.yaw_rad);
  const Eigen::Vector2d d = to.position_en_m - from.position_en_m;
  RelativePose2d delta;
  delta.translation_m = Eigen::Vector2d(c * d.x() + s * d.y(), -s * d.x() + c * d.y());
  delta.yaw_rad = wrapAngle(to.yaw_rad - from.yaw_rad);
  return delta;
}

Pose2d compose(const Pose2d& from, const RelativePose2d& delta) {
  const double c = std::cos(from.yaw_rad), s = std::sin(from.yaw_rad);
  Pose2d to;
  to.position_en_m = from.position_en_m + Eigen::Vector2d(c * delta.translation_m.x() - s * delta.translation_m.y(),
                                                          s * delta.translation_m.x() + c * delta.translation_m.y());
  to.yaw_rad = wrapAngle(from.yaw_rad + delta.yaw_rad);
  return to;
}

std::string PoseGraphConfig::validate() const {
  std::ostringstream err;
  const auto positive = [&](const char* name, double v) {
    if (!(v > 0.0) || !std::isfinite(v)) err << name << " = " << v << " out of range (0, inf); ";
  };
  if (window_policy != WindowPolicy::kFull && window_policy != WindowPolicy::kAffected)
    err << "window_policy = " << static_cast<int>(window_policy) << " not one of kFull, kAffected; ";
  if (window_margin_keyframes < 0)
    err << "window_margin_keyframes = " << window_margin_keyframes << " out of range [0, inf); ";
  if (loop_margin_keyframes < 0)
    err << "loop_margin_keyframes = " << loop_margin_keyframes << " out of range [0, inf); ";
  if (!(position_fix_cauchy_scale >= 0.0) || !std::isfinite(position_fix_cauchy_scale))
    err << "position_fix_cauchy_scale = " << position_fix_cauchy_scale << " out of range [0, inf) (0: no loss); ";
  positive("loop_gate_chi2", loop_gate_chi2);
  positive("gauge_sigma_m", gauge_sigma_m);
  positive("gauge_sigma_rad", gauge_sigma_rad);
  positive("max_solver_time_s", max_solver_time_s);
  if (max_iterations < 1) err << "max_iterations = " << max_iterations << " out of range [1, inf); ";
  if (!(moved_threshold_m >= 0.0) || !std::isfinite(moved_threshold_m))
    err << "moved_threshold_m = " << moved_threshold_m << " out of range [0, inf); ";
  if (threads < 1) err << "threads = " << threads << " out of range [1, inf); ";
  std::string s = err.str();
  if (!s.empty()) s.resize(s.size() - 2);
  return s;
}

PoseGraph::PoseGraph(const PoseGraphConfig& config) : config_(config) {
  const std::string problem = config_.validate();
  if (!problem.empty()) throw std::invalid_argument("PoseGraphConfig: " + problem);
  if (config_.position_fix_cauchy_scale > 0.0)
    fix_loss_ = std::make_unique<ceres::CauchyLoss>(config_.position_fix_cauchy_scale);
}

PoseGraph::~PoseGraph() = default;

int PoseGraph::indexOf(int64_t id) const {
  // Ids strictly increase: the deque is sorted.
  const auto it =
      std::lower_bound(keyframes_.begin(), keyframes_.end(), id, [](const KeyFrame& k, int64_t v) { return k.id < v; });
  if (it == keyframes_.end() || it->id != id) return -1;
  return static_cast<int>(it - keyframes_.begin());
}

int PoseGraph::requireIndex(int64_t id, const char* what) const {
  const int index = indexOf(id);
  if (index < 0)
    throw std::invalid_argument(std::string(what) + ": unknown key frame id " + idText(id) +
                                (keyframes_.empty() ? " (no key frame yet)"
                                                    : " (known: " + idText(keyframes_.front().id) + " to " +
                                                          idText(keyframes_.back().id) + ")"));
  return index;
}

bool PoseGraph::hasKeyFrame(int64_t id) const { return indexOf(id) >= 0; }

void PoseGraph::markDirty(int index) { dirty_.push_back(index); }

void PoseGraph::addFactor(FactorType type, int a, int b, ceres::CostFunction* cost, ceres::LossFunction* loss,
                          int loop) {
  Factor f;
  f.type = type;
  f.a = a;
  f.b = b;
  f.loop = loop;
  f.cost.reset(cost);
  f.loss = loss;
  const int index = static_cast<int>(factors_.size());
  factors_.push_back(std::move(f));
  factor_mark_.push_back(0);
  keyframes_[a].factors.push_back(index);
  markDirty(a);
  if (b >= 0) {
    keyframes_[b].factors.push_back(index);
    markDirty(b);
  }
}

void PoseGraph::addKeyFrame(int64_t id, double stamp_s, const Pose2d& initial_pose) {
  if (!std::isfinite(stamp_s) || !initial_pose.position_en_m.allFinite() || !std::isfinite(initial_pose.yaw_rad))
    throw std::invalid_argument("addKeyFrame: key frame " + idText(id) + " has a non-finite stamp or initial pose");
  if (!keyframes_.empty()) {
    if (id <= keyframes_.back().id)
      throw std::invalid_argument("addKeyFrame: id " + idText(id) + " not greater than the last id " +
                                  idText(keyframes_.back().id));
    if (!(stamp_s > keyframes_.back().stamp_s)) {
      std::ostringstream s;
      s.precision(17);
      s << "addKeyFrame: key frame " << id << " stamp " << stamp_s << " s not after the last stamp "
        << keyframes_.back().stamp_s << " s";
      throw std::invalid_argument(s.str());
    }
  } else {
    origin_en_m_ = initial_pose.position_en_m;
  }
  KeyFrame k;
  k.id = id;
  k.stamp_s = stamp_s;
  k.initial = initial_pose;
  k.state[0] = initial_pose.position_en_m.x() - origin_en_m_.x();
  k.state[1] = initial_pose.position_en_m.y() - origin_en_m_.y();
  k.state[2] = wrapAngle(initial_pose.yaw_rad);
  keyframes_.push_back(std::move(k));
  const int index = static_cast<int>(keyframes_.size()) - 1;
  markDirty(index);
  if (index == 0) {
    const Eigen::Vector3d prior(0.0, 0.0, keyframes_[0].state[2]);
    gauge_factor_ = static_cast<int>(factors_.size());
    addFactor(FactorType::kGauge, 0, -1,
              new ceres::AutoDiffCostFunction<PriorResidual, 3, 3>(
                  new PriorResidual{prior, config_.gauge_sigma_m, config_.gauge_sigma_rad}),
              nullptr);
    return;
  }
  // Fixes that were waiting for a key frame after them.
  const KeyFrame& previous = keyframes_[index - 1];
  std::vector<PendingFix> waiting;
  for (const PendingFix& fix : pending_fixes_) {
    if (fix.stamp_s <= stamp_s) {
      const double w = (fix.stamp_s - previous.stamp_s) / (stamp_s - previous.stamp_s);
      attachFix(fix, index - 1, index, w);
    } else {
      waiting.push_back(fix);
    }
  }
  pending_fixes_.swap(waiting);
}

void PoseGraph::attachFix(const PendingFix& fix, int a, int b, double weight_b) {
  const Eigen::Vector2d z = fix.position_en_m - origin_en_m_;
  ceres::CostFunction* cost = nullptr;
  if (weight_b <= 0.0 || weight_b >= 1.0) {
    a = weight_b >= 1.0 ? b : a;
    b = -1;
    cost = new ceres::AutoDiffCostFunction<FixResidual, 2, 3>(new FixResidual{z, fix.whitening});
  } else {
    cost = new ceres::AutoDiffCostFunction<InterpolatedFixResidual, 2, 3, 3>(
        new InterpolatedFixResidual{z, fix.whitening, weight_b});
  }
  addFactor(FactorType::kPositionFix, a, b, cost, fix.robust ? fix_loss_.get() : nullptr);
  ++fixes_attached_;
}

void PoseGraph::addOdometry(int64_t from_id, int64_t to_id, const RelativePose2d& delta,
                            const Eigen::Matrix3d& covariance) {
  const int a = requireIndex(from_id, "addOdometry from"), b = requireIndex(to_id, "addOdometry to");
  if (!(from_id < to_id))
    throw std::invalid_argument("addOdometry: from id " + idText(from_id) + " not before to id " + idText(to_id));
  if (!delta.translation_m.allFinite() || !std::isfinite(delta.yaw_rad))
    throw std::invalid_argument("addOdometry " + idText(from_id) + " -> " + idText(to_id) + ": non-finite delta");
  const Eigen::Matrix3d whitening =
      whiteningOf(covariance, "addOdometry " + idText(from_id) + " -> " + idText(to_id) + " covariance");
  const Eigen::Vector3d measured(delta.translation_m.x(), delta.translation_m.y(), delta.yaw_rad);
  addFactor(FactorType::kOdometry, a, b,
            new ceres::AutoDiffCostFunction<OdometryResidual, 3, 3, 3>(new OdometryResidual{measured, whitening}),
            nullptr);
}

void PoseGraph::addRelativePosition(int64_t from_id, int64_t to_id, const Eigen::Vector2d& translation_m,
                                    const Eigen::Matrix2d& covariance_m2) {
  const int a = requireIndex(from_id, "addRelativePosition from"), b = requireIndex(to_id, "addRelativePosition to");
  const std::string what = "addRelativePosition " + idText(from_id) + " -> " + idText(to_id);
  if (!(from_id < to_id)) throw std::invalid_argument(what + ": from id not before to id");
  if (!translation_m.allFinite()) throw std::invalid_argument(what + ": non-finite translation");
  const Eigen::Matrix2d whitening = whiteningOf(covariance_m2, what + " covariance_m2");
  addFactor(FactorType::kRelativePosition, a, b,
            new ceres::AutoDiffCostFunction<RelativePositionResidual, 2, 3, 3>(
                new RelativePositionResidual{Eigen::Vector3d(translation_m.x(), translation_m.y(), 0.0), whitening}),
            fix_loss_.get());
  ++relative_positions_;
}

bool PoseGraph::addPositionFix(double stamp_s, const Eigen::Vector2d& position_en_m,
                               const Eigen::Matrix2d& covariance_m2, bool robust) {
  if (!std::isfinite(stamp_s) || !position_en_m.allFinite())
    throw std::invalid_argument("addPositionFix: non-finite stamp or position");
  PendingFix fix{stamp_s, position_en_m, whiteningOf(covariance_m2, "addPositionFix covariance_m2"), robust};
  if (keyframes_.empty() || stamp_s < keyframes_.front().stamp_s) return false;
  if (stamp_s > keyframes_.back().stamp_s) {
    pending_fixes_.push_back(fix);
    return true;
  }
  const auto it = std::lower_bound(keyframes_.begin(), keyframes_.end(), stamp_s,
                                   [](const KeyFrame& k, double t) { return k.stamp_s < t; });
  const int b = static_cast<int>(it - keyframes_.begin());
  if (keyframes_[b].stamp_s == stamp_s) {
    attachFix(fix, b, -1, 0.0);
  } else {
    const double w = (stamp_s - keyframes_[b - 1].stamp_s) / (keyframes_[b].stamp_s - keyframes_[b - 1].stamp_s);
    attachFix(fix, b - 1, b, w);
  }
  return true;
}

void PoseGraph::addHeading(int64_t id, double yaw_rad, double sigma_rad) {
  const int a = requireIndex(id, "addHeading");
  if (!std::isfinite(yaw_rad)) throw std::invalid_argument("addHeading " + idText(id) + ": non-finite yaw_rad");
  if (!(sigma_rad > 0.0) || !std::isfinite(sigma_rad))
    throw std::invalid_argument("addHeading " + idText(id) + ": sigma_rad = " + std::to_string(sigma_rad) +
                                " out of range (0, inf)");
  addFactor(FactorType::kHeading, a, -1,
            new ceres::AutoDiffCostFunction<HeadingResidual, 1, 3>(new HeadingResidual{wrapAngle(yaw_rad), sigma_rad}),
            nullptr);
}

int PoseGraph::addLoop(int64_t from_id, int64_t to_id, const RelativePose2d& delta, const Eigen::Matrix3d& covariance) {
  const int a = requireIndex(from_id, "addLoop from"), b = requireIndex(to_id, "addLoop to");
  if (a == b) throw std::invalid_argument("addLoop: from and to are the same key frame " + idText(from_id));
  if (!delta.translation_m.allFinite() || !std::isfinite(delta.yaw_rad))
    throw std::invalid_argument("addLoop " + idText(from_id) + " -> " + idText(to_id) + ": non-finite delta");
  Loop loop;
  loop.from = a;
  loop.to = b;
  loop.measured = Eigen::Vector3d(delta.translation_m.x(), delta.translation_m.y(), delta.yaw_rad);
  loop.whitening = whiteningOf(covariance, "addLoop " + idText(from_id) + " -> " + idText(to_id) + " covariance");
  const int index = static_cast<int>(loops_.size());
  loops_.push_back(loop);
  addFactor(FactorType::kLoop, a, b,
            new ceres::AutoDiffCostFunction<LoopResidual, 4, 3, 3, 1>(
                new LoopResidual{loop.measured, loop.whitening, std::sqrt(config_.loop_gate_chi2)}),
            nullptr, index);
  dirty_loops_.push_back(index);
  return index;
}

int PoseGraph::buildProblem(const std::vector<char>& active, bool switches_free, ceres::Problem* problem, int* held) {
  ++build_count_;
  std::vector<char> constant(keyframes_.size(), 0);
  int count = 0;
  *held = 0;
  for (size_t k = 0; k < keyframes_.size(); ++k) {
    if (!active[k]) continue;
    for (const int fi : keyframes_[k].factors) {
      if (factor_mark_[fi] == build_count_) continue;
      factor_mark_[fi] = build_count_;
      Factor& f = factors_[fi];
      if (f.type == FactorType::kGauge && fixes_attached_ > 0) continue;  // the fixes fix the gauge
      double* a = keyframes_[f.a].state;
      if (f.b < 0) {
        problem->AddResidualBlock(f.cost.get(), f.loss, a);
      } else if (f.type == FactorType::kLoop) {
        double* s = &loops_[f.loop].switch_value;
        problem->AddResidualBlock(f.cost.get(), f.loss, a, keyframes_[f.b].state, s);
        if (switches_free && !loops_[f.loop].held) {
          problem->SetParameterLowerBound(s, 0, 0.0);
          problem->SetParameterUpperBound(s, 0, 1.0);
        } else {
          problem->SetParameterBlockConstant(s);
        }
      } else {
        problem->AddResidualBlock(f.cost.get(), f.loss, a, keyframes_[f.b].state);
      }
      for (const int other : {f.a, f.b}) {
        if (other >= 0 && !active[other] && !constant[other]) {
          constant[other] = 1;
          problem->SetParameterBlockConstant(keyframes_[other].state);
          ++*held;
        }
      }
      ++count;
    }
  }
  return count;
}

PoseGraph::SolverRun PoseGraph::optimize(const std::vector<char>& active) {
  SolverRun run;
  ceres::Problem::Options problem_options;
  problem_options.cost_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  problem_options.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem problem(problem_options);
  run.factors = buildProblem(active, true, &problem, &run.held);
  if (run.factors == 0) {
    run.message = "no factor";
    return run;
  }
  ceres::Solver::Options options;
  configureSolver(config_, &options);
  InterruptCallback interrupt(interrupt_check_);
  if (interrupt_check_) options.callbacks.push_back(&interrupt);
  ceres::Solver::Summary summary;
  ceres::Solve(options, &problem, &summary);
  run.iterations = static_cast<int>(summary.iterations.size());
  run.initial_cost = summary.initial_cost;
  run.final_cost = summary.final_cost;
  run.converged = summary.termination_type == ceres::CONVERGENCE;
  run.message = summary.BriefReport();
  return run;
}

void PoseGraph::testNewLoops(const std::vector<char>& active, SolveReport* report) {
  std::vector<int> untested;
  for (size_t l = 0; l < loops_.size(); ++l)
    if (!loops_[l].tested && (active[loops_[l].from] || active[loops_[l].to])) untested.push_back(static_cast<int>(l));
  if (untested.empty()) return;
  // The graph without them.
  for (const int l : untested) {
    loops_[l].switch_value = 0.0;
    loops_[l].held = true;
  }
  optimize(active);
  const int n = static_cast<int>(keyframes_.size()), margin = config_.loop_margin_keyframes;
  for (const int l : untested) {
    Loop& loop = loops_[l];
    const int lo = std::max(0, std::min(loop.from, loop.to) - margin);
    const int hi = std::min(n - 1, std::max(loop.from, loop.to) + margin);
    // Within the solve's window: the test sees the flexibility the solve has.
    std::vector<char> window(n, 0);
    for (int k = lo; k <= hi; ++k) window[k] = active[k];
    std::vector<std::array<double, 3>> saved(hi - lo + 1);
    for (int k = lo; k <= hi; ++k) std::copy(keyframes_[k].state, keyframes_[k].state + 3, saved[k - lo].begin());

    ceres::Problem::Options problem_options;
    problem_options.cost_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    problem_options.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    ceres::Problem problem(problem_options);
    int held = 0;
    buildProblem(window, true, &problem, &held);
    double cost_off = 0.0, cost_on = 0.0;
    problem.Evaluate(ceres::Problem::EvaluateOptions(), &cost_off, nullptr, nullptr, nullptr);
    loop.switch_value = 1.0;
    ceres::Solver::Options options;
    configureSolver(config_, &options);
    InterruptCallback interrupt(interrupt_check_);
    if (interrupt_check_) options.callbacks.push_back(&interrupt);
    ceres::Solver::Summary summary;
    ceres::Solve(options, &problem, &summary);
    problem.Evaluate(ceres::Problem::EvaluateOptions(), &cost_on, nullptr, nullptr, nullptr);
    // Costs are half the chi2; the loop's block holds gate / 2 when off (its switch prior) and chi2 / 2 when on.
    loop.consistency_chi2 = 2.0 * (cost_on - cost_off) + config_.loop_gate_chi2;
    loop.tested = true;
    ++report->loops_tested;
    if (loop.consistency_chi2 <= config_.loop_gate_chi2) {
      ++report->loops_passed;
    } else {
      loop.switch_value = 0.0;
      for (int k = lo; k <= hi; ++k) std::copy(saved[k - lo].begin(), saved[k - lo].end(), keyframes_[k].state);
    }
  }
  for (const int l : untested) loops_[l].held = false;
}

SolveReport PoseGraph::solveWindow(const std::vector<char>& active) {
  SolveReport report;
  const double cpu0 = threadCpuSeconds();
  const auto wall0 = std::chrono::steady_clock::now();
  std::vector<int> free_keyframes;
  for (size_t k = 0; k < keyframes_.size(); ++k)
    if (active[k]) free_keyframes.push_back(static_cast<int>(k));
  report.keyframes_optimized = static_cast<int>(free_keyframes.size());
  report.full = report.keyframes_optimized == static_cast<int>(keyframes_.size());
  if (free_keyframes.empty()) {
    report.converged = true;
    report.message = "nothing to solve";
  } else {
    std::vector<Eigen::Vector2d> before(free_keyframes.size());
    for (size_t i = 0; i < free_keyframes.size(); ++i)
      before[i] = Eigen::Vector2d(keyframes_[free_keyframes[i]].state[0], keyframes_[free_keyframes[i]].state[1]);
    testNewLoops(active, &report);
    const SolverRun run = optimize(active);
    report.factors = run.factors;
    report.keyframes_held = run.held;
    report.iterations = run.iterations;
    report.initial_cost = run.initial_cost;
    report.final_cost = run.final_cost;
    report.converged = run.converged;
    report.message = run.message;
    for (size_t i = 0; i < free_keyframes.size(); ++i) {
      double* state = keyframes_[free_keyframes[i]].state;
      state[2] = wrapAngle(state[2]);
      const double move = (Eigen::Vector2d(state[0], state[1]) - before[i]).norm();
      report.max_move_m = std::max(report.max_move_m, move);
      if (move > config_.moved_threshold_m) ++report.keyframes_moved;
    }
  }
  for (size_t i = 0; i < loops_.size(); ++i)
    (loops_[i].switch_value > 0.5 ? report.loops_accepted : report.loops_rejected)++;
  report.cpu_s = threadCpuSeconds() - cpu0;
  report.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
  return report;
}

SolveReport PoseGraph::solve() {
  if (config_.window_policy == PoseGraphConfig::WindowPolicy::kFull) return solveFull();
  const int n = static_cast<int>(keyframes_.size());
  std::vector<char> active(n, 0);
  const int margin = config_.window_margin_keyframes;
  for (const int k : dirty_)
    for (int j = std::max(0, k - margin); j <= std::min(n - 1, k + margin); ++j) active[j] = 1;
  for (const int l : dirty_loops_) {
    // A loop bends the trajectory between its ends, and beyond them.
    const int lo = std::max(0, std::min(loops_[l].from, loops_[l].to) - config_.loop_margin_keyframes);
    const int hi = std::min(n - 1, std::max(loops_[l].from, loops_[l].to) + config_.loop_margin_keyframes);
    std::fill(active.begin() + lo, active.begin() + hi + 1, 1);
  }
  dirty_.clear();
  dirty_loops_.clear();
  return solveWindow(active);
}

SolveReport PoseGraph::solveFull() {
  dirty_.clear();
  dirty_loops_.clear();
  return solveWindow(std::vector<char>(keyframes_.size(), 1));
}

SolveReport PoseGraph::solveAround(const std::vector<int64_t>& ids) {
  const int n = static_cast<int>(keyframes_.size());
  std::vector<char> active(n, 0);
  const int margin = config_.window_margin_keyframes;
  for (const int64_t id : ids) {
    const int k = requireIndex(id, "solveAround");
    for (int j = std::max(0, k - margin); j <= std::min(n - 1, k + margin); ++j) active[j] = 1;
  }
  return solveWindow(active);
}

Pose2d PoseGraph::pose(int64_t id) const {
  const KeyFrame& k = keyframes_[requireIndex(id, "pose")];
  Pose2d p;
  p.position_en_m = origin_en_m_ + Eigen::Vector2d(k.state[0], k.state[1]);
  p.yaw_rad = wrapAngle(k.state[2]);
  return p;
}

Pose2d PoseGraph::initialPose(int64_t id) const { return keyframes_[requireIndex(id, "initialPose")].initial; }

double PoseGraph::stamp(int64_t id) const { return keyframes_[requireIndex(id, "stamp")].stamp_s; }

std::vector<int64_t> PoseGraph::keyFrameIds() const {
  std::vector<int64_t> ids;
  ids.reserve(keyframes_.size());
  for (const KeyFrame& k : keyframes_) ids.push_back(k.id);
  return ids;
}

std::vector<KeyFramePose> PoseGraph::keyFramePoses() const {
  std::vector<KeyFramePose> poses;
  poses.reserve(keyframes_.size());
  for (const KeyFrame& k : keyframes_) {
    KeyFramePose p;
    p.id = k.id;
    p.stamp_s = k.stamp_s;
    p.pose.position_en_m = origin_en_m_ + Eigen::Vector2d(k.state[0], k.state[1]);
    p.pose.yaw_rad = wrapAngle(k.state[2]);
    p.correction_en_m = p.pose.position_en_m - k.initial.position_en_m;
    p.correction_yaw_rad = wrapAngle(p.pose.yaw_rad - k.initial.yaw_rad);
    poses.push_back(p);
  }
  return poses;
}

LoopStatus PoseGraph::loop(int index) const {
  if (index < 0 || index >= static_cast<int>(loops_.size()))
    throw std::invalid_argument("loop: index " + std::to_string(index) + " out of range [0, " +
                                std::to_string(loops_.size()) + ")");
  const Loop& l = loops_[index];
  LoopStatus status;
  status.from_id = keyframes_[l.from].id;
  status.to_id = keyframes_[l.to].id;
  status.switch_value = l.switch_value;
  status.chi2 =
      (l.whitening * relativeError(keyframes_[l.from].state, keyframes_[l.to].state, l.measured)).squaredNorm();
  status.accepted = l.switch_value > 0.5;
  status.consistency_chi2 = l.consistency_chi2;
  return status;
}

std::optional<std::vector<Eigen::Matrix3d>> PoseGraph::covarianceBlocks(const std::vector<int>& indices) const {
  // Ceres reads the parameter blocks without changing them; buildProblem's bookkeeping is scratch.
  PoseGraph& self = const_cast<PoseGraph&>(*this);
  ceres::Problem::Options problem_options;
  problem_options.cost_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  problem_options.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem problem(problem_options);
  int held = 0;
  self.buildProblem(std::vector<char>(keyframes_.size(), 1), false, &problem, &held);
  // Ceres needs a full-rank Jacobian: a weak prior (the gauge's sigmas) on every key frame at its estimate.
  std::vector<std::unique_ptr<ceres::CostFunction>> priors;
  priors.reserve(keyframes_.size());
  for (KeyFrame& k : self.keyframes_) {
    priors.emplace_back(new ceres::AutoDiffCostFunction<PriorResidual, 3, 3>(new PriorResidual{
        Eigen::Vector3d(k.state[0], k.state[1], k.state[2]), config_.gauge_sigma_m, config_.gauge_sigma_rad}));
    problem.AddResidualBlock(priors.back().get(), nullptr, k.state);
  }
  std::vector<std::pair<const double*, const double*>> blocks;
  blocks.reserve(indices.size());
  for (const int i : indices) blocks.emplace_back(self.keyframes_[i].state, self.keyframes_[i].state);
  ceres::Covariance::Options options;
  options.sparse_linear_algebra_library_type =
      ceres::IsSparseLinearAlgebraLibraryTypeAvailable(ceres::SUITE_SPARSE) ? ceres::SUITE_SPARSE : ceres::EIGEN_SPARSE;
  options.num_threads = 1;  // a background task: it must not take the chain's cores
  ceres::Covariance covariance(options);
  if (!covariance.Compute(blocks, &problem)) return std::nullopt;
  std::vector<Eigen::Matrix3d> out;
  out.reserve(blocks.size());
  Eigen::Matrix<double, 3, 3, Eigen::RowMajor> c;
  for (const auto& block : blocks) {
    if (!covariance.GetCovarianceBlock(block.first, block.second, c.data())) return std::nullopt;
    out.emplace_back(c);
  }
  return out;
}

std::optional<Eigen::Matrix3d> PoseGraph::covariance(int64_t id) const {
  const std::optional<std::vector<Eigen::Matrix3d>> blocks = covarianceBlocks({requireIndex(id, "covariance")});
  if (!blocks) return std::nullopt;
  return blocks->front();
}

std::vector<Eigen::Matrix2d> PoseGraph::positionCovariances(int max_computed) const {
  const int n = static_cast<int>(keyframes_.size());
  if (n == 0) return {};
  // The key frames computed: every stride-th, and the last (at most floor((n - 1) / stride) + 2 <= max_computed).
  const int spans = std::max(1, max_computed - 2);
  const int stride = max_computed > 0 && n > max_computed ? (n - 1 + spans - 1) / spans : 1;
  std::vector<int> computed;
  for (int i = 0; i < n; i += stride) computed.push_back(i);
  if (computed.back() != n - 1) computed.push_back(n - 1);
  const std::optional<std::vector<Eigen::Matrix3d>> blocks = covarianceBlocks(computed);
  if (!blocks) return {};
  std::vector<Eigen::Matrix2d> at_computed;
  at_computed.reserve(blocks->size());
  for (const Eigen::Matrix3d& c : *blocks) at_computed.push_back(c.topLeftCorner<2, 2>());
  std::vector<Eigen::Matrix2d> out(n);
  for (size_t j = 0; j < computed.size(); ++j) {
    out[computed[j]] = at_computed[j];
    if (j + 1 == computed.size()) break;
    const int a = computed[j], b = computed[j + 1];
    for (int i = a + 1; i < b; ++i) {
      const double t = static_cast<double>(i - a) / (b - a);
      out[i] = (1.0 - t) * at_computed[j] + t * at_computed[j + 1];
    }
  }
  return out;
}

}  // namespace graph
}  // namespace exocet_mosaic
