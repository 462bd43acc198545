#include "exocet_mosaic/selfcal/planarity_test.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

#include <Eigen/Dense>
#include <opencv2/calib3d.hpp>

namespace exocet_mosaic {
namespace selfcal {

double homographySampsonDistance_px(const Eigen::Matrix3d& H, const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  const Eigen::Vector3d x = a.homogeneous();
  const double h1 = H.row(0).dot(x), h2 = H.row(1).dot(x), h3 = H.row(2).dot(x);
  // The two independent rows of b x (H a) = 0 and their Jacobian with respect to (a.x, a.y, b.x, b.y).
  const Eigen::Vector2d e(b.y() * h3 - h2, h1 - b.x() * h3);
  Eigen::Matrix<double, 2, 4> j;
  j << b.y() * H(2, 0) - H(1, 0), b.y() * H(2, 1) - H(1, 1), 0.0, h3,  //
      H(0, 0) - b.x() * H(2, 0), H(0, 1) - b.x() * H(2, 1), -h3, 0.0;
  const Eigen::Matrix2d jjt = j * j.transpose();
  const double det = jjt.determinant();
  if (!(std::abs(det) > 0.0)) return std::numeric_limits<double>::infinity();
  const double e2 = e.dot(jjt.inverse() * e);
  return std::sqrt(std::max(0.0, e2));
}

std::string PlanarityConfig::validate() const {
  std::ostringstream err;
  if (!(homography_threshold_sigmas > 0.0))
    err << "homography_threshold_sigmas = " << homography_threshold_sigmas << " must be > 0; ";
  if (!(noise_sigma_px >= 0.0)) err << "noise_sigma_px = " << noise_sigma_px << " must be >= 0 (0: estimated); ";
  if (!(min_noise_px > 0.0)) err << "min_noise_px = " << min_noise_px << " must be > 0; ";
  std::string s = err.str();
  if (!s.empty()) s.resize(s.size() - 2);
  return s;
}

namespace {

/// GRIC of a model whose residuals (pixels) are `distances` (Torr 1997), r = 4 for two views.
double gric(const std::vector<double>& distances, double sigma_px, int manifold_dimension, int parameter_count) {
  const double r = 4.0, lambda3 = 2.0;
  const double n = static_cast<double>(distances.size());
  const double cap = lambda3 * (r - manifold_dimension);
  double sum = 0.0;
  for (double d : distances) {
    const double e2 = std::isfinite(d) ? d * d / (sigma_px * sigma_px) : cap;
    sum += std::min(e2, cap);
  }
  return sum + std::log(r) * manifold_dimension * n + std::log(r * n) * parameter_count;
}

}  // namespace

PlanarityVerdict assessPlanarity(const std::vector<Eigen::Vector2d>& a, const std::vector<Eigen::Vector2d>& b,
                                 const FundamentalResult& fundamental, const PlanarityConfig& config) {
  const std::string problem = config.validate();
  if (!problem.empty()) throw std::invalid_argument("planarity: " + problem);
  if (a.size() != b.size())
    throw std::invalid_argument("assessPlanarity: " + std::to_string(a.size()) + " points in the first image, " +
                                std::to_string(b.size()) + " in the second");
  PlanarityVerdict v;
  if (a.size() < 8 || !fundamental.ok) {
    v.planar = true;  // nothing says otherwise: too little to tell a plane from relief
    return v;
  }
  std::vector<double> d_f(a.size()), d_h(a.size()), inlier_abs;
  for (size_t i = 0; i < a.size(); ++i) {
    d_f[i] = sampsonDistance_px(fundamental.F, a[i], b[i]);
    if (fundamental.inliers[i]) inlier_abs.push_back(d_f[i]);
  }
  if (config.noise_sigma_px > 0.0) {
    v.sigma_px = config.noise_sigma_px;
  } else {
    // Sampson distances of inliers are ~ N(0, sigma^2) along one direction: the MAD estimate is robust.
    std::nth_element(inlier_abs.begin(), inlier_abs.begin() + inlier_abs.size() / 2, inlier_abs.end());
    v.sigma_px = std::max(config.min_noise_px, 1.4826 * inlier_abs[inlier_abs.size() / 2]);
  }
  std::vector<cv::Point2d> pa(a.size()), pb(b.size());
  for (size_t i = 0; i < a.size(); ++i) {
    pa[i] = cv::Point2d(a[i].x(), a[i].y());
    pb[i] = cv::Point2d(b[i].x(), b[i].y());
  }
  // RANSAC for a robust start, then least squares (with OpenCV's Levenberg-Marquardt) on the matches within
  // threshold of it, repeated: OpenCV's RANSAC alone stops on a consensus that is good, not the best.
  const double threshold_px = config.homography_threshold_sigmas * v.sigma_px;
  cv::Mat h = cv::findHomography(pa, pb, cv::RANSAC, threshold_px, cv::noArray(), 2000, 0.999);
  for (int round = 0; round < 4 && !h.empty(); ++round) {
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) v.H(r, c) = h.at<double>(r, c);
    std::vector<cv::Point2d> qa, qb;
    for (size_t i = 0; i < a.size(); ++i) {
      if (homographySampsonDistance_px(v.H, a[i], b[i]) >= threshold_px) continue;
      qa.push_back(pa[i]);
      qb.push_back(pb[i]);
    }
    const int count = static_cast<int>(qa.size());
    if (count < 8 || count == v.homography_inliers) break;
    v.homography_inliers = count;
    const cv::Mat refined = cv::findHomography(qa, qb, 0);
    if (refined.empty()) break;
    h = refined;
  }
  if (!h.empty()) {
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) v.H(r, c) = h.at<double>(r, c);
  }
  for (size_t i = 0; i < a.size(); ++i)
    d_h[i] = h.empty() ? std::numeric_limits<double>::infinity() : homographySampsonDistance_px(v.H, a[i], b[i]);
  v.gric_f = gric(d_f, v.sigma_px, 3, 7);
  v.gric_h = gric(d_h, v.sigma_px, 2, 8);
  v.planar = v.gric_h <= v.gric_f;
  std::vector<double> parallax;
  for (size_t i = 0; i < a.size(); ++i)
    if (fundamental.inliers[i]) parallax.push_back(d_h[i]);
  std::nth_element(parallax.begin(), parallax.begin() + parallax.size() / 2, parallax.end());
  v.median_homography_px = parallax[parallax.size() / 2];
  return v;
}

}  // namespace selfcal
}  // namespace exocet_mosaic
