/**
 * @file anchor_fit.h
 * @brief (private) The fit of a mosaic's local ground frame to UTM: y = x + [da -b; b da] (x - centre) + t, by
 * weighted least squares with a prior on (da, b), optionally Huber-robust (IRLS), with its covariance.
 */
#pragma once

#include <vector>

#include <Eigen/Core>
#include <Eigen/Dense>

namespace exocet_mosaic {
namespace compose {

/// One correspondence: a point of the local frame and where the navigation puts it (both metres), with covariance.
struct AnchorPoint {
  Eigen::Vector2d local_m = Eigen::Vector2d::Zero();
  Eigen::Vector2d measured_m = Eigen::Vector2d::Zero();
  Eigen::Matrix2d cov_m2 = Eigen::Matrix2d::Identity();
};

/// The fitted map local -> measured, parameters p = (da, b, tx, ty) about centre_m.
struct AnchorFit {
  Eigen::Vector2d centre_m = Eigen::Vector2d::Zero();
  Eigen::Vector4d params = Eigen::Vector4d::Zero();
  Eigen::Matrix4d cov = Eigen::Matrix4d::Zero();
  int points = 0;
  int downweighted = 0;       ///< points the Huber weights reduced
  double chi2_per_dof = 0.0;  ///< of the final weighted residuals (0 if no redundancy)

  Eigen::Matrix2d linear() const;  ///< I + [da -b; b da]
  Eigen::Vector2d apply(const Eigen::Vector2d& local_m) const;
  Eigen::Vector2d applyInverse(const Eigen::Vector2d& measured_m) const;
  Eigen::Matrix2d covAt(const Eigen::Vector2d& local_m) const;  ///< covariance of apply(local_m)
};

/**
 * @brief A continuity tie: points that the fit must follow closely (weighted by their cov_m2, the allowed slack),
 * whose actual errors are larger and correlated (error_cov, 2n x 2n: the previous tile's own uncertainty). The
 * estimate sticks to the tie (no seam between consecutive tiles) and its covariance is the sandwich
 * M^-1 (sum J^T W C W J) M^-1 that accounts for the tie's actual errors.
 */
struct AnchorTie {
  std::vector<AnchorPoint> points;
  Eigen::MatrixXd error_cov;
};

/**
 * @brief Fits the map. @param similarity false: translation only. @param prior_sigma sigma of da and b.
 * @param robust Huber IRLS (threshold 2 sigma in Mahalanobis distance); the covariance is inflated by the residuals'
 * chi2 per degree of freedom when that exceeds 1 (the navigation covariance too optimistic).
 * With no points: the identity with a zero covariance.
 */
AnchorFit fitAnchor(const std::vector<AnchorPoint>& points, const AnchorTie* tie, bool similarity, double prior_sigma,
                    bool robust);

/// Normal equations accumulated point by point about a fixed centre (running fit for the jump detection, O(1)).
class AnchorAccumulator {
 public:
  void reset(const Eigen::Vector2d& centre_m);
  void add(const AnchorPoint& point);
  AnchorFit solve(bool similarity, double prior_sigma) const;
  int points() const { return points_; }

 private:
  Eigen::Vector2d centre_ = Eigen::Vector2d::Zero();
  Eigen::Matrix4d normal_ = Eigen::Matrix4d::Zero();
  Eigen::Vector4d rhs_ = Eigen::Vector4d::Zero();
  int points_ = 0;
};

}  // namespace compose
}  // namespace exocet_mosaic
