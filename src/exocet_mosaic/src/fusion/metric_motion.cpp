#include "exocet_mosaic/fusion/metric_motion.h"

#include <cmath>
#include <sstream>
#include <stdexcept>

#include <Eigen/Dense>

namespace exocet_mosaic {
namespace fusion {
namespace {

/// Camera centre displacement (x, y, z) from the previous camera to the current one, or an error.
struct Displacement {
  bool valid = false;
  std::string error;
  Eigen::Vector3d delta_m = Eigen::Vector3d::Zero();
};

struct PairGeometry {
  Eigen::Matrix3d K_inverse;
  Eigen::Vector2d principal_point_px;
  Eigen::Matrix3d world_from_camera_prev;
  Eigen::Matrix3d world_from_camera_cur;
};

Displacement displacementFor(registration::MotionModel model, const Eigen::VectorXd& parameters,
                             const Eigen::Vector2d& centre_px, const PairGeometry& g, double height_prev_m,
                             double height_cur_m) {
  Displacement out;
  const Eigen::Matrix3d h = registration::pixelMatrix(model, parameters, centre_px);
  Eigen::FullPivLU<Eigen::Matrix3d> lu(h);
  if (!lu.isInvertible() || !h.allFinite()) {
    out.error = "the motion's pixel matrix is singular or not finite";
    return out;
  }
  // The previous image's pixel that the motion sends to the current principal point.
  const Eigen::Vector3d back = lu.solve(Eigen::Vector3d(g.principal_point_px.x(), g.principal_point_px.y(), 1.0));
  if (!(std::abs(back.z()) > 1e-12)) {
    out.error = "the inverse motion sends the principal point to infinity";
    return out;
  }
  const Eigen::Vector3d pixel_prev(back.x() / back.z(), back.y() / back.z(), 1.0);
  const Eigen::Vector3d ray_prev = g.world_from_camera_prev * (g.K_inverse * pixel_prev);
  if (!(ray_prev.z() < -1e-9 * ray_prev.norm())) {
    out.error = "the previous camera's ray through the matched pixel misses the seabed (points at or above the horizon)";
    return out;
  }
  const Eigen::Vector3d ground_from_prev = ray_prev * (height_prev_m / -ray_prev.z());
  const Eigen::Vector3d principal_ray = g.world_from_camera_cur *
                                        (g.K_inverse * Eigen::Vector3d(g.principal_point_px.x(),
                                                                       g.principal_point_px.y(), 1.0));
  if (!(principal_ray.z() < -1e-9 * principal_ray.norm())) {
    out.error = "the current camera's optical axis misses the seabed (points at or above the horizon)";
    return out;
  }
  out.delta_m = ground_from_prev - principal_ray * (height_cur_m / -principal_ray.z());
  out.valid = out.delta_m.allFinite();
  if (!out.valid) out.error = "the displacement is not finite";
  return out;
}

std::string checkView(const ViewGeometry& v, const char* which) {
  std::ostringstream err;
  if (!v.world_from_base.coeffs().allFinite() || !(v.world_from_base.norm() > 1e-6))
    err << which << ".world_from_base is not a finite non-zero quaternion; ";
  if (!std::isfinite(v.camera_height_m) || !(v.camera_height_m > 0.0))
    err << which << ".camera_height_m = " << v.camera_height_m << " must be finite and > 0 m; ";
  if (!std::isfinite(v.camera_height_sigma_m) || v.camera_height_sigma_m < 0.0)
    err << which << ".camera_height_sigma_m = " << v.camera_height_sigma_m << " must be finite and >= 0 m; ";
  return err.str();
}

}  // namespace

double pixelSize_m(double camera_height_m, double alpha_px) {
  if (!std::isfinite(camera_height_m) || !(camera_height_m > 0.0))
    throw std::invalid_argument("camera_height_m = " + std::to_string(camera_height_m) + " must be finite and > 0 m");
  if (!std::isfinite(alpha_px) || !(alpha_px > 0.0))
    throw std::invalid_argument("alpha_px = " + std::to_string(alpha_px) + " must be finite and > 0 pixels");
  return camera_height_m / alpha_px;
}

double cameraHeightFromAltimeter_m(double range_m, const Eigen::Quaterniond& world_from_base,
                                   const Eigen::Vector3d& altimeter_in_base_m, const Eigen::Vector3d& camera_in_base_m) {
  if (!std::isfinite(range_m) || !(range_m > 0.0))
    throw std::invalid_argument("altimeter range_m = " + std::to_string(range_m) + " must be finite and > 0 m");
  if (!world_from_base.coeffs().allFinite() || !(world_from_base.norm() > 1e-6))
    throw std::invalid_argument("world_from_base is not a finite non-zero quaternion");
  if (!altimeter_in_base_m.allFinite() || !camera_in_base_m.allFinite())
    throw std::invalid_argument("altimeter_in_base_m and camera_in_base_m must be finite");
  const Eigen::Matrix3d r = world_from_base.normalized().toRotationMatrix();
  const double beam_down = r(2, 2);  // -(world z of the beam direction -body z)
  if (!(beam_down > 1e-3))
    throw std::invalid_argument("the altimeter's beam (body -z) does not point downwards: attitude too tilted");
  // Seabed height relative to base_link's origin, then the camera's height above it.
  const double seabed_z = (r * altimeter_in_base_m).z() - range_m * beam_down;
  const double height = (r * camera_in_base_m).z() - seabed_z;
  if (!(height > 0.0))
    throw std::invalid_argument("camera height " + std::to_string(height) +
                                " m above the seabed is not > 0: altimeter range too short for the lever arms");
  return height;
}

Eigen::Vector3d cameraPosition(const Eigen::Vector3d& base_position_m, const Eigen::Quaterniond& world_from_base,
                               const Eigen::Isometry3d& base_from_camera) {
  return base_position_m + world_from_base.normalized() * base_from_camera.translation();
}

MetricMotion toMetricMotion(registration::MotionModel model, const Eigen::VectorXd& parameters,
                            const Eigen::MatrixXd& parameter_covariance, const Eigen::Vector2d& centre_px,
                            const CameraMount& mount, const ViewGeometry& previous, const ViewGeometry& current) {
  MetricMotion out;
  std::ostringstream err;
  const int n = registration::parameterCount(model);
  if (parameters.size() != n)
    err << "parameters has " << parameters.size() << " values, the " << registration::toString(model)
        << " model needs " << n << "; ";
  else if (!parameters.allFinite())
    err << "parameters are not finite; ";
  if (parameter_covariance.rows() != n || parameter_covariance.cols() != n)
    err << "parameter_covariance is " << parameter_covariance.rows() << "x" << parameter_covariance.cols()
        << ", must be " << n << "x" << n << "; ";
  else if (!parameter_covariance.allFinite())
    err << "parameter_covariance is not finite; ";
  else if (!(parameter_covariance - parameter_covariance.transpose()).isZero(
               1e-9 * (1.0 + parameter_covariance.cwiseAbs().maxCoeff())) ||
           (parameter_covariance.diagonal().array() < 0.0).any())
    err << "parameter_covariance is not symmetric with a non-negative diagonal; ";
  if (!centre_px.allFinite()) err << "centre_px is not finite; ";
  const Eigen::Matrix3d& k = mount.camera_matrix;
  if (!k.allFinite() || !(k(0, 0) > 0.0) || !(k(1, 1) > 0.0) || k(2, 0) != 0.0 || k(2, 1) != 0.0 || k(2, 2) != 1.0 ||
      k(1, 0) != 0.0)
    err << "mount.camera_matrix must be finite [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0; ";
  if (!mount.base_from_camera.matrix().allFinite()) err << "mount.base_from_camera is not finite; ";
  err << checkView(previous, "previous") << checkView(current, "current");
  std::string problems = err.str();
  if (!problems.empty()) {
    problems.resize(problems.size() - 2);
    out.error = problems;
    return out;
  }

  PairGeometry g;
  g.K_inverse = k.inverse();
  g.principal_point_px = Eigen::Vector2d(k(0, 2), k(1, 2));
  const Eigen::Matrix3d base_from_camera = mount.base_from_camera.linear();
  g.world_from_camera_prev = previous.world_from_base.normalized().toRotationMatrix() * base_from_camera;
  g.world_from_camera_cur = current.world_from_base.normalized().toRotationMatrix() * base_from_camera;

  const double h_prev = previous.camera_height_m, h_cur = current.camera_height_m;
  const Displacement nominal = displacementFor(model, parameters, centre_px, g, h_prev, h_cur);
  if (!nominal.valid) {
    out.error = nominal.error;
    return out;
  }

  // Covariance: central differences, with steps a small fraction of each input's own uncertainty.
  Eigen::Matrix2d covariance = Eigen::Matrix2d::Zero();
  Eigen::MatrixXd jacobian = Eigen::MatrixXd::Zero(2, n);
  for (int i = 0; i < n; ++i) {
    const double sigma = std::sqrt(parameter_covariance(i, i));
    if (!(sigma > 0.0)) continue;
    const double step = 1e-3 * sigma;
    Eigen::VectorXd plus = parameters, minus = parameters;
    plus[i] += step;
    minus[i] -= step;
    const Displacement dp = displacementFor(model, plus, centre_px, g, h_prev, h_cur);
    const Displacement dm = displacementFor(model, minus, centre_px, g, h_prev, h_cur);
    if (!dp.valid || !dm.valid) {
      out.error = "the displacement is not differentiable at the estimate (" + (dp.valid ? dm.error : dp.error) + ")";
      return out;
    }
    jacobian.col(i) = (dp.delta_m - dm.delta_m).head<2>() / (2.0 * step);
  }
  covariance = jacobian * parameter_covariance * jacobian.transpose();
  const double sigmas[2] = {previous.camera_height_sigma_m, current.camera_height_sigma_m};
  for (int which = 0; which < 2; ++which) {
    if (!(sigmas[which] > 0.0)) continue;
    const double step = 1e-3 * std::min(sigmas[which], 0.5 * (which == 0 ? h_prev : h_cur));
    const double hp_plus = which == 0 ? h_prev + step : h_prev, hc_plus = which == 1 ? h_cur + step : h_cur;
    const double hp_minus = which == 0 ? h_prev - step : h_prev, hc_minus = which == 1 ? h_cur - step : h_cur;
    const Displacement dp = displacementFor(model, parameters, centre_px, g, hp_plus, hc_plus);
    const Displacement dm = displacementFor(model, parameters, centre_px, g, hp_minus, hc_minus);
    const Eigen::Vector2d column = (dp.delta_m - dm.delta_m).head<2>() / (2.0 * step);
    covariance += sigmas[which] * sigmas[which] * column * column.transpose();
  }
  out.valid = true;
  out.camera_displacement_en_m = nominal.delta_m.head<2>();
  out.covariance_m2 = 0.5 * (covariance + covariance.transpose());
  out.height_change_m = nominal.delta_m.z();
  out.ground_sample_distance_m = h_prev / std::sqrt(k(0, 0) * k(1, 1));
  return out;
}

}  // namespace fusion
}  // namespace exocet_mosaic
