#include "exocet_servo/control/invariant_features.h"

#include <cmath>
#include <sstream>

namespace exocet_servo {
namespace control {

bool upperTriangularFactor(const Eigen::Matrix3d& s, Eigen::Matrix3d* u) {
  // Written out (3x3): U's last column from S's last column, then the 2x2 block left over. Eigen's LLT gives a lower
  // factor (S = L L^T); reversing rows and columns of S and of its factor would give the same result.
  u->setZero();
  const double u22_sq = s(2, 2);
  if (!(u22_sq > 0.0)) return false;
  const double u22 = std::sqrt(u22_sq);
  const double u02 = s(0, 2) / u22;
  const double u12 = s(1, 2) / u22;
  const double u11_sq = s(1, 1) - u12 * u12;
  if (!(u11_sq > 1e-15 * std::abs(s(1, 1)) && u11_sq > 0.0)) return false;
  const double u11 = std::sqrt(u11_sq);
  const double u01 = (s(0, 1) - u02 * u12) / u11;
  const double u00_sq = s(0, 0) - u01 * u01 - u02 * u02;
  if (!(u00_sq > 1e-15 * std::abs(s(0, 0)) && u00_sq > 0.0)) return false;
  (*u) << std::sqrt(u00_sq), u01, u02, 0.0, u11, u12, 0.0, 0.0, u22;
  return true;
}

Eigen::VectorXd InvariantPoints::stacked() const {
  Eigen::VectorXd v(2 * q.size());
  for (size_t i = 0; i < q.size(); ++i) {
    v(2 * i) = q[i].x();
    v(2 * i + 1) = q[i].y();
  }
  return v;
}

std::vector<Eigen::Vector3d> homogeneous(const std::vector<Eigen::Vector2d>& points_px) {
  std::vector<Eigen::Vector3d> out;
  out.reserve(points_px.size());
  for (const auto& p : points_px) out.emplace_back(p.x(), p.y(), 1.0);
  return out;
}

std::string computeInvariantPoints(const std::vector<Eigen::Vector3d>& points, InvariantPoints* out) {
  const size_t n = points.size();
  if (n < 3) return "invariant points need at least 3 points, got " + std::to_string(n);
  Eigen::Matrix3d s = Eigen::Matrix3d::Zero();
  for (size_t i = 0; i < n; ++i) {
    if (std::abs(points[i].z() - 1.0) > 1e-12) {
      std::ostringstream msg;
      msg << "point " << i << " has third coordinate " << points[i].z() << ", must be 1 (homogeneous (u, v, 1))";
      return msg.str();
    }
    s.noalias() += points[i] * points[i].transpose();
  }
  s /= static_cast<double>(n);
  if (!upperTriangularFactor(s, &out->t)) return "the points are collinear (S_p is not positive definite)";
  out->s = s;
  // T is upper triangular: its inverse is too, computed by back-substitution.
  out->t_inverse = out->t.triangularView<Eigen::Upper>().solve(Eigen::Matrix3d::Identity());
  out->q.resize(n);
  for (size_t i = 0; i < n; ++i) out->q[i] = out->t_inverse * points[i];
  return "";
}

}  // namespace control
}  // namespace exocet_servo
