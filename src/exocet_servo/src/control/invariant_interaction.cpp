#include "exocet_servo/control/invariant_interaction.h"

#include <sstream>

#include "exocet_servo/control/invariant_features.h"

namespace exocet_servo {
namespace control {

Eigen::Matrix<double, 2, 6> pointInteraction(double x, double y, double z_m) {
  const double iz = 1.0 / z_m;
  Eigen::Matrix<double, 2, 6> l;
  l << -iz, 0.0, x * iz, x * y, -(1.0 + x * x), y,  //
      0.0, -iz, y * iz, 1.0 + y * y, -x * y, -x;
  return l;
}

std::string invariantInteraction(const std::vector<Eigen::Vector3d>& m, const std::vector<double>& depths_m,
                                 Eigen::MatrixXd* interaction) {
  const size_t n = m.size();
  if (depths_m.size() != n) {
    std::ostringstream msg;
    msg << "invariantInteraction: " << depths_m.size() << " depths for " << n << " points (must be equal)";
    return msg.str();
  }
  for (size_t i = 0; i < n; ++i) {
    if (!(depths_m[i] > 0.0)) {
      std::ostringstream msg;
      msg << "invariantInteraction: depth of point " << i << " is " << depths_m[i] << " m, must be > 0";
      return msg.str();
    }
  }
  InvariantPoints inv;
  const std::string err = computeInvariantPoints(m, &inv);
  if (!err.empty()) return "invariantInteraction: " + err;

  // Point interaction matrices, stored as (x-row, y-row) per point.
  std::vector<Eigen::Matrix<double, 2, 6>> lm(n);
  for (size_t i = 0; i < n; ++i) lm[i] = pointInteraction(m[i].x(), m[i].y(), depths_m[i]);

  interaction->resize(2 * n, 6);
  const Eigen::Matrix3d& ti = inv.t_inverse;
  const double inv_n = 1.0 / static_cast<double>(n);
  for (int j = 0; j < 6; ++j) {
    // dS for a unit velocity along component j; dm_i = (dx, dy, 0).
    Eigen::Matrix3d c = Eigen::Matrix3d::Zero();  // sum dm_i m_i^T
    for (size_t i = 0; i < n; ++i) {
      const Eigen::Vector3d dm(lm[i](0, j), lm[i](1, j), 0.0);
      c.noalias() += dm * m[i].transpose();
    }
    const Eigen::Matrix3d ds = inv_n * (c + c.transpose());
    const Eigen::Matrix3d a = ti * ds * ti.transpose();
    Eigen::Matrix3d x = a.triangularView<Eigen::StrictlyUpper>();
    x.diagonal() = 0.5 * a.diagonal();
    for (size_t i = 0; i < n; ++i) {
      const Eigen::Vector3d dm(lm[i](0, j), lm[i](1, j), 0.0);
      const Eigen::Vector3d dq = ti * dm - x * inv.q[i];
      (*interaction)(2 * i, j) = dq.x();
      (*interaction)(2 * i + 1, j) = dq.y();
    }
  }
  return "";
}

}  // namespace control
}  // namespace exocet_servo
