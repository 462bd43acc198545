#include "exocet_stereo/geometry/bundle_adjustment.h"

#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <sstream>
#include <stdexcept>

#include <ceres/ceres.h>
#include <ceres/rotation.h>

namespace exocet_stereo {
namespace geometry {

namespace {

/// Pinhole projection of a camera-frame point with intrinsics (fx, fy, cx, cy) and a constant skew.
template <typename T>
void projectCamera(const T* Xc, const T* intrinsics, double skew, T* pixel) {
  const T x = Xc[0] / Xc[2], y = Xc[1] / Xc[2];
  pixel[0] = intrinsics[0] * x + T(skew) * y + intrinsics[2];
  pixel[1] = intrinsics[1] * y + intrinsics[3];
}

/// A camera with its own pose: rotation vector r (world to camera) and centre c0 + d, where c0 is the gauge camera's
/// camera's centre (held constant), so that the first baseline is the vector d of the second camera.
struct PoseResidual {
  PoseResidual(const Eigen::Vector2d& observed, const Eigen::Vector3d& c0, double skew)
      : observed_(observed), c0_(c0), skew_(skew) {}

  template <typename T>
  bool operator()(const T* r, const T* d, const T* X, const T* intrinsics, T* residual) const {
    const T relative[3] = {X[0] - T(c0_.x()) - d[0], X[1] - T(c0_.y()) - d[1], X[2] - T(c0_.z()) - d[2]};
    T Xc[3];
    ceres::AngleAxisRotatePoint(r, relative, Xc);
    T pixel[2];
    projectCamera(Xc, intrinsics, skew_, pixel);
    residual[0] = pixel[0] - T(observed_.x());
    residual[1] = pixel[1] - T(observed_.y());
    return true;
  }

  Eigen::Vector2d observed_;
  Eigen::Vector3d c0_;
  double skew_;
};

/// A right camera of a rig: the station's left pose followed by the shared right-from-left transform.
struct RigResidual {
  RigResidual(const Eigen::Vector2d& observed, const Eigen::Vector3d& c0, double skew)
      : observed_(observed), c0_(c0), skew_(skew) {}

  template <typename T>
  bool operator()(const T* r_left, const T* d_left, const T* r_rig, const T* t_rig, const T* X, const T* intrinsics,
                  T* residual) const {
    const T relative[3] = {X[0] - T(c0_.x()) - d_left[0], X[1] - T(c0_.y()) - d_left[1], X[2] - T(c0_.z()) - d_left[2]};
    T X_left[3], X_right[3];
    ceres::AngleAxisRotatePoint(r_left, relative, X_left);
    ceres::AngleAxisRotatePoint(r_rig, X_left, X_right);
    for (int k = 0; k < 3; ++k) X_right[k] += t_rig[k];
    T pixel[2];
    projectCamera(X_right, intrinsics, skew_, pixel);
    residual[0] = pixel[0] - T(observed_.x());
    residual[1] = pixel[1] - T(observed_.y());
    return true;
  }

  Eigen::Vector2d observed_;
  Eigen::Vector3d c0_;
  double skew_;
};

Eigen::Vector3d angleAxis(const Eigen::Matrix3d& R) {
  Eigen::Vector3d r;
  ceres::RotationMatrixToAngleAxis(R.data(), r.data());  // both column-major
  return r;
}

Eigen::Matrix3d rotation(const Eigen::Vector3d& r) {
  Eigen::Matrix3d R;
  ceres::AngleAxisToRotationMatrix(r.data(), R.data());
  return R;
}

double rms(const std::vector<double>& errors) {
  if (errors.empty()) return 0.0;
  double sum = 0.0;
  for (double e : errors) sum += e * e;
  return std::sqrt(sum / errors.size());
}

}  // namespace

std::string BundleAdjustmentConfig::validate() const {
  std::ostringstream errors;
  auto check = [&errors](bool ok, const char* field, const char* range) {
    if (ok) return;
    if (errors.tellp() > 0) errors << "; ";
    errors << field << " must be in " << range;
  };
  check(loss_scale_px > 0.0 && loss_scale_px <= 100.0, "loss_scale_px", "(0, 100]");
  check(max_iterations >= 1 && max_iterations <= 1000, "max_iterations", "[1, 1000]");
  check(threads >= 1 && threads <= 16, "threads", "[1, 16]");
  return errors.str();
}

std::vector<double> reprojectionErrors_px(const BaProblem& problem) {
  std::vector<double> errors;
  errors.reserve(problem.observations.size());
  for (const BaObservation& o : problem.observations) {
    const PinholeView& camera = problem.cameras.at(o.camera);
    const Eigen::Vector3d& X = problem.points.at(o.point);
    errors.push_back(camera.depth(X) > 0.0 ? (camera.project(X) - o.pixel).norm()
                                           : std::numeric_limits<double>::infinity());
  }
  return errors;
}

BaReport bundleAdjust(BaProblem& problem, const BundleAdjustmentConfig& config) {
  const std::string error = config.validate();
  if (!error.empty()) throw std::invalid_argument("BundleAdjustmentConfig: " + error);
  const int n_cameras = static_cast<int>(problem.cameras.size());
  if (n_cameras < 2) throw std::invalid_argument("bundleAdjust: at least 2 cameras are needed");
  if (config.shared_rig && n_cameras % 2 != 0)
    throw std::invalid_argument(
        "bundleAdjust: rig mode needs an even number of cameras (left, right per station), got " +
        std::to_string(n_cameras));
  for (const BaObservation& o : problem.observations)
    if (o.camera < 0 || o.camera >= n_cameras || o.point < 0 || o.point >= static_cast<int>(problem.points.size()))
      throw std::invalid_argument("bundleAdjust: an observation references camera " + std::to_string(o.camera) +
                                  " of [0, " + std::to_string(n_cameras) + ") and point " + std::to_string(o.point) +
                                  " of [0, " + std::to_string(problem.points.size()) + ")");

  BaReport report;
  report.initial_rms_px = rms(reprojectionErrors_px(problem));

  // Parameter blocks. In rig mode only left cameras (even indices) own a pose.
  // Gauge: the first camera (left camera in rig mode) that is observed is held, and the scale by the next observed
  // camera's distance to it; an unobserved camera cannot anchor anything.
  std::vector<int> observed(n_cameras, 0);
  for (const BaObservation& o : problem.observations)
    ++observed[config.shared_rig ? o.camera - o.camera % 2 : o.camera];
  const int step = config.shared_rig ? 2 : 1;
  int gauge = -1, scale_camera = -1;
  for (int i = 0; i < n_cameras; i += step) {
    if (observed[i] == 0) continue;
    if (gauge < 0)
      gauge = i;
    else if (scale_camera < 0)
      scale_camera = i;
  }
  if (gauge < 0) {
    report.message = "no observations";
    return report;
  }
  report.gauge_camera = gauge;
  const Eigen::Vector3d c0 = problem.cameras[gauge].centre();
  std::vector<Eigen::Vector3d> r(n_cameras), d(n_cameras);
  for (int i = 0; i < n_cameras; ++i) {
    r[i] = angleAxis(problem.cameras[i].R);
    d[i] = problem.cameras[i].centre() - c0;
  }
  Eigen::Vector3d r_rig = Eigen::Vector3d::Zero(), t_rig = Eigen::Vector3d::Zero();
  if (config.shared_rig) {
    const Eigen::Matrix3d R_rl = problem.cameras[1].R * problem.cameras[0].R.transpose();
    t_rig = problem.cameras[1].t - R_rl * problem.cameras[0].t;
    r_rig = angleAxis(R_rl);
  }
  // Intrinsics: one block per distinct K.
  std::vector<int> intrinsics_of(n_cameras);
  std::vector<Eigen::Vector4d> intrinsics;
  std::vector<Eigen::Matrix3d> distinct_K;
  for (int i = 0; i < n_cameras; ++i) {
    const Eigen::Matrix3d& K = problem.cameras[i].K;
    int found = -1;
    for (size_t k = 0; k < distinct_K.size() && found < 0; ++k)
      if (distinct_K[k] == K) found = static_cast<int>(k);
    if (found < 0) {
      found = static_cast<int>(distinct_K.size());
      distinct_K.push_back(K);
      intrinsics.emplace_back(K(0, 0), K(1, 1), K(0, 2), K(1, 2));
    }
    intrinsics_of[i] = found;
  }

  ceres::Problem ceres_problem;
  auto makeLoss = [&config]() -> ceres::LossFunction* {
    switch (config.loss) {
      case RobustLoss::kHuber:
        return new ceres::HuberLoss(config.loss_scale_px);
      case RobustLoss::kCauchy:
        return new ceres::CauchyLoss(config.loss_scale_px);
      default:
        return nullptr;
    }
  };
  std::vector<bool> point_used(problem.points.size(), false);
  for (const BaObservation& o : problem.observations) {
    const int cam = o.camera;
    const double skew = problem.cameras[cam].K(0, 1);
    double* X = problem.points[o.point].data();
    double* intr = intrinsics[intrinsics_of[cam]].data();
    point_used[o.point] = true;
    if (config.shared_rig && cam % 2 == 1) {
      auto* cost =
          new ceres::AutoDiffCostFunction<RigResidual, 2, 3, 3, 3, 3, 3, 4>(new RigResidual(o.pixel, c0, skew));
      ceres_problem.AddResidualBlock(cost, makeLoss(), r[cam - 1].data(), d[cam - 1].data(), r_rig.data(), t_rig.data(),
                                     X, intr);
    } else {
      auto* cost = new ceres::AutoDiffCostFunction<PoseResidual, 2, 3, 3, 3, 4>(new PoseResidual(o.pixel, c0, skew));
      ceres_problem.AddResidualBlock(cost, makeLoss(), r[cam].data(), d[cam].data(), X, intr);
    }
  }
  if (ceres_problem.NumResidualBlocks() == 0) {
    report.message = "no observations";
    return report;
  }
  // Gauge: the first camera is held; the scale by the first baseline (or the rig's).
  ceres_problem.SetParameterBlockConstant(r[gauge].data());
  ceres_problem.SetParameterBlockConstant(d[gauge].data());
  if (config.shared_rig) {
    if (ceres_problem.HasParameterBlock(r_rig.data())) {
      if (!config.refine_rig) {
        ceres_problem.SetParameterBlockConstant(r_rig.data());
        ceres_problem.SetParameterBlockConstant(t_rig.data());
      } else if (t_rig.norm() > 0.0) {
        ceres_problem.SetManifold(t_rig.data(), new ceres::SphereManifold<3>());
      } else {
        ceres_problem.SetParameterBlockConstant(t_rig.data());
      }
    }
  } else if (config.fix_scale && scale_camera >= 0) {
    report.scale_camera = scale_camera;
    if (d[scale_camera].norm() > 0.0)
      ceres_problem.SetManifold(d[scale_camera].data(), new ceres::SphereManifold<3>());
    else
      ceres_problem.SetParameterBlockConstant(d[scale_camera].data());
  }
  for (auto& block : intrinsics)
    if (ceres_problem.HasParameterBlock(block.data()) && !config.refine_intrinsics)
      ceres_problem.SetParameterBlockConstant(block.data());

  ceres::Solver::Options options;
  options.linear_solver_type = n_cameras <= 64 ? ceres::DENSE_SCHUR : ceres::ITERATIVE_SCHUR;
  if (options.linear_solver_type == ceres::ITERATIVE_SCHUR) options.preconditioner_type = ceres::SCHUR_JACOBI;
  options.max_num_iterations = config.max_iterations;
  options.num_threads = config.threads;
  options.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  ceres::Solve(options, &ceres_problem, &summary);
  report.converged = summary.termination_type == ceres::CONVERGENCE;
  report.iterations = static_cast<int>(summary.iterations.size());
  report.message = summary.BriefReport();

  if (config.compute_covariance) {
    ceres::Covariance::Options cov_options;
    cov_options.num_threads = config.threads;
    ceres::Covariance covariance(cov_options);
    std::vector<std::pair<const double*, const double*>> blocks;
    std::vector<int> free_cameras;
    for (int i = 0; i < n_cameras; ++i) {
      if (config.shared_rig && i % 2 == 1) continue;
      if (!ceres_problem.HasParameterBlock(r[i].data()) || ceres_problem.IsParameterBlockConstant(r[i].data()))
        continue;
      free_cameras.push_back(i);
      blocks.emplace_back(r[i].data(), r[i].data());
      blocks.emplace_back(r[i].data(), d[i].data());
      blocks.emplace_back(d[i].data(), d[i].data());
    }
    report.camera_covariance.assign(n_cameras, Eigen::Matrix<double, 6, 6>::Zero());
    report.covariance_ok = covariance.Compute(blocks, &ceres_problem);
    if (report.covariance_ok) {
      for (int i : free_cameras) {
        Eigen::Matrix<double, 3, 3, Eigen::RowMajor> rr, rd, dd;
        covariance.GetCovarianceBlock(r[i].data(), r[i].data(), rr.data());
        covariance.GetCovarianceBlock(r[i].data(), d[i].data(), rd.data());
        covariance.GetCovarianceBlock(d[i].data(), d[i].data(), dd.data());
        auto& C = report.camera_covariance[i];
        C.topLeftCorner<3, 3>() = rr;
        C.topRightCorner<3, 3>() = rd;
        C.bottomLeftCorner<3, 3>() = rd.transpose();
        C.bottomRightCorner<3, 3>() = dd;
      }
    }
  }

  // Back to (K, R, t).
  const Eigen::Matrix3d R_rig = rotation(r_rig);
  for (int i = 0; i < n_cameras; ++i) {
    PinholeView& camera = problem.cameras[i];
    const Eigen::Vector4d& k = intrinsics[intrinsics_of[i]];
    camera.K(0, 0) = k[0];
    camera.K(1, 1) = k[1];
    camera.K(0, 2) = k[2];
    camera.K(1, 2) = k[3];
    if (config.shared_rig && i % 2 == 1) {
      const PinholeView& left = problem.cameras[i - 1];  // already updated
      camera.R = R_rig * left.R;
      camera.t = R_rig * left.t + t_rig;
    } else {
      camera.R = rotation(r[i]);
      camera.t = -camera.R * (c0 + d[i]);
    }
  }
  report.rig_R = R_rig;
  report.rig_t = t_rig;
  report.final_rms_px = rms(reprojectionErrors_px(problem));
  return report;
}

}  // namespace geometry
}  // namespace exocet_stereo
