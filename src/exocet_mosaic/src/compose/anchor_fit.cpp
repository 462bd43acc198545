#include "anchor_fit.h"

#include <cmath>

#include <Eigen/Dense>

namespace exocet_mosaic {
namespace compose {
namespace {

// Jacobian of (y - x) with respect to (da, b, tx, ty) at d = x - centre.
Eigen::Matrix<double, 2, 4> jacobian(const Eigen::Vector2d& d) {
  Eigen::Matrix<double, 2, 4> j;
  j << d.x(), -d.y(), 1, 0, d.y(), d.x(), 0, 1;
  return j;
}

Eigen::Matrix2d information(const Eigen::Matrix2d& cov) {
  // Guard against singular covariances (a navigation that reports 0).
  Eigen::Matrix2d c = 0.5 * (cov + cov.transpose());
  c += Eigen::Matrix2d::Identity() * 1e-10;
  return c.inverse();
}

AnchorFit solveNormal(const Eigen::Matrix4d& normal_in, const Eigen::Vector4d& rhs, const Eigen::Vector2d& centre,
                      bool similarity, double prior_sigma) {
  AnchorFit fit;
  fit.centre_m = centre;
  if (similarity) {
    Eigen::Matrix4d normal = normal_in;
    const double prior_info = 1.0 / (prior_sigma * prior_sigma);
    normal(0, 0) += prior_info;  // prior da = 0, b = 0: well posed while the baseline is short
    normal(1, 1) += prior_info;
    if (normal(2, 2) <= 0 || normal(3, 3) <= 0) return fit;
    const Eigen::Matrix4d cov = normal.inverse();
    fit.params = cov * rhs;
    fit.cov = cov;
  } else {
    const Eigen::Matrix2d n = normal_in.bottomRightCorner<2, 2>();
    if (n(0, 0) <= 0 || n(1, 1) <= 0) return fit;
    const Eigen::Matrix2d cov = n.inverse();
    fit.params.tail<2>() = cov * rhs.tail<2>();
    fit.cov.bottomRightCorner<2, 2>() = cov;
  }
  return fit;
}

}  // namespace

Eigen::Matrix2d AnchorFit::linear() const {
  Eigen::Matrix2d m;
  m << 1 + params(0), -params(1), params(1), 1 + params(0);
  return m;
}

Eigen::Vector2d AnchorFit::apply(const Eigen::Vector2d& local_m) const {
  return centre_m + linear() * (local_m - centre_m) + params.tail<2>();
}

Eigen::Vector2d AnchorFit::applyInverse(const Eigen::Vector2d& measured_m) const {
  return centre_m + linear().inverse() * (measured_m - centre_m - params.tail<2>());
}

Eigen::Matrix2d AnchorFit::covAt(const Eigen::Vector2d& local_m) const {
  const Eigen::Matrix<double, 2, 4> j = jacobian(local_m - centre_m);
  return j * cov * j.transpose();
}

AnchorFit fitAnchor(const std::vector<AnchorPoint>& points, const AnchorTie* tie, bool similarity, double prior_sigma,
                    bool robust) {
  AnchorFit fit;
  const std::size_t n_tie = tie ? tie->points.size() : 0;
  if (points.empty() && n_tie == 0) return fit;
  // Centre at the information-weighted centroid of the navigation points (or of the tie): the translation is then
  // nearly uncorrelated with rotation/scale.
  Eigen::Matrix2d info_sum = Eigen::Matrix2d::Zero();
  Eigen::Vector2d weighted = Eigen::Vector2d::Zero();
  std::vector<Eigen::Matrix2d> infos;
  infos.reserve(points.size());
  for (const auto& p : points) {
    infos.push_back(information(p.cov_m2));
    info_sum += infos.back();
    weighted += infos.back() * p.local_m;
  }
  std::vector<Eigen::Matrix2d> tie_infos;
  Eigen::Matrix4d tie_normal = Eigen::Matrix4d::Zero();
  Eigen::Vector4d tie_rhs = Eigen::Vector4d::Zero();
  if (points.empty()) {
    for (std::size_t i = 0; i < n_tie; ++i) weighted += tie->points[i].local_m / n_tie;
    info_sum = Eigen::Matrix2d::Identity();
  }
  const Eigen::Vector2d centre = info_sum.inverse() * weighted;
  for (std::size_t i = 0; i < n_tie; ++i) {
    tie_infos.push_back(information(tie->points[i].cov_m2));
    const auto j = jacobian(tie->points[i].local_m - centre);
    tie_normal += j.transpose() * tie_infos.back() * j;
    tie_rhs += j.transpose() * tie_infos.back() * (tie->points[i].measured_m - tie->points[i].local_m);
  }
  std::vector<double> w(points.size(), 1.0);
  const double huber_k = 2.0;
  const int iterations = robust ? 8 : 1;
  Eigen::Matrix4d data_normal = Eigen::Matrix4d::Zero(), data_meat = Eigen::Matrix4d::Zero();
  for (int it = 0; it < iterations; ++it) {
    data_normal.setZero();
    data_meat.setZero();
    Eigen::Vector4d rhs = tie_rhs;
    for (std::size_t i = 0; i < points.size(); ++i) {
      const auto j = jacobian(points[i].local_m - centre);
      const Eigen::Matrix2d wi = w[i] * infos[i];
      data_normal += j.transpose() * wi * j;
      data_meat += w[i] * j.transpose() * wi * j;  // J^T (wW) W^-1 (wW) J
      rhs += j.transpose() * wi * (points[i].measured_m - points[i].local_m);
    }
    fit = solveNormal(data_normal + tie_normal, rhs, centre, similarity, prior_sigma);
    if (!robust) break;
    // Huber weights on the Mahalanobis distance of each navigation residual.
    bool changed = false;
    fit.downweighted = 0;
    for (std::size_t i = 0; i < points.size(); ++i) {
      const Eigen::Vector2d r = points[i].measured_m - fit.apply(points[i].local_m);
      const double d = std::sqrt(std::max(0.0, r.dot(infos[i] * r)));
      const double nw = d <= huber_k ? 1.0 : huber_k / d;
      if (nw < 1.0) ++fit.downweighted;
      if (std::abs(nw - w[i]) > 1e-4) changed = true;
      w[i] = nw;
    }
    if (!changed && it > 0) break;
  }
  fit.points = static_cast<int>(points.size() + n_tie);
  double chi2 = 0;
  for (std::size_t i = 0; i < points.size(); ++i) {
    const Eigen::Vector2d r = points[i].measured_m - fit.apply(points[i].local_m);
    chi2 += w[i] * r.dot(infos[i] * r);
  }
  const int dof = 2 * static_cast<int>(points.size()) - (similarity ? 4 : 2);
  double inflation = 1.0;
  if (dof >= 4) {
    fit.chi2_per_dof = chi2 / dof;
    inflation = std::max(1.0, fit.chi2_per_dof);  // the navigation's covariance too optimistic
  }
  if (n_tie > 0 && tie->error_cov.rows() == static_cast<int>(2 * n_tie)) {
    // Sandwich covariance: the tie's weights are its slack, its actual errors the previous tile's uncertainty.
    Eigen::MatrixXd jw(4, 2 * n_tie);
    for (std::size_t i = 0; i < n_tie; ++i)
      jw.block<4, 2>(0, 2 * i) = jacobian(tie->points[i].local_m - centre).transpose() * tie_infos[i];
    Eigen::Matrix4d meat = inflation * data_meat + jw * tie->error_cov * jw.transpose();
    if (similarity) {
      const double prior_info = 1.0 / (prior_sigma * prior_sigma);
      meat(0, 0) += prior_info;
      meat(1, 1) += prior_info;
      fit.cov = fit.cov * meat * fit.cov;
    } else {
      const Eigen::Matrix2d bread = fit.cov.bottomRightCorner<2, 2>();
      const Eigen::Matrix2d c = bread * meat.bottomRightCorner<2, 2>() * bread;
      fit.cov.setZero();
      fit.cov.bottomRightCorner<2, 2>() = c;
    }
  } else {
    fit.cov *= inflation;
  }
  return fit;
}

void AnchorAccumulator::reset(const Eigen::Vector2d& centre_m) {
  centre_ = centre_m;
  normal_.setZero();
  rhs_.setZero();
  points_ = 0;
}

void AnchorAccumulator::add(const AnchorPoint& point) {
  const auto j = jacobian(point.local_m - centre_);
  const Eigen::Matrix2d info = information(point.cov_m2);
  normal_ += j.transpose() * info * j;
  rhs_ += j.transpose() * info * (point.measured_m - point.local_m);
  ++points_;
}

AnchorFit AnchorAccumulator::solve(bool similarity, double prior_sigma) const {
  AnchorFit fit = solveNormal(normal_, rhs_, centre_, similarity, prior_sigma);
  fit.points = points_;
  return fit;
}

}  // namespace compose
}  // namespace exocet_mosaic
