#include "exocet_mosaic/registration/robust_motion_fitter.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <sstream>
#include <stdexcept>

#include <Eigen/Dense>

namespace exocet_mosaic {
namespace registration {

int minimalPointCount(MotionModel model) { return (parameterCount(model) + 1) / 2; }

std::string RobustFitConfig::validate() const {
  std::ostringstream errors;
  auto check = [&errors](bool ok, const char* field, const std::string& range) {
    if (ok) return;
    if (errors.tellp() > 0) errors << "; ";
    errors << field << " must be in " << range;
  };
  check(tukey_c >= 1.0 && tukey_c <= 20.0, "tukey_c", "[1, 20]");
  check(rejection_k >= 2.0 && rejection_k <= 20.0, "rejection_k", "[2, 20]");
  check(min_scale_px > 0.0 && min_scale_px <= 10.0, "min_scale_px", "(0, 10]");
  check(min_inliers >= std::max(1, minimalPointCount(model)) && min_inliers <= 1000000, "min_inliers",
        "[" + std::to_string(minimalPointCount(model)) + " (minimal points of the " + toString(model) +
            " model), 1000000]");
  check(min_inlier_fraction >= 0.0 && min_inlier_fraction <= 1.0, "min_inlier_fraction", "[0, 1]");
  check(sample_threshold_px > 0.0 && sample_threshold_px <= 1000.0, "sample_threshold_px", "(0, 1000]");
  check(max_samples >= 0 && max_samples <= 100000, "max_samples", "[0, 100000]");
  check(sample_confidence > 0.0 && sample_confidence < 1.0, "sample_confidence", "(0, 1)");
  check(max_iterations >= 1 && max_iterations <= 1000, "max_iterations", "[1, 1000]");
  check(convergence_px > 0.0 && convergence_px <= 1.0, "convergence_px", "(0, 1]");
  return errors.str();
}

namespace {

constexpr int kMaxParameters = 8;
using Vec = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxParameters, 1>;
using Mat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxParameters, kMaxParameters>;
// Median of the norm of a 2D residual with N(0, sigma^2) components is sigma * sqrt(2 ln 2) (Rayleigh).
constexpr double kRayleighMedian = 1.1774100225154747;
// ... and its 20 % quantile is sigma * sqrt(-2 ln 0.8).
constexpr double kRayleighFifth = 0.66805205325;
// Below this reciprocal condition number (normalised coordinates) the points do not determine the model.
constexpr double kMinReciprocalCondition = 1e-12;

// Two rows of a Jacobian, plain arrays: the accumulation loops are the fitter's inner loop, and Eigen's products of
// dynamic-size blocks this small cost far more than the arithmetic.
struct Rows {
  double x[kMaxParameters];
  double y[kMaxParameters];
};

// Where the centred, normalised point (u, v) goes under the normalised parameters q.
inline Eigen::Vector2d warp(MotionModel model, const Vec& q, double u, double v) {
  switch (model) {
    case MotionModel::kTranslation:
      return {u + q[0], v + q[1]};
    case MotionModel::kSimilarity:
      return {(1.0 + q[2]) * u - q[3] * v + q[0], q[3] * u + (1.0 + q[2]) * v + q[1]};
    case MotionModel::kAffine:
      return {(1.0 + q[2]) * u + q[3] * v + q[0], q[4] * u + (1.0 + q[5]) * v + q[1]};
    case MotionModel::kHomography: {
      const double w = q[6] * u + q[7] * v + 1.0;
      return {((1.0 + q[2]) * u + q[3] * v + q[0]) / w, (q[4] * u + (1.0 + q[5]) * v + q[1]) / w};
    }
  }
  return {u, v};
}

// d warp / d q at (u, v) (the same as warpJacobian(), without its heap allocation).
inline void jacobian(MotionModel model, const Vec& q, double u, double v, Rows* j) {
  std::fill(j->x, j->x + kMaxParameters, 0.0);
  std::fill(j->y, j->y + kMaxParameters, 0.0);
  j->x[0] = 1.0;
  j->y[1] = 1.0;
  switch (model) {
    case MotionModel::kTranslation:
      break;
    case MotionModel::kSimilarity:
      j->x[2] = u;
      j->x[3] = -v;
      j->y[2] = v;
      j->y[3] = u;
      break;
    case MotionModel::kAffine:
      j->x[2] = u;
      j->x[3] = v;
      j->y[4] = u;
      j->y[5] = v;
      break;
    case MotionModel::kHomography: {
      const double iw = 1.0 / (q[6] * u + q[7] * v + 1.0);
      const double xw = ((1.0 + q[2]) * u + q[3] * v + q[0]) * iw;
      const double yw = (q[4] * u + (1.0 + q[5]) * v + q[1]) * iw;
      j->x[0] = iw;
      j->y[1] = iw;
      j->x[2] = u * iw;
      j->x[3] = v * iw;
      j->y[4] = u * iw;
      j->y[5] = v * iw;
      j->x[6] = -xw * u * iw;
      j->x[7] = -xw * v * iw;
      j->y[6] = -yw * u * iw;
      j->y[7] = -yw * v * iw;
      break;
    }
  }
}

// Rows of the linear system A q = b that one correspondence gives: the exact equations of the linear models, the
// DLT (algebraic) equations of the homography: (1+a11) u + a12 v + tx = u' (g1 u + g2 v + 1), and likewise for v'.
inline void linearRows(MotionModel model, double u, double v, double tu, double tv, Rows* a, Eigen::Vector2d* b) {
  static const Vec kZero = Vec::Zero(kMaxParameters);
  jacobian(model == MotionModel::kHomography ? MotionModel::kAffine : model, kZero, u, v, a);
  if (model == MotionModel::kHomography) {
    a->x[6] = -tu * u;
    a->x[7] = -tu * v;
    a->y[6] = -tv * u;
    a->y[7] = -tv * v;
  }
  *b = {tu - u, tv - v};
}

// Accumulates (upper triangle) and solves the normal equations J^T W J x = J^T W r.
class NormalEquations {
 public:
  explicit NormalEquations(int p) : p_(p) {
    std::fill(&a_[0][0], &a_[0][0] + kMaxParameters * kMaxParameters, 0.0);
    std::fill(b_, b_ + kMaxParameters, 0.0);
  }
  void add(const Rows& j, const Eigen::Vector2d& r, double w) {
    for (int i = 0; i < p_; ++i) {
      const double wx = w * j.x[i], wy = w * j.y[i];
      for (int k = i; k < p_; ++k) a_[i][k] += wx * j.x[k] + wy * j.y[k];
      b_[i] += wx * r.x() + wy * r.y();
    }
  }
  Mat matrix() const {
    Mat m(p_, p_);
    for (int i = 0; i < p_; ++i)
      for (int k = i; k < p_; ++k) m(i, k) = m(k, i) = a_[i][k];
    return m;
  }
  bool solve(Vec* x) const {
    const Eigen::LDLT<Mat> ldlt(matrix());
    if (ldlt.info() != Eigen::Success || !(ldlt.rcond() > kMinReciprocalCondition)) return false;
    *x = ldlt.solve(Eigen::Map<const Eigen::VectorXd>(b_, p_));
    return x->allFinite();
  }

 private:
  int p_;
  double a_[kMaxParameters][kMaxParameters];
  double b_[kMaxParameters];
};

// Scale of the difference between the residual of each inlier and that of its nearest inlier neighbour: the
// tracking noise when the residuals come from one surface (where the model errs - relief, lens distortion - it errs
// alike at neighbouring points), the residual scale itself when neighbouring points move independently (marine snow
// at various depths). Per coordinate, like the residual scale.
template <typename Points, typename Residual>
double localScale(const Points& points, const std::vector<uint8_t>& inlier, const Residual& residual_of) {
  std::vector<int> index;
  for (size_t i = 0; i < inlier.size(); ++i)
    if (inlier[i]) index.push_back(static_cast<int>(i));
  if (index.size() < 2) return 0.0;
  // Sorted along u, the nearest neighbour search stops once the u gap alone exceeds the best distance.
  std::sort(index.begin(), index.end(), [&](int a, int b) { return points[a].u < points[b].u; });
  const int n = static_cast<int>(index.size());
  std::vector<Eigen::Vector2d> residual(n);
  for (int k = 0; k < n; ++k) residual[k] = residual_of(points[index[k]]);
  std::vector<double> difference(n);
  for (int k = 0; k < n; ++k) {
    const auto& a = points[index[k]];
    double nearest = std::numeric_limits<double>::infinity();
    int best = k;
    for (int direction : {-1, 1}) {
      for (int m = k + direction; m >= 0 && m < n; m += direction) {
        const auto& b = points[index[m]];
        const double du = b.u - a.u;
        if (du * du >= nearest) break;
        const double d = du * du + (b.v - a.v) * (b.v - a.v);
        if (d < nearest) nearest = d, best = m;
      }
    }
    difference[k] = (residual[k] - residual[best]).norm();
  }
  // The difference of two independent residuals has sqrt(2) times their scale.
  const size_t mid = difference.size() / 2;
  std::nth_element(difference.begin(), difference.begin() + mid, difference.end());
  return difference[mid] / (kRayleighMedian * std::sqrt(2.0));
}

double median(std::vector<double>* values) {
  if (values->empty()) return 0.0;
  const size_t mid = values->size() / 2;
  std::nth_element(values->begin(), values->begin() + mid, values->end());
  return (*values)[mid];
}

}  // namespace

RobustMotionFitter::RobustMotionFitter(const RobustFitConfig& config) : config_(config) {
  const std::string error = config_.validate();
  if (!error.empty()) throw std::invalid_argument("RobustFitConfig: " + error);
}

RobustFit RobustMotionFitter::fit(const std::vector<cv::Point2f>& from_px, const std::vector<cv::Point2f>& to_px,
                                  const Eigen::Vector2d& centre_px, const Eigen::VectorXd& initial_parameters) const {
  std::vector<Eigen::Vector2d> from(from_px.size()), to(to_px.size());
  for (size_t i = 0; i < from_px.size(); ++i) from[i] = {from_px[i].x, from_px[i].y};
  for (size_t i = 0; i < to_px.size(); ++i) to[i] = {to_px[i].x, to_px[i].y};
  return fit(from, to, centre_px, initial_parameters);
}

RobustFit RobustMotionFitter::fit(const std::vector<Eigen::Vector2d>& from_px,
                                  const std::vector<Eigen::Vector2d>& to_px, const Eigen::Vector2d& centre_px,
                                  const Eigen::VectorXd& initial_parameters) const {
  const MotionModel model = config_.model;
  const int p = parameterCount(model);
  RobustFit result;
  result.model = model;
  result.parameters = Eigen::VectorXd::Zero(p);
  result.covariance = Eigen::MatrixXd::Zero(p, p);
  result.observations = static_cast<int>(from_px.size());
  result.inlier_mask.assign(from_px.size(), 0);
  auto fail = [&result](FailureReason reason, const std::string& detail) {
    result.ok = false;
    result.failure = reason;
    result.failure_detail = detail;
    return result;
  };
  if (from_px.size() != to_px.size())
    return fail(FailureReason::kInvalidInput,
                std::to_string(from_px.size()) + " points in A but " + std::to_string(to_px.size()) + " in B");
  if (initial_parameters.size() != 0 && initial_parameters.size() != p)
    return fail(FailureReason::kInvalidInput, "initial parameters: " + std::to_string(initial_parameters.size()) +
                                                  " values, the " + toString(model) + " model has " +
                                                  std::to_string(p));
  const int n = static_cast<int>(from_px.size());
  const int minimal = minimalPointCount(model);
  if (n < minimal)
    return fail(FailureReason::kTooFewInliers, std::to_string(n) + " correspondences, the " + toString(model) +
                                                   " model needs at least " + std::to_string(minimal));

  // Centre and normalise by the RMS radius so that every parameter has a comparable scale.
  double sum_sq = 0.0;
  for (int i = 0; i < n; ++i) {
    if (!from_px[i].allFinite() || !to_px[i].allFinite())
      return fail(FailureReason::kInvalidInput, "correspondence " + std::to_string(i) + " is not finite");
    sum_sq += (from_px[i] - centre_px).squaredNorm();
  }
  const double scale_px = sum_sq > 1e-18 ? std::sqrt(sum_sq / n) : 1.0;
  std::vector<Correspondence> points(n);
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector2d a = (from_px[i] - centre_px) / scale_px, b = (to_px[i] - centre_px) / scale_px;
    points[i] = {a.x(), a.y(), b.x(), b.y()};
  }
  return fitNormalised(points, scale_px, initial_parameters);
}

RobustFit RobustMotionFitter::fitNormalised(const std::vector<Correspondence>& points, double scale_px,
                                            const Eigen::VectorXd& initial_parameters) const {
  const MotionModel model = config_.model;
  const bool homography = model == MotionModel::kHomography;
  const int p = parameterCount(model);
  const int n = static_cast<int>(points.size());
  const int minimal = minimalPointCount(model);

  RobustFit result;
  result.model = model;
  result.parameters = Eigen::VectorXd::Zero(p);
  result.covariance = Eigen::MatrixXd::Zero(p, p);
  result.observations = n;
  result.inlier_mask.assign(n, 0);

  // Pixel parameters = d .* normalised parameters (translations scale with the radius, g1 g2 with its inverse).
  Vec d = Vec::Ones(p);
  d[0] = d[1] = scale_px;
  if (homography) d[6] = d[7] = 1.0 / scale_px;

  // Bounding box of the points of A: convergence is judged on how far its corners move.
  double umin = points[0].u, umax = umin, vmin = points[0].v, vmax = vmin;
  for (const Correspondence& c : points) {
    umin = std::min(umin, c.u), umax = std::max(umax, c.u);
    vmin = std::min(vmin, c.v), vmax = std::max(vmax, c.v);
  }
  const Eigen::Vector2d box[4] = {{umin, vmin}, {umax, vmin}, {umin, vmax}, {umax, vmax}};
  auto box_move_px = [&](const Vec& q1, const Vec& q2) {
    double worst = 0.0;
    for (const Eigen::Vector2d& c : box)
      worst = std::max(worst, (warp(model, q1, c.x(), c.y()) - warp(model, q2, c.x(), c.y())).norm());
    return worst * scale_px;
  };
  // A homography must keep the points in front (positive denominator) to be a plausible camera motion.
  auto plausible = [&](const Vec& q) {
    if (!q.allFinite()) return false;
    if (!homography) return true;
    for (const Eigen::Vector2d& c : box)
      if (q[6] * c.x() + q[7] * c.y() + 1.0 <= 0.05) return false;
    return true;
  };

  std::vector<double> residual(n);
  auto compute_residuals = [&](const Vec& q) {
    for (int i = 0; i < n; ++i) {
      const Correspondence& c = points[i];
      residual[i] = (warp(model, q, c.u, c.v) - Eigen::Vector2d(c.tu, c.tv)).norm();
    }
  };
  // Linear solve (direct for linear models, DLT for the homography) over the points of non-zero weight.
  auto solve_linear = [&](const std::vector<double>& weight, Vec* q) {
    NormalEquations equations(p);
    Rows j;
    Eigen::Vector2d b;
    for (int i = 0; i < n; ++i) {
      if (weight[i] <= 0.0) continue;
      const Correspondence& c = points[i];
      linearRows(model, c.u, c.v, c.tu, c.tv, &j, &b);
      equations.add(j, b, weight[i]);
    }
    return equations.solve(q);
  };
  auto weighted_cost = [&](const Vec& q, const std::vector<double>& weight) {
    double cost = 0.0;
    for (int i = 0; i < n; ++i) {
      if (weight[i] <= 0.0) continue;
      const Correspondence& c = points[i];
      cost += weight[i] * (warp(model, q, c.u, c.v) - Eigen::Vector2d(c.tu, c.tv)).squaredNorm();
    }
    return cost;
  };
  // One Gauss-Newton step of the homography on the weighted geometric error, halved until the cost decreases.
  auto gauss_newton_step = [&](const Vec& q, const std::vector<double>& weight, Vec* q_next) {
    NormalEquations equations(p);
    Rows j;
    double cost = 0.0;
    for (int i = 0; i < n; ++i) {
      if (weight[i] <= 0.0) continue;
      const Correspondence& c = points[i];
      jacobian(model, q, c.u, c.v, &j);
      const Eigen::Vector2d r = Eigen::Vector2d(c.tu, c.tv) - warp(model, q, c.u, c.v);
      equations.add(j, r, weight[i]);
      cost += weight[i] * r.squaredNorm();
    }
    Vec step;
    if (!equations.solve(&step)) return false;
    for (int halving = 0; halving < 8; ++halving, step *= 0.5) {
      const Vec candidate = q + step;
      if (plausible(candidate) && weighted_cost(candidate, weight) <= cost) {
        *q_next = candidate;
        return true;
      }
    }
    *q_next = q;  // no descent left: q is the minimum to numerical precision
    return true;
  };
  // Weighted fit from q: the solution itself for the linear models, one Gauss-Newton step for the homography.
  auto weighted_fit = [&](const Vec& q, const std::vector<double>& weight, Vec* q_next) {
    return homography ? gauss_newton_step(q, weight, q_next) : solve_linear(weight, q_next);
  };
  // Unweighted least squares over the weighted points: a few Gauss-Newton steps to convergence for the homography.
  int iterations = 0;
  auto full_fit = [&](const Vec& q, const std::vector<double>& weight, Vec* q_next) {
    ++iterations;
    if (!homography) return solve_linear(weight, q_next);
    Vec current = q;
    for (int step = 0; step < config_.max_iterations; ++step) {
      Vec next;
      if (!gauss_newton_step(current, weight, &next)) return false;
      if (step > 0) ++iterations;
      const double move = box_move_px(current, next);
      current = next;
      if (move < config_.convergence_px) break;
    }
    *q_next = current;
    return true;
  };

  // --- 1. Initial hypothesis: identity, the caller's, LS of all, minimal samples (MSAC cost) ---
  const double threshold = config_.sample_threshold_px / scale_px;
  const double threshold_sq = threshold * threshold;
  Vec best = Vec::Zero(p);
  double best_cost = std::numeric_limits<double>::infinity();
  int best_support = 0;
  auto score = [&](const Vec& q) {
    if (!plausible(q)) return;
    double cost = 0.0;
    int support = 0;
    for (const Correspondence& c : points) {
      const double r2 = (warp(model, q, c.u, c.v) - Eigen::Vector2d(c.tu, c.tv)).squaredNorm();
      cost += std::min(r2, threshold_sq);
      support += r2 <= threshold_sq;
    }
    if (cost < best_cost) {
      best_cost = cost;
      best = q;
      best_support = support;
    }
  };
  score(Vec::Zero(p));
  if (initial_parameters.size() == p) score(initial_parameters.array() / d.array());
  std::vector<double> weight(n, 1.0);
  Vec q;
  if (solve_linear(weight, &q)) score(q);

  std::mt19937 rng(config_.seed);
  const double log_miss = std::log(1.0 - config_.sample_confidence);
  auto samples_needed = [&]() {
    const double all_inlier = std::pow(static_cast<double>(best_support) / n, minimal);
    if (all_inlier >= 1.0 - 1e-12) return 0;
    const double needed = log_miss / std::log1p(-all_inlier);
    return needed < config_.max_samples ? static_cast<int>(std::ceil(needed)) : config_.max_samples;
  };
  std::vector<int> sample(minimal);
  std::vector<double> sample_weight(n, 0.0);
  for (int s = 0; s < std::min(config_.max_samples, samples_needed()); ++s) {
    for (int k = 0; k < minimal; ++k) {
      int index;
      do {
        index = static_cast<int>(rng() % static_cast<uint32_t>(n));
      } while (std::find(sample.begin(), sample.begin() + k, index) != sample.begin() + k);
      sample[k] = index;
      sample_weight[index] = 1.0;
    }
    if (solve_linear(sample_weight, &q)) score(q);
    for (int k = 0; k < minimal; ++k) sample_weight[sample[k]] = 0.0;
  }
  if (!std::isfinite(best_cost) || best_support < minimal) {
    result.inlier_mask.assign(n, 0);
    result.failure = best_support < minimal ? FailureReason::kTooFewInliers : FailureReason::kInconsistent;
    result.failure_detail = "no motion hypothesis is supported by " + std::to_string(minimal) +
                            " correspondences within sample_threshold_px " +
                            std::to_string(config_.sample_threshold_px);
    return result;
  }

  auto count = [](const std::vector<uint8_t>& set) { return static_cast<int>(std::count(set.begin(), set.end(), 1)); };

  // --- 2. Re-weighted least squares (Tukey), striking off points beyond rejection_k * sigma ---
  // The first inlier set: within rejection_k * sigma0 of the best hypothesis, sigma0 from the lowest fifth of the
  // residuals rather than from those within sample_threshold_px. False matches that agree among themselves (marine
  // snow at various depths) would otherwise enter that set by the dozen and drag the fit away from the seabed.
  std::vector<uint8_t> inlier(n), next_inlier(n);
  std::vector<double> inlier_residuals;
  inlier_residuals.reserve(n);
  const double min_scale = config_.min_scale_px / scale_px;
  compute_residuals(best);
  inlier_residuals = residual;
  const int low = std::max(minimal, n / 5) - 1;
  std::nth_element(inlier_residuals.begin(), inlier_residuals.begin() + low, inlier_residuals.end());
  const double sigma0 = std::max(min_scale, inlier_residuals[low] / kRayleighFifth);
  for (int i = 0; i < n; ++i) inlier[i] = residual[i] <= config_.rejection_k * sigma0;
  if (count(inlier) < minimal)
    for (int i = 0; i < n; ++i) inlier[i] = residual[i] <= threshold;
  q = best;
  auto robust_scale = [&](const std::vector<uint8_t>& set) {
    inlier_residuals.clear();
    for (int i = 0; i < n; ++i)
      if (set[i]) inlier_residuals.push_back(residual[i]);
    return std::max(min_scale, median(&inlier_residuals) / kRayleighMedian);
  };

  for (int i = 0; i < n; ++i) weight[i] = inlier[i];
  if (!full_fit(best, weight, &q) || !plausible(q)) q = best;
  for (int it = 0; it < config_.max_iterations; ++it) {
    compute_residuals(q);
    const double sigma = robust_scale(inlier);
    for (int i = 0; i < n; ++i) {
      next_inlier[i] = residual[i] <= config_.rejection_k * sigma;
      const double x = residual[i] / (config_.tukey_c * sigma);
      weight[i] = next_inlier[i] && x < 1.0 ? (1.0 - x * x) * (1.0 - x * x) : 0.0;
    }
    if (count(next_inlier) < minimal) break;
    Vec q_next;
    ++iterations;
    if (!weighted_fit(q, weight, &q_next) || !plausible(q_next)) break;
    const bool stable = next_inlier == inlier;
    const double move = box_move_px(q, q_next);
    inlier.swap(next_inlier);
    q = q_next;
    if (stable && move < config_.convergence_px) break;
  }

  // --- 3. Least squares on the inlier set, until that set no longer changes ---
  bool fitted = false;
  for (int it = 0; it < config_.max_iterations; ++it) {
    if (count(inlier) < minimal) break;
    for (int i = 0; i < n; ++i) weight[i] = inlier[i];
    Vec q_next;
    if (!full_fit(q, weight, &q_next) || !plausible(q_next)) {
      fitted = false;
      break;
    }
    q = q_next;
    fitted = true;
    compute_residuals(q);
    const double sigma = robust_scale(inlier);
    for (int i = 0; i < n; ++i) next_inlier[i] = residual[i] <= config_.rejection_k * sigma;
    if (next_inlier == inlier || count(next_inlier) < minimal) break;
    inlier.swap(next_inlier);
    fitted = false;  // the set changed: refit
  }
  if (!fitted) {
    // The last set change was not refitted (iteration cap): refit once so that q and the set agree.
    for (int i = 0; i < n; ++i) weight[i] = inlier[i];
    Vec q_next;
    if (count(inlier) >= minimal && full_fit(q, weight, &q_next) && plausible(q_next)) {
      q = q_next;
      fitted = true;
    }
  }
  compute_residuals(q);

  // --- Result ---
  const int inliers = count(inlier);
  double sum_sq = 0.0;
  NormalEquations information(p);
  Rows j;
  for (int i = 0; i < n; ++i) {
    if (!inlier[i]) continue;
    sum_sq += residual[i] * residual[i];
    const Correspondence& c = points[i];
    jacobian(model, q, c.u, c.v, &j);
    information.add(j, Eigen::Vector2d::Zero(), 1.0);
  }
  const int dof = 2 * inliers - p;
  const double sigma = dof > 0 ? std::sqrt(sum_sq / dof) : 0.0;
  const double sigma_cov = std::max(sigma, min_scale);

  result.inlier_mask = inlier;
  result.inliers = inliers;
  result.inlier_fraction = static_cast<double>(inliers) / n;
  result.residual_scale_px = sigma * scale_px;
  result.local_scale_px = localScale(points, inlier,
                                     [&](const Correspondence& c) -> Eigen::Vector2d {
                                       return warp(model, q, c.u, c.v) - Eigen::Vector2d(c.tu, c.tv);
                                     }) *
                          scale_px;
  result.iterations = iterations;
  const Vec q_px = q.array() * d.array();
  result.parameters = q_px;

  if (!fitted || !plausible(q)) {
    result.failure = FailureReason::kNotConverged;
    result.failure_detail = "the least-squares fit on the inliers did not converge";
    return result;
  }
  const Eigen::LDLT<Mat> ldlt(information.matrix());
  if (ldlt.info() != Eigen::Success || !(ldlt.rcond() > kMinReciprocalCondition)) {
    result.failure = FailureReason::kInconsistent;
    result.failure_detail = "the " + std::to_string(inliers) + " inliers do not determine the " + toString(model) +
                            " model (degenerate configuration)";
    return result;
  }
  const Mat covariance = sigma_cov * sigma_cov * ldlt.solve(Mat::Identity(p, p));
  result.covariance = d.asDiagonal() * covariance * d.asDiagonal();

  if (inliers < config_.min_inliers || result.inlier_fraction < config_.min_inlier_fraction) {
    std::ostringstream detail;
    detail << inliers << " inliers of " << n << " (" << std::lround(100.0 * result.inlier_fraction)
           << " %), need min_inliers " << config_.min_inliers << " and min_inlier_fraction "
           << config_.min_inlier_fraction;
    result.failure = FailureReason::kTooFewInliers;
    result.failure_detail = detail.str();
    return result;
  }
  result.ok = true;
  result.failure = FailureReason::kNone;
  return result;
}

}  // namespace registration
}  // namespace exocet_mosaic
