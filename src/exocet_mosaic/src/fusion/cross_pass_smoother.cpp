#include "exocet_mosaic/fusion/cross_pass_smoother.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <memory>
#include <sstream>
#include <stdexcept>

#include <ceres/ceres.h>
#include <Eigen/Dense>

namespace exocet_mosaic {
namespace fusion {
namespace {

/// r = W (sum_k c_k p_k - z): a linear residual over 2D position blocks, with its exact Jacobians.
class LinearPositionCost : public ceres::CostFunction {
 public:
  LinearPositionCost(std::vector<double> coefficients, const Eigen::Vector2d& target, const Eigen::Matrix2d& whitening)
      : coefficients_(std::move(coefficients)), target_(target), whitening_(whitening) {
    set_num_residuals(2);
    for (size_t i = 0; i < coefficients_.size(); ++i) mutable_parameter_block_sizes()->push_back(2);
  }
  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override {
    Eigen::Vector2d sum = -target_;
    for (size_t k = 0; k < coefficients_.size(); ++k)
      sum += coefficients_[k] * Eigen::Map<const Eigen::Vector2d>(parameters[k]);
    Eigen::Map<Eigen::Vector2d> r(residuals);
    r = whitening_ * sum;
    if (jacobians) {
      for (size_t k = 0; k < coefficients_.size(); ++k) {
        if (!jacobians[k]) continue;
        Eigen::Map<Eigen::Matrix<double, 2, 2, Eigen::RowMajor>> jacobian(jacobians[k]);
        jacobian = coefficients_[k] * whitening_;
      }
    }
    return true;
  }

 private:
  std::vector<double> coefficients_;
  Eigen::Vector2d target_;
  Eigen::Matrix2d whitening_;
};

/// W with W^T W = covariance^-1 (inverse Cholesky factor); the covariance is made positive definite first.
Eigen::Matrix2d whiteningOf(const Eigen::Matrix2d& covariance) {
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(0.5 * (covariance + covariance.transpose()));
  Eigen::Vector2d values = eig.eigenvalues().cwiseMax(1e-18);
  const Eigen::Matrix2d pd = eig.eigenvectors() * values.asDiagonal() * eig.eigenvectors().transpose();
  const Eigen::Matrix2d L = pd.llt().matrixL();
  return L.inverse();
}

/// The steps around a stamp with their interpolation weights; empty when outside the log.
std::vector<std::pair<int, double>> stepsAt(const std::vector<double>& stamps, double stamp_s) {
  if (stamps.empty() || !(stamp_s >= stamps.front() && stamp_s <= stamps.back())) return {};
  const auto it = std::lower_bound(stamps.begin(), stamps.end(), stamp_s);
  const int j = static_cast<int>(it - stamps.begin());
  if (stamps[j] == stamp_s) return {{j, 1.0}};
  const double w = (stamp_s - stamps[j - 1]) / (stamps[j] - stamps[j - 1]);
  return {{j - 1, 1.0 - w}, {j, w}};
}

}  // namespace

std::string CrossPassSmootherConfig::validate() const {
  std::ostringstream err;
  if (!(odometry_floor_m >= 0.0) || !std::isfinite(odometry_floor_m))
    err << "odometry_floor_m = " << odometry_floor_m << " out of range [0, inf) m; ";
  if (!(absolute_loss_scale > 0.0)) err << "absolute_loss_scale = " << absolute_loss_scale << " out of range (0, inf); ";
  if (!(relative_loss_scale > 0.0)) err << "relative_loss_scale = " << relative_loss_scale << " out of range (0, inf); ";
  if (max_iterations < 1) err << "max_iterations = " << max_iterations << " out of range [1, inf); ";
  if (threads < 1) err << "threads = " << threads << " out of range [1, inf); ";
  std::string s = err.str();
  if (!s.empty()) s.resize(s.size() - 2);
  return s;
}

CrossPassResult smoothWithCrossPassConstraints(const FilterLog& log, const std::vector<FilterState>& smoothed,
                                               const std::vector<AbsoluteConstraint>& absolute,
                                               const std::vector<RelativeConstraint>& relative,
                                               const CrossPassSmootherConfig& config) {
  const std::string problem = config.validate();
  if (!problem.empty()) throw std::invalid_argument("CrossPassSmootherConfig: " + problem);
  if (smoothed.size() != log.steps.size())
    throw std::invalid_argument("smoothed has " + std::to_string(smoothed.size()) + " states, the log " +
                                std::to_string(log.steps.size()) + " steps: pass smoothRts(log)");
  CrossPassResult result;
  const size_t n = log.steps.size();
  if (n == 0) {
    result.message = "empty log";
    return result;
  }
  std::vector<double> stamps(n);
  result.positions_en_m.resize(n);
  // Work relative to the first position: small numbers for the solver.
  const Eigen::Vector2d origin = smoothed.front().position_en_m;
  for (size_t i = 0; i < n; ++i) {
    stamps[i] = log.steps[i].stamp_s;
    result.positions_en_m[i] = smoothed[i].position_en_m - origin;
  }

  ceres::Problem::Options problem_options;
  problem_options.cost_function_ownership = ceres::TAKE_OWNERSHIP;
  problem_options.loss_function_ownership = ceres::TAKE_OWNERSHIP;
  ceres::Problem ceres_problem(problem_options);
  for (size_t i = 0; i < n; ++i) ceres_problem.AddParameterBlock(result.positions_en_m[i].data(), 2);

  // Odometry: the RTS displacement, weighted by the process noise of the step.
  const double floor2 = config.odometry_floor_m * config.odometry_floor_m;
  for (size_t i = 1; i < n; ++i) {
    const FilterStep& step = log.steps[i];
    if (step.discontinuity) continue;
    const StateMatrix propagated = step.transition * log.steps[i - 1].P_posterior * step.transition.transpose();
    const Eigen::Matrix2d q = (step.P_prior - propagated).block<2, 2>(kEast, kEast) + floor2 * Eigen::Matrix2d::Identity();
    const Eigen::Vector2d delta = smoothed[i].position_en_m - smoothed[i - 1].position_en_m;
    ceres_problem.AddResidualBlock(new LinearPositionCost({-1.0, 1.0}, delta, whiteningOf(q)), nullptr,
                                   result.positions_en_m[i - 1].data(), result.positions_en_m[i].data());
  }
  // Adds sum of weighted blocks = target, merging a block that appears twice.
  const auto add_linear = [&](const std::vector<std::pair<int, double>>& terms, const Eigen::Vector2d& target,
                              const Eigen::Matrix2d& covariance, ceres::LossFunction* loss) {
    std::map<int, double> merged;
    for (const auto& [block, c] : terms) merged[block] += c;
    std::vector<double> coefficients;
    std::vector<double*> blocks;
    for (const auto& [block, c] : merged) {
      if (c == 0.0) continue;
      coefficients.push_back(c);
      blocks.push_back(result.positions_en_m[block].data());
    }
    if (blocks.empty()) {
      delete loss;
      return false;
    }
    ceres_problem.AddResidualBlock(new LinearPositionCost(coefficients, target, whiteningOf(covariance)), loss, blocks);
    return true;
  };
  for (const AbsoluteConstraint& a : absolute) {
    if (!a.position_en_m.allFinite() || !a.covariance_m2.allFinite()) continue;
    const auto terms = stepsAt(stamps, a.stamp_s);
    if (terms.empty()) continue;
    result.absolute_used += add_linear(terms, a.position_en_m - origin, a.covariance_m2,
                                       new ceres::CauchyLoss(config.absolute_loss_scale));
  }
  for (const RelativeConstraint& r : relative) {
    if (!r.delta_en_m.allFinite() || !r.covariance_m2.allFinite()) continue;
    const auto to = stepsAt(stamps, r.to_stamp_s), from = stepsAt(stamps, r.from_stamp_s);
    if (to.empty() || from.empty()) continue;
    std::vector<std::pair<int, double>> terms = to;
    for (const auto& [block, c] : from) terms.emplace_back(block, -c);
    result.relative_used += add_linear(terms, r.delta_en_m, r.covariance_m2,
                                       new ceres::HuberLoss(config.relative_loss_scale));
  }
  if (result.absolute_used == 0) {
    // Nothing anchors the track: hold the first position.
    ceres_problem.SetParameterBlockConstant(result.positions_en_m.front().data());
  }

  ceres::Solver::Options options;
  options.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  options.sparse_linear_algebra_library_type =
      ceres::IsSparseLinearAlgebraLibraryTypeAvailable(ceres::SUITE_SPARSE) ? ceres::SUITE_SPARSE : ceres::EIGEN_SPARSE;
  options.max_num_iterations = config.max_iterations;
  options.num_threads = config.threads;
  options.function_tolerance = 1e-12;
  options.gradient_tolerance = 1e-14;
  options.parameter_tolerance = 1e-12;
  ceres::Solver::Summary summary;
  ceres::Solve(options, &ceres_problem, &summary);
  result.converged = summary.termination_type == ceres::CONVERGENCE;
  result.iterations = static_cast<int>(summary.iterations.size());
  result.initial_cost = summary.initial_cost;
  result.final_cost = summary.final_cost;
  result.message = summary.BriefReport();
  for (Eigen::Vector2d& p : result.positions_en_m) p += origin;
  return result;
}

}  // namespace fusion
}  // namespace exocet_mosaic
