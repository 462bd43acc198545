#include "exocet_common/geometry/fundamental_estimator.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <random>
#include <sstream>
#include <stdexcept>

#include <Eigen/Dense>

namespace exocet_common {
namespace geometry {

namespace {

/// Hartley's normalisation of the listed points: centroid to the origin, mean distance sqrt(2).
Eigen::Matrix3d normalizingTransform(const std::vector<Eigen::Vector2d>& p, const std::vector<int>& subset) {
  Eigen::Vector2d centroid = Eigen::Vector2d::Zero();
  for (int i : subset) centroid += p[i];
  centroid /= static_cast<double>(subset.size());
  double mean_distance = 0.0;
  for (int i : subset) mean_distance += (p[i] - centroid).norm();
  mean_distance /= static_cast<double>(subset.size());
  const double s = mean_distance > 0.0 ? std::sqrt(2.0) / mean_distance : 1.0;
  Eigen::Matrix3d t;
  t << s, 0.0, -s * centroid.x(), 0.0, s, -s * centroid.y(), 0.0, 0.0, 1.0;
  return t;
}

std::vector<int> allIndices(size_t n) {
  std::vector<int> v(n);
  std::iota(v.begin(), v.end(), 0);
  return v;
}

/// Sum of the truncated quadratic loss (MSAC) and the inliers of F.
double scoreOf(const Eigen::Matrix3d& F, const std::vector<Eigen::Vector2d>& a, const std::vector<Eigen::Vector2d>& b,
               double threshold_px, std::vector<bool>* inliers, int* count) {
  const double t2 = threshold_px * threshold_px;
  double score = 0.0;
  *count = 0;
  inliers->assign(a.size(), false);
  for (size_t i = 0; i < a.size(); ++i) {
    const double d = sampsonDistance_px(F, a[i], b[i]);
    const double d2 = std::isfinite(d) ? d * d : t2;
    if (d2 < t2) {
      (*inliers)[i] = true;
      ++*count;
      score += d2;
    } else {
      score += t2;
    }
  }
  return score;
}

}  // namespace

Eigen::Matrix3d eightPointFundamental(const std::vector<Eigen::Vector2d>& a, const std::vector<Eigen::Vector2d>& b,
                                      const std::vector<int>& subset) {
  if (a.size() != b.size())
    throw std::invalid_argument("eightPointFundamental: " + std::to_string(a.size()) + " points in the first image, " +
                                std::to_string(b.size()) + " in the second");
  if (subset.size() < 8)
    throw std::invalid_argument("eightPointFundamental: needs at least 8 matches, got " +
                                std::to_string(subset.size()));
  const Eigen::Matrix3d ta = normalizingTransform(a, subset);
  const Eigen::Matrix3d tb = normalizingTransform(b, subset);
  // One row per match: b^T F a = 0 is linear in the 9 entries of F (row-major).
  Eigen::Matrix<double, Eigen::Dynamic, 9> rows(subset.size(), 9);
  for (size_t k = 0; k < subset.size(); ++k) {
    const int i = subset[k];
    const Eigen::Vector3d p = ta * a[i].homogeneous();
    const Eigen::Vector3d q = tb * b[i].homogeneous();
    rows.row(k) << q.x() * p.x(), q.x() * p.y(), q.x(), q.y() * p.x(), q.y() * p.y(), q.y(), p.x(), p.y(), 1.0;
  }
  Eigen::Matrix<double, 9, 1> f;
  if (subset.size() <= 9) {
    // A minimal sample: the null vector from the full SVD (the system has fewer rows than unknowns).
    Eigen::JacobiSVD<Eigen::MatrixXd> svd(rows, Eigen::ComputeFullV);
    f = svd.matrixV().col(8);
  } else {
    // Many matches: the smallest eigenvector of the 9x9 normal matrix (well conditioned after normalisation).
    const Eigen::Matrix<double, 9, 9> normal = rows.transpose() * rows;
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 9, 9>> eigen(normal);
    f = eigen.eigenvectors().col(0);
  }
  Eigen::Matrix3d fn;
  fn << f(0), f(1), f(2), f(3), f(4), f(5), f(6), f(7), f(8);
  // The closest rank-2 matrix in Frobenius norm: zero the smallest singular value.
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(fn, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Vector3d s = svd.singularValues();
  s(2) = 0.0;
  fn = svd.matrixU() * s.asDiagonal() * svd.matrixV().transpose();
  Eigen::Matrix3d F = tb.transpose() * fn * ta;
  const double norm = F.norm();
  if (norm > 0.0) F /= norm;
  return F;
}

Eigen::Matrix3d eightPointFundamental(const std::vector<Eigen::Vector2d>& a, const std::vector<Eigen::Vector2d>& b) {
  return eightPointFundamental(a, b, allIndices(a.size()));
}

double sampsonDistance_px(const Eigen::Matrix3d& F, const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  const Eigen::Vector3d fa = F * a.homogeneous();
  const Eigen::Vector3d ftb = F.transpose() * b.homogeneous();
  const double algebraic = b.homogeneous().dot(fa);
  const double gradient_sq = fa.x() * fa.x() + fa.y() * fa.y() + ftb.x() * ftb.x() + ftb.y() * ftb.y();
  if (!(gradient_sq > 0.0)) return std::numeric_limits<double>::infinity();
  return std::abs(algebraic) / std::sqrt(gradient_sq);
}

std::string FundamentalConfig::validate() const {
  std::ostringstream err;
  if (!(threshold_px > 0.0)) err << "threshold_px = " << threshold_px << " must be > 0; ";
  if (!(confidence > 0.0 && confidence < 1.0)) err << "confidence = " << confidence << " out of range (0, 1); ";
  if (max_iterations < 1) err << "max_iterations = " << max_iterations << " must be >= 1; ";
  if (refinement_rounds < 1) err << "refinement_rounds = " << refinement_rounds << " must be >= 1; ";
  std::string s = err.str();
  if (!s.empty()) s.resize(s.size() - 2);
  return s;
}

FundamentalEstimator::FundamentalEstimator(const FundamentalConfig& config) : config_(config) {
  const std::string problem = config_.validate();
  if (!problem.empty()) throw std::invalid_argument("fundamental: " + problem);
}

FundamentalResult FundamentalEstimator::estimate(const std::vector<Eigen::Vector2d>& a,
                                                 const std::vector<Eigen::Vector2d>& b) const {
  if (a.size() != b.size())
    throw std::invalid_argument("FundamentalEstimator: " + std::to_string(a.size()) + " points in the first image, " +
                                std::to_string(b.size()) + " in the second");
  FundamentalResult result;
  const int n = static_cast<int>(a.size());
  result.inliers.assign(n, false);
  if (n < 8) {
    result.failure = "only " + std::to_string(n) + " matches (at least 8 needed)";
    return result;
  }
  std::mt19937_64 rng(config_.seed);
  std::vector<int> pool = allIndices(n), sample(8);
  std::vector<bool> inliers;
  double best_score = std::numeric_limits<double>::infinity();
  int best_count = 0;
  long needed = config_.max_iterations;
  int iteration = 0;
  for (; iteration < needed && iteration < config_.max_iterations; ++iteration) {
    // 8 distinct matches: a partial Fisher-Yates shuffle of the pool.
    for (int k = 0; k < 8; ++k) {
      std::uniform_int_distribution<int> pick(k, n - 1);
      std::swap(pool[k], pool[pick(rng)]);
      sample[k] = pool[k];
    }
    const Eigen::Matrix3d F = eightPointFundamental(a, b, sample);
    if (!F.allFinite()) continue;
    int count = 0;
    const double score = scoreOf(F, a, b, config_.threshold_px, &inliers, &count);
    if (score < best_score) {
      best_score = score;
      best_count = count;
      result.F = F;
      result.inliers = inliers;
      const double w = static_cast<double>(count) / n;
      // log1p: for a small inlier ratio, log(1 - w^8) would round to 0 and the count overflow.
      const double all_inliers = std::pow(w, 8);
      const double samples =
          all_inliers >= 1.0 ? 0.0 : std::ceil(std::log(1.0 - config_.confidence) / std::log1p(-all_inliers));
      needed = std::isfinite(samples) ? static_cast<long>(std::min<double>(samples, config_.max_iterations))
                                      : config_.max_iterations;
    }
  }
  result.iterations = iteration;
  // Final least squares on all inliers, repeated while it finds a better consensus.
  for (int round = 0; round < config_.refinement_rounds && best_count >= 8; ++round) {
    std::vector<int> subset;
    for (int i = 0; i < n; ++i)
      if (result.inliers[i]) subset.push_back(i);
    const Eigen::Matrix3d F = eightPointFundamental(a, b, subset);
    if (!F.allFinite()) break;
    int count = 0;
    const double score = scoreOf(F, a, b, config_.threshold_px, &inliers, &count);
    const bool same_set = inliers == result.inliers;
    if (score <= best_score || same_set) {
      best_score = score;
      best_count = count;
      result.F = F;
      result.inliers = inliers;
    }
    if (same_set || score > best_score) break;
  }
  result.inlier_count = best_count;
  double sum_sq = 0.0;
  for (int i = 0; i < n; ++i) {
    if (!result.inliers[i]) continue;
    const double d = sampsonDistance_px(result.F, a[i], b[i]);
    sum_sq += d * d;
  }
  result.rms_sampson_px = best_count > 0 ? std::sqrt(sum_sq / best_count) : 0.0;
  result.ok = best_count >= 8;
  if (!result.ok) result.failure = "only " + std::to_string(best_count) + " inliers (at least 8 needed)";
  return result;
}

}  // namespace geometry
}  // namespace exocet_common
