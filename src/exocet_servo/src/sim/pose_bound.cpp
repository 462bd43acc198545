#include "exocet_servo/sim/pose_bound.h"

#include <cmath>

#include <Eigen/Dense>

#include "exocet_servo/control/invariant_interaction.h"

namespace exocet_servo {
namespace sim {

PoseBound poseCramerRao(const std::vector<Eigen::Vector3d>& points_w, const PinholeCamera& camera,
                        const Eigen::Isometry3d& world_T_camera, double noise_px, bool intrinsics_known) {
  // Analytic Jacobian of the pixels: pose through K * L_m (a small pose change is a camera velocity over unit time),
  // intrinsics through p = K m.
  const int n = static_cast<int>(points_w.size());
  const Eigen::Isometry3d camera_T_world = world_T_camera.inverse();
  const Eigen::Matrix3d& k = camera.k;
  Eigen::MatrixXd j(2 * n, 11);
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d pc = camera_T_world * points_w[i];
    const double x = pc.x() / pc.z(), y = pc.y() / pc.z();
    const Eigen::Matrix<double, 2, 6> lm = control::pointInteraction(x, y, pc.z());
    j.block<2, 6>(2 * i, 0) = k.topLeftCorner<2, 2>() * lm;
    // d(u, v)/d(fx, fy, cx, cy, skew): u = fx x + s y + cx, v = fy y + cy.
    j.block<2, 5>(2 * i, 6) << x, 0.0, 1.0, 0.0, y,  //
        0.0, y, 0.0, 1.0, 0.0;
  }
  const Eigen::MatrixXd info = j.transpose() * j / (noise_px * noise_px);
  Eigen::Matrix<double, 6, 6> cov;
  if (intrinsics_known) {
    cov = info.topLeftCorner<6, 6>().inverse();
  } else {
    cov = info.inverse().topLeftCorner<6, 6>();
  }
  PoseBound b;
  for (int a = 0; a < 3; ++a) {
    b.translation_mm(a) = 1000.0 * std::sqrt(cov(a, a));
    b.rotation_deg(a) = 180.0 / M_PI * std::sqrt(cov(3 + a, 3 + a));
  }
  return b;
}

}  // namespace sim
}  // namespace exocet_servo
