#include "exocet_mosaic/fusion/rts_smoother.h"

#include <Eigen/Dense>

namespace exocet_mosaic {
namespace fusion {
namespace {

/// Solves P_prior C^T = F P_posterior for C^T in the least-squares, minimum-norm sense (P_prior may be singular
/// in the directions the filter holds exactly).
StateMatrix smootherGain(const StateMatrix& P_posterior, const StateMatrix& transition, const StateMatrix& P_prior) {
  // Scale so that states of very different units (metres, radians per second) are conditioned alike.
  StateVector scale;
  for (int i = 0; i < kStateSize; ++i) scale[i] = P_prior(i, i) > 0.0 ? 1.0 / std::sqrt(P_prior(i, i)) : 1.0;
  const StateMatrix D = scale.asDiagonal();
  const StateMatrix A = D * P_prior * D;
  Eigen::CompleteOrthogonalDecomposition<StateMatrix> cod;
  cod.setThreshold(1e-12);
  cod.compute(A);
  // C^T = P_prior^+ F P_post = D (D P_prior D)^+ D F P_post
  const StateMatrix Ct = D * cod.solve(D * transition * P_posterior);
  return Ct.transpose();
}

}  // namespace

std::vector<FilterState> smoothRts(const FilterLog& log) {
  const auto& steps = log.steps;
  std::vector<FilterState> out(steps.size());
  if (steps.empty()) return out;
  const size_t n = steps.size();
  StateVector xs = steps[n - 1].x_posterior;
  StateMatrix Ps = steps[n - 1].P_posterior;
  out[n - 1] = FilterState::from(steps[n - 1].stamp_s, xs, Ps);
  for (size_t k = n - 1; k-- > 0;) {
    const FilterStep& cur = steps[k];
    const FilterStep& next = steps[k + 1];
    if (next.discontinuity) {
      xs = cur.x_posterior;
      Ps = cur.P_posterior;
    } else {
      const StateMatrix C = smootherGain(cur.P_posterior, next.transition, next.P_prior);
      xs = cur.x_posterior + C * (xs - next.x_prior);
      Ps = cur.P_posterior + C * (Ps - next.P_prior) * C.transpose();
      Ps = 0.5 * (Ps + Ps.transpose());
    }
    out[k] = FilterState::from(cur.stamp_s, xs, Ps);
  }
  return out;
}

}  // namespace fusion
}  // namespace exocet_mosaic
