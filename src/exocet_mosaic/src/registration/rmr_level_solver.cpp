#include "rmr_level_solver.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include <Eigen/Dense>

namespace exocet_mosaic {
namespace registration {
namespace internal {

namespace {

constexpr double kMadToSigma = 1.4826;  // MAD of a Gaussian = 0.6745 sigma
constexpr int kMaxParameters = 10;      // 8 geometric + gain + offset
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
constexpr int kMedianSample = 2048;       // residuals used for the robust scale
constexpr int kCorrelationSample = 2000;  // pixels used to measure the residuals' spatial correlation

using SmallMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxParameters, kMaxParameters>;
using SmallVector = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxParameters, 1>;

// Residual B(W(x)) - gain A(x) - offset of every selected pixel (bilinear B; NaN when W(x) falls outside B). Writes
// the magnitudes of the evaluated ones to `magnitudes`; returns how many were evaluated.
template <bool kPerspective>
int evaluate(const RmrLevelSelection& sel, const cv::Mat& target, const Eigen::Matrix3d& p, double gain, double offset,
             float* residuals, float* magnitudes) {
  const double p00 = p(0, 0), p01 = p(0, 1), p02 = p(0, 2), p10 = p(1, 0), p11 = p(1, 1), p12 = p(1, 2);
  const double p20 = p(2, 0), p21 = p(2, 1), p22 = p(2, 2);
  const double max_x = target.cols - 1, max_y = target.rows - 1;
  const size_t step = target.step1();
  const float* base = target.ptr<float>();
  const float* xs = sel.x.data();
  const float* ys = sel.y.data();
  const float* values = sel.value.data();
  const float g = static_cast<float>(gain), o = static_cast<float>(offset);
  int evaluated = 0;
  for (int i = 0; i < sel.count; ++i) {
    const double x = xs[i], y = ys[i];
    double xp = p00 * x + p01 * y + p02;
    double yp = p10 * x + p11 * y + p12;
    if (kPerspective) {
      const double d = p20 * x + p21 * y + p22;
      if (!(d > 1e-6)) {
        residuals[i] = kNaN;
        continue;
      }
      xp /= d;
      yp /= d;
    }
    if (!(xp >= 0.0 && yp >= 0.0 && xp < max_x && yp < max_y)) {
      residuals[i] = kNaN;
      continue;
    }
    const int ix = static_cast<int>(xp), iy = static_cast<int>(yp);
    const float fx = static_cast<float>(xp - ix), fy = static_cast<float>(yp - iy);
    const float* q = base + iy * step + ix;
    const float top = q[0] + fx * (q[1] - q[0]);
    const float bottom = q[step] + fx * (q[step + 1] - q[step]);
    const float e = top + fy * (bottom - top) - (g * values[i] + o);
    residuals[i] = e;
    magnitudes[evaluated++] = std::abs(e);
  }
  return evaluated;
}

// Dot product of two float arrays: float partial sums over short blocks (eight independent lanes, which the compiler
// vectorises), added in double. `b` null: the sum of `a`.
double dot(const float* a, const float* b, int n) {
  constexpr int kBlock = 512;
  double total = 0.0;
  for (int start = 0; start < n; start += kBlock) {
    const int end = std::min(n, start + kBlock);
    float acc[8] = {};
    int i = start;
    if (b) {
      for (; i + 8 <= end; i += 8)
        for (int l = 0; l < 8; ++l) acc[l] += a[i + l] * b[i + l];
      for (; i < end; ++i) acc[0] += a[i] * b[i];
    } else {
      for (; i + 8 <= end; i += 8)
        for (int l = 0; l < 8; ++l) acc[l] += a[i + l];
      for (; i < end; ++i) acc[0] += a[i];
    }
    double block = 0.0;
    for (int l = 0; l < 8; ++l) block += acc[l];
    total += block;
  }
  return total;
}

// Column j of the Jacobian (before the gain): steepest descent j, then A, then 1 (nullptr).
const float* column(const RmrLevelSelection& sel, int j) {
  const int ng = sel.geometric_parameters;
  if (j < ng) return sel.steepest.data() + static_cast<size_t>(j) * sel.count;
  if (j == ng) return sel.value.data();
  return nullptr;
}

// Tukey weights and the normal equations sum w s s^T, sum w s e, with s = the Jacobian columns `columns` (nullptr: a
// column of ones). `weighted` and `scratch` are work arrays of sel.count.
void accumulate(const RmrLevelSelection& sel, const std::vector<const float*>& columns, const float* residuals,
                double cutoff, float* weights, float* weighted, float* scratch, SmallMatrix* h, SmallVector* b) {
  const int n = sel.count;
  const int nt = static_cast<int>(columns.size());
  const float inv_cutoff = static_cast<float>(1.0 / cutoff);
  for (int i = 0; i < n; ++i) {
    const float e = residuals[i];
    const float r = e * inv_cutoff;
    const bool inside = std::abs(r) < 1.0f;  // false for NaN (not evaluated)
    const float t = 1.0f - r * r;
    const float w = inside ? t * t : 0.0f;
    weights[i] = w;
    weighted[i] = inside ? w * e : 0.0f;
  }
  h->resize(nt, nt);
  b->resize(nt);
  for (int j = 0; j < nt; ++j) {
    const float* cj = columns[j];
    (*b)[j] = dot(weighted, cj, n);
    if (cj) {
      for (int i = 0; i < n; ++i) scratch[i] = weights[i] * cj[i];
    } else {
      std::copy(weights, weights + n, scratch);
    }
    for (int k = j; k < nt; ++k) (*h)(j, k) = (*h)(k, j) = dot(scratch, columns[k], n);
  }
}

// The geometric columns of the Jacobian are gain * steepest descent (the template is gain * A + offset).
void applyGain(int ng, double gain, SmallMatrix* h, SmallVector* b) {
  const int nt = static_cast<int>(h->rows());
  for (int j = 0; j < nt; ++j) {
    for (int k = 0; k < nt; ++k) (*h)(j, k) *= (j < ng ? gain : 1.0) * (k < ng ? gain : 1.0);
    if (j < ng) (*b)[j] *= gain;
  }
}

// Jacobi-scaled Cholesky of the normal matrix (the homography's columns span 12 orders of magnitude in pixels).
struct ScaledCholesky {
  SmallVector inv_sqrt_diagonal;
  Eigen::LDLT<SmallMatrix> ldlt;
  bool ok = false;

  explicit ScaledCholesky(const SmallMatrix& h) {
    const int n = static_cast<int>(h.rows());
    inv_sqrt_diagonal.resize(n);
    for (int j = 0; j < n; ++j) {
      if (!(h(j, j) > 0.0)) return;
      inv_sqrt_diagonal[j] = 1.0 / std::sqrt(h(j, j));
    }
    const SmallMatrix scaled = inv_sqrt_diagonal.asDiagonal() * h * inv_sqrt_diagonal.asDiagonal();
    ldlt.compute(scaled);
    ok = ldlt.info() == Eigen::Success && ldlt.isPositive() && ldlt.rcond() > 1e-10;
  }
  SmallVector solve(const SmallVector& b) const {
    return inv_sqrt_diagonal.asDiagonal() * ldlt.solve(SmallVector(inv_sqrt_diagonal.asDiagonal() * b));
  }
};

}  // namespace

Eigen::VectorXd parametersFromCentred(MotionModel model, const Eigen::Matrix3d& m) {
  Eigen::VectorXd p(parameterCount(model));
  p[0] = m(0, 2);
  p[1] = m(1, 2);
  switch (model) {
    case MotionModel::kTranslation:
      break;
    case MotionModel::kSimilarity:
      p[2] = 0.5 * (m(0, 0) + m(1, 1)) - 1.0;
      p[3] = 0.5 * (m(1, 0) - m(0, 1));
      break;
    case MotionModel::kAffine:
    case MotionModel::kHomography:
      p[2] = m(0, 0) - 1.0;
      p[3] = m(0, 1);
      p[4] = m(1, 0);
      p[5] = m(1, 1) - 1.0;
      if (model == MotionModel::kHomography) {
        p[6] = m(2, 0);
        p[7] = m(2, 1);
      }
      break;
  }
  return p;
}

double cornerShift(const Eigen::Matrix3d& m, const Eigen::Vector2d& c) {
  double worst = 0.0;
  for (const double su : {-1.0, 1.0}) {
    for (const double sv : {-1.0, 1.0}) {
      const Eigen::Vector3d x(su * c.x(), sv * c.y(), 1.0);
      const Eigen::Vector3d y = m * x;
      if (!(std::abs(y.z()) > 1e-12)) return std::numeric_limits<double>::infinity();
      const double d = (y.head<2>() / y.z() - x.head<2>()).norm();
      if (!std::isfinite(d)) return std::numeric_limits<double>::infinity();
      worst = std::max(worst, d);
    }
  }
  return worst;
}

RmrLevelResult RmrLevelSolver::solve(const RmrLevelSelection& sel, const cv::Mat& target, const Eigen::Vector2d& centre,
                                     const RmrSolverSettings& settings, RmrState* state) {
  RmrLevelResult result;
  const int ng = parameterCount(settings.model);
  const bool perspective = settings.model == MotionModel::kHomography;
  // The geometric parameters estimated here: all, or the translation only (the first two in every model).
  const int active = settings.translation_only ? 2 : ng;
  std::vector<const float*> columns;
  for (int j = 0; j < active; ++j) columns.push_back(column(sel, j));
  if (settings.illumination) {
    columns.push_back(sel.value.data());
    columns.push_back(nullptr);
  }
  residuals_.resize(sel.count);
  weights_.resize(sel.count);
  magnitudes_.resize(sel.count);
  weighted_.resize(sel.count);
  scratch_.resize(sel.count);
  Eigen::Matrix3d centring = Eigen::Matrix3d::Identity();
  centring(0, 2) = -centre.x();
  centring(1, 2) = -centre.y();
  const Eigen::Matrix3d decentring = centring.inverse();
  SmallMatrix h;
  SmallVector b;
  for (int iteration = 0; iteration < settings.max_iterations; ++iteration) {
    const Eigen::Matrix3d pixel = decentring * state->centred * centring;
    const int evaluated =
        perspective
            ? evaluate<true>(sel, target, pixel, state->gain, state->offset, residuals_.data(), magnitudes_.data())
            : evaluate<false>(sel, target, pixel, state->gain, state->offset, residuals_.data(), magnitudes_.data());
    result.evaluated = evaluated;
    if (evaluated < settings.min_evaluated) {
      result.failure = FailureReason::kMotionTooLarge;
      result.detail = "only " + std::to_string(evaluated) + " of " + std::to_string(sel.count) +
                      " reference pixels land in the other image (need " + std::to_string(settings.min_evaluated) + ")";
      return result;
    }
    // Robust scale: normalised median absolute residual (the residuals' median is ~0 near the solution), on a
    // regular subsample of a few thousand pixels (ample for a scale, and a few times cheaper).
    const int stride = std::max(1, evaluated / kMedianSample);
    const int sampled = (evaluated + stride - 1) / stride;
    for (int k = 1; k < sampled; ++k) magnitudes_[k] = magnitudes_[k * stride];
    float* mid = magnitudes_.data() + sampled / 2;
    std::nth_element(magnitudes_.data(), mid, magnitudes_.data() + sampled);
    result.scale = std::max(settings.min_scale, kMadToSigma * *mid);
    accumulate(sel, columns, residuals_.data(), settings.tukey_constant * result.scale, weights_.data(),
               weighted_.data(), scratch_.data(), &h, &b);
    applyGain(active, state->gain, &h, &b);
    result.normal_matrix = h;
    const ScaledCholesky cholesky(h);
    if (!cholesky.ok) {
      result.failure = FailureReason::kInconsistent;
      result.detail =
          "the normal equations are singular or ill-conditioned (too little texture in some direction, "
          "or too few inliers)";
      return result;
    }
    // Inverse compositional update: W <- W o W(delta)^-1, since delta was linearised about the template A. A step that
    // would move an image corner by more than max_step_px is shortened (damping: far from the solution, or along a
    // direction the texture hardly constrains, the linearisation does not hold that far).
    SmallVector delta = cholesky.solve(b);
    Eigen::VectorXd geometric = Eigen::VectorXd::Zero(ng);
    geometric.head(active) = delta.head(active);
    Eigen::Matrix3d increment = centredMatrix(settings.model, geometric);
    const double step_px = cornerShift(increment, centre);
    if (step_px > settings.max_step_px) {
      delta *= settings.max_step_px / step_px;
      geometric.head(active) = delta.head(active);
      increment = centredMatrix(settings.model, geometric);
    }
    Eigen::Matrix3d updated = state->centred * increment.inverse();
    updated /= updated(2, 2);
    state->centred = centredMatrix(settings.model, parametersFromCentred(settings.model, updated));
    if (settings.illumination) {
      state->gain += delta[active];
      state->offset += delta[active + 1];
    }
    ++result.iterations;
    result.last_increment_px = cornerShift(increment, centre);
    if (!std::isfinite(result.last_increment_px) || !state->centred.allFinite() ||
        !(cornerShift(state->centred, centre) <= settings.divergence_px)) {
      result.failure = FailureReason::kNotConverged;
      result.detail = "the iterations diverged";
      return result;
    }
    if (result.last_increment_px < settings.convergence_px) {
      result.converged = true;
      break;
    }
  }
  return result;
}

RmrFitStatistics RmrLevelSolver::statistics(const RmrLevelSelection& sel, cv::Size level_size, const RmrState& state,
                                            const RmrLevelResult& result) {
  RmrFitStatistics stats;
  // Fresh memory costs a page fault per 4 KiB: reuse the previous weights image if nobody else holds it.
  if (weights_image_.empty() || weights_image_.size() != level_size || !weights_image_.u ||
      weights_image_.u->refcount != 1)
    weights_image_ = cv::Mat(level_size, CV_32F);
  weights_image_.setTo(cv::Scalar(kNaN));
  stats.weights = weights_image_;
  double sw = 0.0, sa = 0.0, sb = 0.0, saa = 0.0, sbb = 0.0, sab = 0.0;
  for (int i = 0; i < sel.count; ++i) {
    const float e = residuals_[i];
    if (std::isnan(e)) continue;
    const float w = weights_[i];
    stats.weights.at<float>(static_cast<int>(sel.y[i]), static_cast<int>(sel.x[i])) = w;
    ++stats.evaluated;
    if (w > 0.5f) ++stats.inliers;
    // Weighted by the robust weights, so that outliers (a fish) do not make a good alignment look inconsistent.
    const double a = sel.value[i];
    const double bv = e + state.gain * a + state.offset;
    sw += w;
    sa += w * a;
    sb += w * bv;
    saa += w * a * a;
    sbb += w * bv * bv;
    sab += w * a * bv;
  }
  if (sw > 0.0) {
    const double var_a = saa - sa * sa / sw, var_b = sbb - sb * sb / sw, cov = sab - sa * sb / sw;
    stats.correlation = (var_a > 0.0 && var_b > 0.0) ? cov / std::sqrt(var_a * var_b) : 0.0;
  }

  // Correlated residuals: the parameters' variance is H^-1 (sum_ij a_i a_j^T) H^-1 with a_i = w_i e_i s_i, whereas
  // sigma^2 H^-1 assumes independent pixels. The factor is the ratio of the two meats measured in the metric H^-1,
  // with the pairs of neighbouring selected pixels (8-connectivity) as the correlated ones.
  const SmallMatrix h = result.normal_matrix;
  const int nt = static_cast<int>(h.rows());
  const int ng = sel.geometric_parameters;
  const int n = sel.count;
  if (nt == 0) return stats;
  const ScaledCholesky cholesky(h);
  if (!cholesky.ok) return stats;
  // Whitening: a^T H^-1 a = |Q a|^2 with Q = D^-1/2 L^-1 P S, where S H S = P^T L D L^T P (S: Jacobi scaling).
  const Eigen::LDLT<SmallMatrix>& ldlt = cholesky.ldlt;
  SmallMatrix q(nt, nt);
  for (int k = 0; k < nt; ++k) {
    SmallVector y = SmallVector::Zero(nt);
    y[k] = cholesky.inv_sqrt_diagonal[k];
    y = ldlt.transpositionsP() * y;
    ldlt.matrixL().solveInPlace(y);
    q.col(k) = y.cwiseQuotient(ldlt.vectorD().cwiseSqrt());
  }
  // Per pixel a_i = (w e)_i (gain * steepest, A, 1) and its whitened z_i = Q a_i, on about kCorrelationSample
  // regularly spaced pixels and their neighbours (enough for a ratio).
  const auto whiten = [&](int i, SmallVector* z) -> bool {
    const float e = residuals_[i];
    if (std::isnan(e) || !(weights_[i] > 0.0f)) return false;
    const double we = double(weights_[i]) * e;
    SmallVector a(nt);
    for (int j = 0; j < nt; ++j) {
      const float* cj = column(sel, j);
      a[j] = we * (cj ? cj[i] : 1.0f) * (j < ng ? state.gain : 1.0);
    }
    for (int j = 0; j < nt; ++j) {  // z = q a, by hand: Eigen's general product is slow for such small sizes
      double v = 0.0;
      for (int k = 0; k < nt; ++k) v += q(j, k) * a[k];
      (*z)[j] = v;
    }
    return true;
  };
  const int step = std::max(1, n / kCorrelationSample);
  double white = 0.0, cross = 0.0;
  SmallVector zi(nt), zk(nt);
  for (int i = 0; i < n; i += step) {
    if (!whiten(i, &zi)) continue;
    white += zi.squaredNorm();
    for (const int k : sel.next[i])
      if (k >= 0 && whiten(k, &zk)) cross += 2.0 * zi.dot(zk);
  }
  if (white > 0.0) stats.correlation_inflation = std::clamp((white + cross) / white, 1.0, 10.0);
  const SmallMatrix identity = SmallMatrix::Identity(nt, nt);
  SmallMatrix inverse(nt, nt);
  for (int j = 0; j < nt; ++j) inverse.col(j) = cholesky.solve(identity.col(j));
  stats.covariance = result.scale * result.scale * stats.correlation_inflation * inverse;
  return stats;
}

}  // namespace internal
}  // namespace registration
}  // namespace exocet_mosaic
