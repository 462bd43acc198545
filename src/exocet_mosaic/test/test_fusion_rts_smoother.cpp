// Rauch-Tung-Striebel smoother over the navigation filter's log: equal to batch least squares on a linear-Gaussian
// model, better than the filter on simulated dives.
#include <cmath>

#include <gtest/gtest.h>

#include "exocet_mosaic/fusion/navigation_filter.h"
#include "exocet_mosaic/fusion/rts_smoother.h"
#include "fusion_fixtures.h"

namespace {

using namespace exocet_mosaic::fusion;
using namespace exocet_mosaic::fusion::testing;

struct SmoothedRun {
  SyntheticDive dive;
  std::vector<FilterState> filtered;  ///< at the image stamps
  std::vector<FilterState> smoothed;
};

SmoothedRun runDive(const SyntheticDiveConfig& dc) {
  SmoothedRun run;
  run.dive = makeSyntheticDive(dc);
  NavigationFilter filter(dc.model);
  filter.initialize(dc.t0_s, run.dive.initial_estimate, run.dive.initial_covariance);
  for (const NavEvent& e : run.dive.events) feed(filter, e);
  const std::vector<FilterState> smoothed = smoothRts(filter.log());
  const auto& steps = filter.log().steps;
  size_t k = 0;
  for (size_t i = 0; i < steps.size() && k < run.dive.image_stamps_s.size(); ++i) {
    if (steps[i].stamp_s != run.dive.image_stamps_s[k]) continue;
    run.filtered.push_back(FilterState::from(steps[i].stamp_s, steps[i].x_posterior, steps[i].P_posterior));
    run.smoothed.push_back(smoothed[i]);
    ++k;
  }
  EXPECT_EQ(run.filtered.size(), run.dive.image_stamps_s.size());
  return run;
}

double rmse(const std::vector<FilterState>& states, const std::vector<Eigen::Vector2d>& truth) {
  double sum = 0.0;
  for (size_t k = 0; k < states.size(); ++k) sum += (states[k].position_en_m - truth[k]).squaredNorm();
  return std::sqrt(sum / states.size());
}

}  // namespace

TEST(RtsSmoother, EqualsBatchLeastSquaresOnALinearModel) {
  SyntheticDiveConfig dc;
  dc.model = linearConfig();
  dc.duration_s = 30.0;
  dc.heading_sigma_rad = dc.heading_drift_sigma_rps = dc.pixel_size_sigma = 0.0;
  dc.dr_rate_hz = dc.fps;  // every DR and fix stamp is an image stamp: the batch unknowns
  dc.dr_shares_heading = false;
  dc.image_sigma_m = 0.003;
  dc.seed = 17;
  const SyntheticDive dive = makeSyntheticDive(dc);
  NavigationFilter filter(dc.model);
  filter.initialize(dc.t0_s, dive.initial_estimate, dive.initial_covariance);
  for (const NavEvent& e : dive.events) ASSERT_EQ(feed(filter, e).status, UpdateStatus::kApplied);
  const std::vector<FilterState> smoothed = smoothRts(filter.log());
  const std::vector<Eigen::Vector4d> batch =
      batchLeastSquares(dc.model, dc.t0_s, dive.initial_estimate, dive.initial_covariance, dive.events, true);
  ASSERT_EQ(smoothed.size(), batch.size());
  double worst_p = 0.0, worst_d = 0.0, largest_change = 0.0;
  for (size_t k = 0; k < batch.size(); ++k) {
    worst_p = std::max(worst_p, (smoothed[k].position_en_m - batch[k].head<2>()).norm());
    worst_d = std::max(worst_d, (smoothed[k].dr_offset_en_m - batch[k].tail<2>()).norm());
    const FilterStep& s = filter.log().steps[k];
    largest_change = std::max(largest_change, (smoothed[k].position_en_m - s.x_posterior.head<2>()).norm());
  }
  EXPECT_LT(worst_p, 1e-6);
  EXPECT_LT(worst_d, 1e-6);
  EXPECT_GT(largest_change, 1e-3);  // the smoother does change the filter's estimates

  // Without dead reckoning as well (position only: the 2D3 report's model).
  SyntheticDiveConfig no_dr = dc;
  no_dr.with_dr = false;
  const SyntheticDive dive2 = makeSyntheticDive(no_dr);
  NavigationFilter filter2(no_dr.model);
  filter2.initialize(dc.t0_s, dive2.initial_estimate, dive2.initial_covariance);
  for (const NavEvent& e : dive2.events) ASSERT_EQ(feed(filter2, e).status, UpdateStatus::kApplied);
  const std::vector<FilterState> smoothed2 = smoothRts(filter2.log());
  const std::vector<Eigen::Vector4d> batch2 =
      batchLeastSquares(no_dr.model, dc.t0_s, dive2.initial_estimate, dive2.initial_covariance, dive2.events, false);
  ASSERT_EQ(smoothed2.size(), batch2.size());
  for (size_t k = 0; k < batch2.size(); ++k) EXPECT_LT((smoothed2[k].position_en_m - batch2[k].head<2>()).norm(), 1e-6);
}

TEST(RtsSmoother, BeatsTheFilterOnSimulatedDives) {
  // Linear-Gaussian, then the full model (heading error and drift, pixel size, DR sharing the heading). The errors
  // of one dive are correlated over minutes, so the RMSE is taken over 20 dives.
  for (const bool linear : {true, false}) {
    SyntheticDiveConfig dc;
    dc.model = linear ? linearConfig() : FilterConfig();
    if (linear) dc.heading_sigma_rad = dc.heading_drift_sigma_rps = dc.pixel_size_sigma = 0.0;
    dc.duration_s = 120.0;
    dc.image_sigma_m = 0.002;
    double filter_sq = 0.0, smoother_sq = 0.0;
    int better = 0;
    const int dives = 20;
    for (int seed = 1; seed <= dives; ++seed) {
      dc.seed = 40 + seed;
      const SmoothedRun run = runDive(dc);
      const double f = rmse(run.filtered, run.dive.truth_at_images);
      const double s = rmse(run.smoothed, run.dive.truth_at_images);
      better += s < f;
      filter_sq += f * f / dives;
      smoother_sq += s * s / dives;
      // The smoothed covariance is never larger than the filtered one, and equal at the last step.
      for (size_t k = 0; k < run.filtered.size(); ++k)
        EXPECT_LE(run.smoothed[k].position_covariance_m2.trace(),
                  run.filtered[k].position_covariance_m2.trace() * (1.0 + 1e-9));
      EXPECT_NEAR(run.smoothed.back().position_covariance_m2.trace(), run.filtered.back().position_covariance_m2.trace(),
                  1e-12);
    }
    const char* which = linear ? "linear" : "full";
    EXPECT_LT(std::sqrt(smoother_sq), 0.85 * std::sqrt(filter_sq))
        << which << ": smoother " << std::sqrt(smoother_sq) << " m, filter " << std::sqrt(filter_sq) << " m";
    EXPECT_GE(better, dives * 3 / 4) << which;
  }
}

TEST(RtsSmoother, DoesNotSmoothAcrossARecovery) {
  // A filter that recovers (re-anchors at a fix) marks a discontinuity: the states before it are smoothed as if the
  // log ended there.
  FilterConfig config;
  config.recovery_rejections = 2;
  NavigationFilter filter(config);
  filter.initialize(0.0, Eigen::Vector2d(0, 0), 0.01 * Eigen::Matrix2d::Identity());
  MetricMotion m;
  m.valid = true;
  m.camera_displacement_en_m = Eigen::Vector2d(0.08, 0.0);
  m.covariance_m2 = 1e-6 * Eigen::Matrix2d::Identity();
  for (int k = 1; k <= 100; ++k) {
    filter.addImageMotion((k - 1) * 0.2, k * 0.2, m);
    if (k == 50 || k == 55) filter.addAbsoluteFix(k * 0.2, Eigen::Vector2d(k * 0.08 + 20.0, 0.0), 0.25 * Eigen::Matrix2d::Identity());
  }
  const auto& steps = filter.log().steps;
  size_t cut = 0;
  for (size_t i = 0; i < steps.size(); ++i)
    if (steps[i].discontinuity) cut = i;
  ASSERT_GT(cut, 0u);
  const std::vector<FilterState> smoothed = smoothRts(filter.log());
  FilterLog before;
  before.steps.assign(steps.begin(), steps.begin() + static_cast<long>(cut));
  const std::vector<FilterState> smoothed_before = smoothRts(before);
  for (size_t i = 0; i < cut; ++i) EXPECT_LT((smoothed[i].x - smoothed_before[i].x).norm(), 1e-12) << i;
  EXPECT_NEAR(smoothed[cut - 1].position_en_m.x(), steps[cut - 1].x_posterior[kEast], 1e-12);
  EXPECT_GT(smoothed[cut].position_en_m.x(), 20.0);
  EXPECT_TRUE(smoothRts(FilterLog()).empty());
}
