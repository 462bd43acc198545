#include "exocet_mosaic/selfcal/mendonca_cipolla_calibrator.h"

#include <cmath>
#include <limits>
#include <memory>
#include <sstream>
#include <stdexcept>

#include <ceres/ceres.h>
#include <Eigen/Dense>

namespace exocet_mosaic {
namespace selfcal {

Eigen::Matrix3d Intrinsics::K() const {
  Eigen::Matrix3d k;
  k << alpha_u, 0.0, u0, 0.0, alpha_v, v0, 0.0, 0.0, 1.0;
  return k;
}

namespace {

/**
 * (s1 - s2) / s2 of E = K^T F K without an SVD (so that Ceres differentiates it exactly): for M = E^T E with
 * eigenvalues s1^2, s2^2 and 0 (F has rank 2), a = trace(M) = s1^2 + s2^2 and b = (a^2 - trace(M^2)) / 2 = s1^2 s2^2,
 * hence s1 - s2 = sqrt(a - 2 sqrt(b)) and s1 + s2 = sqrt(a + 2 sqrt(b)).
 */
struct SingularValueGap {
  template <typename T>
  static T relativeGap(const Eigen::Matrix3d& F, const T* k) {
    Eigen::Matrix<T, 3, 3> K;
    K << k[0], T(0.0), k[2], T(0.0), k[1], k[3], T(0.0), T(0.0), T(1.0);
    const Eigen::Matrix<T, 3, 3> E = K.transpose() * F.cast<T>() * K;
    const Eigen::Matrix<T, 3, 3> M = E.transpose() * E;
    const T a = M.trace();
    const T b = T(0.5) * (a * a - (M * M).trace());
    const T root_b = b > T(0.0) ? T(sqrt(b)) : T(0.0);
    T gap_sq = a - T(2.0) * root_b;
    // At s1 = s2 exactly the square root has no derivative: keep it a hair above zero.
    const T floor = T(1e-20) * a;
    if (gap_sq < floor) gap_sq = floor;
    const T gap = sqrt(gap_sq);
    const T sum = sqrt(a + T(2.0) * root_b);
    const T s2 = T(0.5) * (sum - gap);
    return gap / s2;
  }
};

struct GapResidual {
  GapResidual(const Eigen::Matrix3d& F, double sqrt_weight) : F_(F), sqrt_weight_(sqrt_weight) {}
  template <typename T>
  bool operator()(const T* k, T* residual) const {
    residual[0] = T(sqrt_weight_) * SingularValueGap::relativeGap(F_, k);
    return true;
  }
  Eigen::Matrix3d F_;
  double sqrt_weight_;
};

/// The closest rank-2 matrix with unit norm (E must have a zero singular value for the closed form above).
Eigen::Matrix3d rankTwoUnitNorm(const Eigen::Matrix3d& F) {
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(F, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Vector3d s = svd.singularValues();
  s(2) = 0.0;
  Eigen::Matrix3d r = svd.matrixU() * s.asDiagonal() * svd.matrixV().transpose();
  return r / r.norm();
}

}  // namespace

bool isAdmissible(const Intrinsics& k, const cv::Size& size) {
  const double w = size.width, h = size.height;
  return std::isfinite(k.alpha_u) && std::isfinite(k.alpha_v) && std::isfinite(k.u0) && std::isfinite(k.v0) &&
         k.alpha_u > 0.05 * w && k.alpha_v > 0.05 * w && k.alpha_u < 50.0 * w && k.alpha_v < 50.0 * w &&
         k.alpha_u / k.alpha_v > 0.5 && k.alpha_u / k.alpha_v < 2.0 && k.u0 >= 0.0 && k.u0 <= w - 1.0 && k.v0 >= 0.0 &&
         k.v0 <= h - 1.0;
}

std::string MendoncaCipollaConfig::validate() const {
  std::ostringstream err;
  if (!(initial_hfov_deg > 1.0 && initial_hfov_deg < 179.0))
    err << "initial_hfov_deg = " << initial_hfov_deg << " out of range (1, 179); ";
  if (focal_start_factors.empty()) err << "focal_start_factors is empty (at least one factor > 0); ";
  for (double f : focal_start_factors)
    if (!(f > 0.0 && f < 100.0)) {
      err << "focal_start_factors holds " << f << ", out of range (0, 100); ";
      break;
    }
  if (max_iterations < 1) err << "max_iterations = " << max_iterations << " must be >= 1; ";
  std::string s = err.str();
  if (!s.empty()) s.resize(s.size() - 2);
  return s;
}

MendoncaCipollaCalibrator::MendoncaCipollaCalibrator(const MendoncaCipollaConfig& config) : config_(config) {
  const std::string problem = config_.validate();
  if (!problem.empty()) throw std::invalid_argument("mendonca_cipolla: " + problem);
}

double MendoncaCipollaCalibrator::cost(const Intrinsics& k, const std::vector<PairFundamental>& pairs) {
  const double params[4] = {k.alpha_u, k.alpha_v, k.u0, k.v0};
  double c = 0.0;
  for (const PairFundamental& p : pairs) {
    const double r = SingularValueGap::relativeGap(rankTwoUnitNorm(p.F), params);
    c += p.weight * r * r;
  }
  return c;
}

IntrinsicsEstimate MendoncaCipollaCalibrator::calibrate(const std::vector<PairFundamental>& pairs,
                                                        const cv::Size& image_size) const {
  if (image_size.width < 2 || image_size.height < 2)
    throw std::invalid_argument("mendonca_cipolla: image size " + std::to_string(image_size.width) + "x" +
                                std::to_string(image_size.height) + " is empty");
  if (pairs.size() < 3)
    throw std::invalid_argument("mendonca_cipolla: " + std::to_string(pairs.size()) +
                                " image pairs, at least 3 needed (4 unknowns, 2 constraints per pair)");
  double weight_sum = 0.0;
  for (const PairFundamental& p : pairs) {
    if (!p.F.allFinite() || p.F.norm() == 0.0)
      throw std::invalid_argument("mendonca_cipolla: pair (" + std::to_string(p.key_a) + ", " +
                                  std::to_string(p.key_b) + ") has a zero or non-finite F");
    if (!(p.weight > 0.0) || !std::isfinite(p.weight))
      throw std::invalid_argument("mendonca_cipolla: pair (" + std::to_string(p.key_a) + ", " +
                                  std::to_string(p.key_b) + ") has weight " + std::to_string(p.weight) +
                                  ", must be finite and > 0");
    weight_sum += p.weight;
  }
  std::vector<PairFundamental> normalized = pairs;
  for (PairFundamental& p : normalized) {
    p.F = rankTwoUnitNorm(p.F);
    p.weight *= static_cast<double>(pairs.size()) / weight_sum;
  }

  const double nominal_focal = 0.5 * image_size.width / std::tan(0.5 * config_.initial_hfov_deg * M_PI / 180.0);
  const double centre_u = 0.5 * (image_size.width - 1), centre_v = 0.5 * (image_size.height - 1);
  IntrinsicsEstimate best;
  best.cost = std::numeric_limits<double>::infinity();
  double best_params[4] = {0, 0, 0, 0};
  for (double factor : config_.focal_start_factors) {
    double k[4] = {factor * nominal_focal, factor * nominal_focal, centre_u, centre_v};
    ceres::Problem problem;
    for (const PairFundamental& p : normalized) {
      problem.AddResidualBlock(
          new ceres::AutoDiffCostFunction<GapResidual, 1, 4>(new GapResidual(p.F, std::sqrt(p.weight))), nullptr, k);
    }
    ceres::Solver::Options options;
    options.linear_solver_type = ceres::DENSE_QR;
    options.max_num_iterations = config_.max_iterations;
    options.function_tolerance = 1e-14;
    options.parameter_tolerance = 1e-12;
    options.gradient_tolerance = 1e-16;
    options.logging_type = ceres::SILENT;
    ceres::Solver::Summary summary;
    ceres::Solve(options, &problem, &summary);
    ++best.starts;
    if (!summary.IsSolutionUsable() || !isAdmissible(Intrinsics{k[0], k[1], k[2], k[3]}, image_size)) continue;
    ++best.starts_converged;
    const double c = 2.0 * summary.final_cost;
    if (c < best.cost) {
      best.cost = c;
      for (int i = 0; i < 4; ++i) best_params[i] = k[i];
    }
  }
  if (!std::isfinite(best.cost)) {
    std::ostringstream msg;
    msg << "no start of the Mendonca-Cipolla minimisation (" << best.starts << " focal lengths around " << nominal_focal
        << " px) converged to an admissible camera (positive focal lengths, aspect ratio in [0.5, 2], "
        << "principal point in the image): the fundamental matrices do not constrain the intrinsics";
    throw std::runtime_error(msg.str());
  }
  const int starts = best.starts, converged = best.starts_converged;
  const double final_cost = best.cost;
  best = IntrinsicsEstimate();
  best.starts = starts;
  best.starts_converged = converged;
  best.cost = final_cost;
  best.pairs = static_cast<int>(pairs.size());
  best.value.alpha_u = best_params[0];
  best.value.alpha_v = best_params[1];
  best.value.u0 = best_params[2];
  best.value.v0 = best_params[3];
  best.residual_rms = std::sqrt(final_cost / best.pairs);

  // Uncertainty: (J^T J)^-1 at the solution, scaled by the variance of the residuals.
  const double inf = std::numeric_limits<double>::infinity();
  best.sigma = Intrinsics{inf, inf, inf, inf};
  best.covariance.setConstant(inf);
  const int dof = best.pairs - 4;
  if (dof > 0) {
    ceres::Problem problem;
    for (const PairFundamental& p : normalized) {
      problem.AddResidualBlock(
          new ceres::AutoDiffCostFunction<GapResidual, 1, 4>(new GapResidual(p.F, std::sqrt(p.weight))), nullptr,
          best_params);
    }
    ceres::Covariance::Options options;
    options.algorithm_type = ceres::DENSE_SVD;
    ceres::Covariance covariance(options);
    std::vector<std::pair<const double*, const double*>> blocks = {{best_params, best_params}};
    if (covariance.Compute(blocks, &problem)) {
      double c[16];
      covariance.GetCovarianceBlock(best_params, best_params, c);
      const double variance = final_cost / dof;
      best.covariance = Eigen::Map<Eigen::Matrix<double, 4, 4, Eigen::RowMajor>>(c) * variance;
      best.covariance_ok = best.covariance.allFinite();
      if (best.covariance_ok) {
        best.sigma.alpha_u = std::sqrt(best.covariance(0, 0));
        best.sigma.alpha_v = std::sqrt(best.covariance(1, 1));
        best.sigma.u0 = std::sqrt(best.covariance(2, 2));
        best.sigma.v0 = std::sqrt(best.covariance(3, 3));
      }
    }
  }
  return best;
}

}  // namespace selfcal
}  // namespace exocet_mosaic
