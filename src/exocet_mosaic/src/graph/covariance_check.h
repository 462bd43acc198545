/**
 * @file covariance_check.h
 * @brief The whitening matrix of a measurement covariance, after checking that the covariance is usable. Private to
 * the graph library.
 */
#pragma once

#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/Eigenvalues>

namespace exocet_mosaic {
namespace graph {

/**
 * @brief W with W^T W = covariance^-1 (the inverse of the lower Cholesky factor).
 * @param what names the covariance in the message
 * @throws std::invalid_argument naming `what` and the problem: a non-finite entry, asymmetry beyond rounding, or an
 * eigenvalue <= 0 (not positive definite)
 */
template <int N>
Eigen::Matrix<double, N, N> whiteningOf(const Eigen::Matrix<double, N, N>& covariance, const std::string& what) {
  std::ostringstream err;
  err.precision(6);
  if (!covariance.allFinite()) {
    err << what << " has a non-finite entry (NaN or infinity):\n" << covariance;
    throw std::invalid_argument(err.str());
  }
  const double scale = covariance.cwiseAbs().maxCoeff();
  if ((covariance - covariance.transpose()).cwiseAbs().maxCoeff() > 1e-9 * scale) {
    err << what << " is not symmetric:\n" << covariance;
    throw std::invalid_argument(err.str());
  }
  const Eigen::Matrix<double, N, N> symmetric = 0.5 * (covariance + covariance.transpose());
  const double min_eigenvalue =
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, N, N>>(symmetric, Eigen::EigenvaluesOnly)
          .eigenvalues()
          .minCoeff();
  Eigen::LLT<Eigen::Matrix<double, N, N>> llt(symmetric);
  if (!(min_eigenvalue > 0.0) || llt.info() != Eigen::Success) {
    err << what << " is not positive definite (smallest eigenvalue " << min_eigenvalue << "):\n" << covariance;
    throw std::invalid_argument(err.str());
  }
  return llt.matrixL().solve(Eigen::Matrix<double, N, N>::Identity());
}

}  // namespace graph
}  // namespace exocet_mosaic
