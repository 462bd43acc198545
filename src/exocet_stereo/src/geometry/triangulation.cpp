#include "exocet_stereo/geometry/triangulation.h"

#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include <Eigen/Dense>
#include <Eigen/Geometry>

#include "exocet_stereo/geometry/epipolar.h"

namespace exocet_stereo {
namespace geometry {

namespace {

void checkViews(const std::vector<Projection>& projections, const std::vector<Eigen::Vector2d>& pixels,
                const char* who) {
  if (projections.size() != pixels.size())
    throw std::invalid_argument(std::string(who) + ": " + std::to_string(projections.size()) + " projections but " +
                                std::to_string(pixels.size()) + " pixels");
  if (projections.size() < 2)
    throw std::invalid_argument(std::string(who) + ": at least 2 views are needed, got " +
                                std::to_string(projections.size()));
}

double squaredError(const Projection& P, const Eigen::Vector2d& x, const Eigen::Vector3d& X) {
  const Eigen::Vector3d u = P * X.homogeneous();
  if (!(std::abs(u.z()) > 0.0)) return std::numeric_limits<double>::infinity();
  return (u.head<2>() / u.z() - x).squaredNorm();
}

double sumSquared(const std::vector<Projection>& projections, const std::vector<Eigen::Vector2d>& pixels,
                  const Eigen::Vector3d& X) {
  double sum = 0.0;
  for (size_t i = 0; i < projections.size(); ++i) sum += squaredError(projections[i], pixels[i], X);
  return sum;
}

}  // namespace

Eigen::Vector3d triangulateLinear(const std::vector<Projection>& projections,
                                  const std::vector<Eigen::Vector2d>& pixels) {
  checkViews(projections, pixels, "triangulateLinear");
  Eigen::MatrixXd A(2 * projections.size(), 4);
  for (size_t i = 0; i < projections.size(); ++i) {
    const Projection& P = projections[i];
    Eigen::RowVector4d rx = pixels[i].x() * P.row(2) - P.row(0);
    Eigen::RowVector4d ry = pixels[i].y() * P.row(2) - P.row(1);
    // Unit rows: a view with a large projection scale must not dominate the algebraic error.
    A.row(2 * i) = rx / std::max(rx.norm(), 1e-300);
    A.row(2 * i + 1) = ry / std::max(ry.norm(), 1e-300);
  }
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(A, Eigen::ComputeFullV);
  const Eigen::Vector4d h = svd.matrixV().col(3);
  return h.head<3>() / h(3);
}

std::pair<Eigen::Vector2d, Eigen::Vector2d> correctMatchOptimal(const Eigen::Matrix3d& F, const Eigen::Vector2d& a,
                                                                const Eigen::Vector2d& b) {
  // Lindstrom's notation: x^T E x' = 0 with x in the second image (b) and x' in the first (a).
  const Eigen::Vector3d x = b.homogeneous(), xp = a.homogeneous();
  const Eigen::Matrix2d Et = F.topLeftCorner<2, 2>();
  Eigen::Vector2d n = (F * xp).head<2>();
  Eigen::Vector2d np = (F.transpose() * x).head<2>();
  const double c = x.dot(F * xp);
  const double half = 0.5 * (n.squaredNorm() + np.squaredNorm());
  const double disc = half * half - n.dot(Et * np) * c;
  const double d = std::sqrt(std::max(disc, 0.0));
  if (!(half + d > 0.0)) return {a, b};
  double lambda = c / (half + d);
  Eigen::Vector2d dx = lambda * n, dxp = lambda * np;
  // Second iteration: the normals at the corrected points, then the exact step along them.
  n -= Et * dxp;
  np -= Et.transpose() * dx;
  const double nn = n.squaredNorm() + np.squaredNorm();
  if (nn > 0.0) lambda *= 2.0 * d / nn;
  dx = lambda * n;
  dxp = lambda * np;
  return {a - dxp, b - dx};
}

Eigen::Vector3d triangulateOptimalTwoView(const PinholeView& view1, const PinholeView& view2, const Eigen::Vector2d& a,
                                          const Eigen::Vector2d& b) {
  const auto corrected = correctMatchOptimal(fundamentalFromViews(view1, view2), a, b);
  return triangulateLinear({view1.projection(), view2.projection()}, {corrected.first, corrected.second});
}

TriangulationRefinement refineTriangulation(const std::vector<Projection>& projections,
                                            const std::vector<Eigen::Vector2d>& pixels, const Eigen::Vector3d& X0,
                                            int max_iterations) {
  checkViews(projections, pixels, "refineTriangulation");
  TriangulationRefinement out;
  out.X = X0;
  const double n = static_cast<double>(projections.size());
  double cost = sumSquared(projections, pixels, X0);
  out.initial_rms_px = std::sqrt(cost / n);
  for (int it = 0; it < max_iterations && std::isfinite(cost); ++it) {
    Eigen::Matrix3d JtJ = Eigen::Matrix3d::Zero();
    Eigen::Vector3d Jtr = Eigen::Vector3d::Zero();
    for (size_t i = 0; i < projections.size(); ++i) {
      const Projection& P = projections[i];
      const Eigen::Vector3d u = P * out.X.homogeneous();
      const Eigen::Vector2d r = u.head<2>() / u.z() - pixels[i];
      Eigen::Matrix<double, 2, 3> dpi_du;
      dpi_du << 1.0 / u.z(), 0.0, -u.x() / (u.z() * u.z()), 0.0, 1.0 / u.z(), -u.y() / (u.z() * u.z());
      const Eigen::Matrix<double, 2, 3> J = dpi_du * P.leftCols<3>();
      JtJ += J.transpose() * J;
      Jtr += J.transpose() * r;
    }
    const Eigen::Vector3d step = JtJ.ldlt().solve(-Jtr);
    if (!step.allFinite()) break;
    // Step halving keeps Gauss-Newton from overshooting far from the minimum.
    double scale = 1.0;
    bool improved = false;
    for (int k = 0; k < 8; ++k, scale *= 0.5) {
      const Eigen::Vector3d candidate = out.X + scale * step;
      const double candidate_cost = sumSquared(projections, pixels, candidate);
      if (candidate_cost < cost) {
        out.X = candidate;
        improved = cost - candidate_cost > 1e-12 * cost;
        cost = candidate_cost;
        break;
      }
    }
    out.iterations = it + 1;
    if (!improved) break;
  }
  out.final_rms_px = std::sqrt(cost / n);
  return out;
}

double reprojectionRms_px(const std::vector<Projection>& projections, const std::vector<Eigen::Vector2d>& pixels,
                          const Eigen::Vector3d& X) {
  checkViews(projections, pixels, "reprojectionRms_px");
  return std::sqrt(sumSquared(projections, pixels, X) / projections.size());
}

}  // namespace geometry
}  // namespace exocet_stereo
