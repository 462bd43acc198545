/**
 * @file rts_smoother.h
 * @brief Fixed-interval Rauch-Tung-Striebel smoother over the navigation filter's log: every step's estimate given
 * all the measurements of the dive (past and future). No ROS in it.
 */
#pragma once

#include <vector>

#include "exocet_mosaic/fusion/filter_log.h"

namespace exocet_mosaic {
namespace fusion {

/**
 * @brief Smoothed state of every step of `log`, in the same order (empty log -> empty result).
 *
 * Backward pass x_s(k) = x(k) + C_k (x_s(k+1) - x_prior(k+1)), P_s(k) = P(k) + C_k (P_s(k+1) - P_prior(k+1)) C_k^T,
 * C_k = P(k) F(k+1)^T P_prior(k+1)^+ (pseudo-inverse: states the filter holds exactly, such as an uninitialised
 * dead-reckoning offset, carry no information). With the extended filter's linearised transitions this is the
 * extended RTS smoother; on a linear-Gaussian model it equals the batch least-squares solution. A step marked as a
 * discontinuity (filter recovery) starts an independent interval: nothing is carried across it.
 */
std::vector<FilterState> smoothRts(const FilterLog& log);

}  // namespace fusion
}  // namespace exocet_mosaic
