#include "exocet_mosaic/selfcal/planar_self_calibrator.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <queue>
#include <sstream>
#include <stdexcept>

#include <ceres/ceres.h>
#include <Eigen/Dense>

namespace exocet_mosaic {
namespace selfcal {

namespace {

/**
 * One key frame's circular point z = H (x_r + i x_i), x_0 = (1, c0 + i c1, c2 + i c3), must lie on omega:
 * with y = K^-1 z, z^T omega z = y^T y = (y_r.y_r - y_i.y_i) + 2 i y_r.y_i. Divided by y^H y = |y_r|^2 + |y_i|^2
 * (the residual is then free of the scale of z and bounded by 1).
 */
struct CircularPointResidual {
  CircularPointResidual(const Eigen::Matrix3d& H, double sqrt_weight) : H_(H), sqrt_weight_(sqrt_weight) {}
  template <typename T>
  bool operator()(const T* k, const T* c, T* residual) const {
    const Eigen::Matrix<T, 3, 1> xr(T(1.0), c[0], c[2]);
    const Eigen::Matrix<T, 3, 1> xi(T(0.0), c[1], c[3]);
    const Eigen::Matrix<T, 3, 3> H = H_.cast<T>();
    const Eigen::Matrix<T, 3, 1> zr = H * xr, zi = H * xi;
    // K^-1 z for K = [k0 0 k2; 0 k1 k3; 0 0 1].
    const Eigen::Matrix<T, 3, 1> yr((zr(0) - k[2] * zr(2)) / k[0], (zr(1) - k[3] * zr(2)) / k[1], zr(2));
    const Eigen::Matrix<T, 3, 1> yi((zi(0) - k[2] * zi(2)) / k[0], (zi(1) - k[3] * zi(2)) / k[1], zi(2));
    const T rr = yr.dot(yr), ii = yi.dot(yi), ri = yr.dot(yi);
    const T scale = T(sqrt_weight_) / (rr + ii);
    residual[0] = scale * (rr - ii);
    residual[1] = scale * T(2.0) * ri;
    return true;
  }
  Eigen::Matrix3d H_;
  double sqrt_weight_;
};

}  // namespace

std::string PlanarCalibrationConfig::validate() const {
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
  if (min_key_frames < 4) err << "min_key_frames = " << min_key_frames << " must be >= 4; ";
  std::string s = err.str();
  if (!s.empty()) s.resize(s.size() - 2);
  return s;
}

PlanarSelfCalibrator::PlanarSelfCalibrator(const PlanarCalibrationConfig& config) : config_(config) {
  const std::string problem = config_.validate();
  if (!problem.empty()) throw std::invalid_argument("planar_calibration: " + problem);
}

IntrinsicsEstimate PlanarSelfCalibrator::calibrate(const std::vector<PairHomography>& pairs,
                                                   const cv::Size& image_size) const {
  if (image_size.width < 2 || image_size.height < 2)
    throw std::invalid_argument("planar_calibration: image size " + std::to_string(image_size.width) + "x" +
                                std::to_string(image_size.height) + " is empty");
  for (const PairHomography& p : pairs)
    if (!p.H.allFinite() || std::abs(p.H.determinant()) < 1e-300 || !(p.weight > 0.0))
      throw std::invalid_argument("planar_calibration: pair (" + std::to_string(p.key_a) + ", " +
                                  std::to_string(p.key_b) + ") has a singular or non-finite H or a weight <= 0");

  // Spanning tree from the lowest key frame, heaviest pairs first: H_k0 maps the reference to key frame k.
  std::map<int, std::vector<size_t>> edges;
  for (size_t i = 0; i < pairs.size(); ++i) {
    edges[pairs[i].key_a].push_back(i);
    edges[pairs[i].key_b].push_back(i);
  }
  std::map<int, Eigen::Matrix3d> from_reference;
  if (!edges.empty()) {
    const int reference = edges.begin()->first;
    from_reference[reference] = Eigen::Matrix3d::Identity();
    std::queue<int> queue;
    queue.push(reference);
    while (!queue.empty()) {
      const int u = queue.front();
      queue.pop();
      std::vector<size_t> out = edges[u];
      std::sort(out.begin(), out.end(), [&](size_t x, size_t y) { return pairs[x].weight > pairs[y].weight; });
      for (size_t e : out) {
        const PairHomography& p = pairs[e];
        const int v = p.key_a == u ? p.key_b : p.key_a;
        if (from_reference.count(v)) continue;
        const Eigen::Matrix3d step = p.key_a == u ? p.H : Eigen::Matrix3d(p.H.inverse());
        Eigen::Matrix3d h = step * from_reference[u];
        from_reference[v] = h / h.norm();
        queue.push(v);
      }
    }
  }
  const int linked = static_cast<int>(from_reference.size());
  if (linked < config_.min_key_frames)
    throw std::runtime_error("planar self-calibration: only " + std::to_string(linked) +
                             " key frames are linked by homographies, at least " +
                             std::to_string(config_.min_key_frames) + " needed");

  // Coordinates normalised by the nominal camera: the unknowns are then all of order 1.
  const double f0 = 0.5 * image_size.width / std::tan(0.5 * config_.initial_hfov_deg * M_PI / 180.0);
  const double u_c = 0.5 * (image_size.width - 1), v_c = 0.5 * (image_size.height - 1);
  Eigen::Matrix3d N;
  N << 1.0 / f0, 0.0, -u_c / f0, 0.0, 1.0 / f0, -v_c / f0, 0.0, 0.0, 1.0;
  const Eigen::Matrix3d N_inverse = N.inverse();
  std::vector<Eigen::Matrix3d> normalized;
  for (const auto& [key, h] : from_reference) {
    const Eigen::Matrix3d hn = N * h * N_inverse;
    normalized.push_back(hn / hn.norm());
  }

  auto build = [&](ceres::Problem* problem, double* k, double* c) {
    for (const Eigen::Matrix3d& h : normalized)
      problem->AddResidualBlock(
          new ceres::AutoDiffCostFunction<CircularPointResidual, 2, 4, 4>(new CircularPointResidual(h, 1.0)), nullptr,
          k, c);
  };
  IntrinsicsEstimate best;
  best.cost = std::numeric_limits<double>::infinity();
  double best_k[4] = {0, 0, 0, 0}, best_c[4] = {0, 0, 0, 0};
  for (double factor : config_.focal_start_factors) {
    // The reference view is close to fronto-parallel: its circular points are near K (1, +-i, 0) ~ (1, i, 0).
    double k[4] = {factor, factor, 0.0, 0.0};
    double c[4] = {0.0, 1.0, 0.0, 0.0};
    ceres::Problem problem;
    build(&problem, k, c);
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
    const Intrinsics pixels{f0 * k[0], f0 * k[1], u_c + f0 * k[2], v_c + f0 * k[3]};
    if (!summary.IsSolutionUsable() || !isAdmissible(pixels, image_size)) continue;
    ++best.starts_converged;
    const double cost = 2.0 * summary.final_cost;
    if (cost < best.cost) {
      best.cost = cost;
      std::copy(k, k + 4, best_k);
      std::copy(c, c + 4, best_c);
    }
  }
  if (!std::isfinite(best.cost)) {
    std::ostringstream msg;
    msg << "no start of the planar self-calibration (" << best.starts << " focal lengths around " << f0
        << " px) converged to an admissible camera: the plane was probably seen under too little tilt (roll, pitch)";
    throw std::runtime_error(msg.str());
  }
  best.pairs = static_cast<int>(pairs.size());
  best.value = Intrinsics{f0 * best_k[0], f0 * best_k[1], u_c + f0 * best_k[2], v_c + f0 * best_k[3]};
  const int residuals = 2 * linked;
  best.residual_rms = std::sqrt(best.cost / residuals);

  const double inf = std::numeric_limits<double>::infinity();
  best.sigma = Intrinsics{inf, inf, inf, inf};
  best.covariance.setConstant(inf);
  const int dof = residuals - 8;
  if (dof > 0) {
    ceres::Problem problem;
    build(&problem, best_k, best_c);
    ceres::Covariance::Options options;
    options.algorithm_type = ceres::DENSE_SVD;
    ceres::Covariance covariance(options);
    std::vector<std::pair<const double*, const double*>> blocks = {{best_k, best_k}};
    if (covariance.Compute(blocks, &problem)) {
      double c[16];
      covariance.GetCovarianceBlock(best_k, best_k, c);
      // Back to pixels: every parameter is f0 times its normalised value (plus a constant).
      best.covariance = Eigen::Map<Eigen::Matrix<double, 4, 4, Eigen::RowMajor>>(c) * (best.cost / dof) * f0 * f0;
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
