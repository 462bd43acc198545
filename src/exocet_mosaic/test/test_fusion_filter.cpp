// The navigation filter (2D3 section 3.5, extended): hand-computed Kalman step, batch least squares, gating and
// recovery, out-of-sequence fixes, dropouts, registration failures, invalid input, consistency (NEES).
#include <cmath>
#include <filesystem>
#include <iostream>
#include <limits>
#include <string>

#include <gtest/gtest.h>

#include "exocet_mosaic/fusion/navigation_filter.h"
#include "fusion_fixtures.h"

namespace {

using namespace exocet_mosaic::fusion;
using namespace exocet_mosaic::fusion::testing;

MetricMotion motionOf(const Eigen::Vector2d& d, double sigma_m) {
  MetricMotion m;
  m.valid = true;
  m.camera_displacement_en_m = d;
  m.covariance_m2 = sigma_m * sigma_m * Eigen::Matrix2d::Identity();
  return m;
}

double positionNees(const FilterState& s, const Eigen::Vector2d& truth) {
  const Eigen::Vector2d e = s.position_en_m - truth;
  return e.dot(s.position_covariance_m2.ldlt().solve(e));
}

/// Chi-square quantile (Wilson-Hilferty), accurate to a fraction of a percent for dof >= 20.
double chiSquareQuantile(double dof, double z_score) {
  const double a = 2.0 / (9.0 * dof);
  return dof * std::pow(1.0 - a + z_score * std::sqrt(a), 3);
}

}  // namespace

TEST(NavigationFilter, ConfigValidationNamesTheField) {
  FilterConfig c;
  EXPECT_EQ(c.validate(), "");
  EXPECT_NEAR(c.gateThreshold(), 13.8155, 1e-3);
  c.gate_probability = 1.0;
  c.history_s = -1.0;
  c.dr_measurement_sigma_m = std::nan("");
  const std::string problems = c.validate();
  EXPECT_NE(problems.find("gate_probability"), std::string::npos) << problems;
  EXPECT_NE(problems.find("history_s"), std::string::npos) << problems;
  EXPECT_NE(problems.find("dr_measurement_sigma_m"), std::string::npos) << problems;
  EXPECT_THROW(NavigationFilter{c}, std::invalid_argument);
  FilterConfig r;
  r.recovery_rejections = 0;
  EXPECT_NE(r.validate().find("recovery_rejections"), std::string::npos);
}

TEST(NavigationFilter, HandComputedKalmanStep) {
  FilterConfig config = linearConfig();
  NavigationFilter filter(config);
  EXPECT_FALSE(filter.initialized());
  const Eigen::Vector2d p0(100.0, 200.0);
  const Eigen::Matrix2d P0 = (Eigen::Matrix2d() << 0.04, 0.01, 0.01, 0.09).finished();
  filter.initialize(10.0, p0, P0);
  ASSERT_TRUE(filter.initialized());

  const Eigen::Vector2d m(0.1, 0.05);
  MetricMotion motion = motionOf(m, 0.0);
  motion.covariance_m2 << 1e-4, 2e-5, 2e-5, 2e-4;
  ASSERT_EQ(filter.addImageMotion(10.0, 10.2, motion).status, UpdateStatus::kApplied);
  // Prediction by hand: x- = x + m, P- = P + R_m + (q dt + step^2) I.
  const Eigen::Matrix2d I = Eigen::Matrix2d::Identity();
  const Eigen::Vector2d x_prior = p0 + m;
  const Eigen::Matrix2d P_prior =
      P0 + motion.covariance_m2 + config.position_noise_m2_per_s * 0.2 * I + config.imageStepNoiseCovariance(m);
  EXPECT_LT((filter.current().position_en_m - x_prior).norm(), 1e-12);
  EXPECT_LT((filter.current().position_covariance_m2 - P_prior).norm(), 1e-12);
  EXPECT_DOUBLE_EQ(filter.current().stamp_s, 10.2);

  // Fix at the image's stamp: K = P- (P- + R)^-1, x = x- + K (z - x-), P = (I - K) P-.
  const Eigen::Vector2d z(100.5, 199.8);
  const Eigen::Matrix2d R = (Eigen::Matrix2d() << 0.25, 0.05, 0.05, 0.16).finished();
  const UpdateResult r = filter.addAbsoluteFix(10.2, z, R);
  ASSERT_EQ(r.status, UpdateStatus::kApplied) << r.detail;
  const Eigen::Matrix2d S = P_prior + R;
  const Eigen::Matrix2d K = P_prior * S.inverse();
  const Eigen::Vector2d x_post = x_prior + K * (z - x_prior);
  const Eigen::Matrix2d P_post = (I - K) * P_prior;
  EXPECT_LT((filter.current().position_en_m - x_post).norm(), 1e-12);
  EXPECT_LT((filter.current().position_covariance_m2 - P_post).norm(), 1e-12);
  EXPECT_NEAR(r.mahalanobis_sq, (z - x_prior).dot(S.inverse() * (z - x_prior)), 1e-12);
  EXPECT_EQ(filter.current().x.size(), kStateSize);
  EXPECT_EQ(filter.log().steps.size(), 2u);
}

TEST(NavigationFilter, ImageStepNoiseIsAlongAndAcrossTheMotion) {
  FilterConfig config = linearConfig();
  config.image_step_noise_along_m = 0.002;
  config.image_step_noise_across_m = -1e-3;
  EXPECT_NE(config.validate().find("image_step_noise_across_m"), std::string::npos) << config.validate();
  config.image_step_noise_across_m = 0.0005;
  ASSERT_EQ(config.validate(), "");
  // A step towards the north-east: its extra variance is 4e-6 m^2 along (1, 1)/sqrt(2), 2.5e-7 m^2 across it.
  const Eigen::Vector2d m(0.03, 0.03);
  const Eigen::Vector2d along = m.normalized(), across(-along.y(), along.x());
  const Eigen::Matrix2d S = config.imageStepNoiseCovariance(m);
  EXPECT_NEAR(along.dot(S * along), 4e-6, 1e-15);
  EXPECT_NEAR(across.dot(S * across), 2.5e-7, 1e-15);
  EXPECT_NEAR(along.dot(S * across), 0.0, 1e-15);
  // A motion with no direction: the mean of the two variances on each axis.
  EXPECT_LT(
      (config.imageStepNoiseCovariance(Eigen::Vector2d::Zero()) - 0.5 * (4e-6 + 2.5e-7) * Eigen::Matrix2d::Identity())
          .norm(),
      1e-18);

  // Through the filter: the predicted covariance holds S in the world frame (no heading error, no pixel-size error
  // in the linear configuration); a step eastwards gets its along-track noise on the east axis only.
  NavigationFilter filter(config);
  const Eigen::Matrix2d P0 = 1e-4 * Eigen::Matrix2d::Identity();
  filter.initialize(10.0, Eigen::Vector2d(500.0, 600.0), P0);
  MetricMotion motion = motionOf(Eigen::Vector2d(0.05, 0.0), 0.0);
  motion.covariance_m2 = 1e-8 * Eigen::Matrix2d::Identity();
  ASSERT_EQ(filter.addImageMotion(10.0, 10.2, motion).status, UpdateStatus::kApplied);
  const Eigen::Matrix2d P = filter.current().position_covariance_m2;
  const double q = config.position_noise_m2_per_s * 0.2;
  EXPECT_NEAR(P(0, 0), 1e-4 + 1e-8 + q + 4e-6, 1e-15);
  EXPECT_NEAR(P(1, 1), 1e-4 + 1e-8 + q + 2.5e-7, 1e-15);
  EXPECT_NEAR(P(0, 1), 0.0, 1e-15);
}

TEST(NavigationFilter, PixelSizeAndHeadingAreEstimatedFromFixes) {
  // The images under-measure the motion by 3 % and are rotated by 2 degrees (heading error): along a 60 m line the
  // fixes reveal both, and the filter's estimates converge to them within their sigmas.
  FilterConfig config;
  config.initial_heading_drift_sigma_rps = 1e-6;
  config.heading_drift_noise_rps_per_sqrt_s = 0.0;
  config.heading_noise_rad_per_sqrt_s = 0.0;
  config.pixel_size_correction_noise_per_sqrt_s = 0.0;
  config.initial_pixel_size_correction_sigma = 0.05;
  config.initial_heading_sigma_rad = 0.05;
  NavigationFilter filter(config);
  const double c_true = 0.03, psi_true = 2.0 * M_PI / 180.0;
  Eigen::Vector2d truth(0.0, 0.0);
  filter.initialize(0.0, truth, 0.01 * Eigen::Matrix2d::Identity());
  std::mt19937 rng(3);
  std::normal_distribution<double> n01;
  const Eigen::Vector2d step(0.06, 0.05);
  for (int k = 1; k <= 900; ++k) {
    const Eigen::Vector2d measured = rot2(psi_true) * step / (1.0 + c_true);
    truth += step;
    ASSERT_EQ(filter.addImageMotion((k - 1) * 0.2, k * 0.2, motionOf(measured, 1e-4)).status, UpdateStatus::kApplied);
    if (k % 5 == 0)
      filter.addAbsoluteFix(k * 0.2, truth + Eigen::Vector2d(0.3 * n01(rng), 0.3 * n01(rng)),
                            0.09 * Eigen::Matrix2d::Identity());
  }
  const FilterState s = filter.current();
  EXPECT_NEAR(s.pixel_size_correction, c_true, 3.0 * s.pixel_size_correction_sigma + 1e-3);
  EXPECT_LT(s.pixel_size_correction_sigma, 0.01);
  EXPECT_NEAR(s.heading_error_rad, psi_true, 3.0 * s.heading_error_sigma_rad + 1e-3);
  EXPECT_LT(s.heading_error_sigma_rad, 0.01);
  EXPECT_LT((s.position_en_m - truth).norm(), 0.3);
}

TEST(NavigationFilter, DeadReckoningScaleErrorIsEstimated) {
  // The DVL over-reads the speed by 2 %: on a 48 m out-and-back the DR runs ahead by up to 0.5 m, then comes back.
  // The images (pixel size known here) measure the true distance, so the filter finds the scale error and keeps
  // the track on the truth; a model without the scale state has to explain it by its offset's random walk.
  SyntheticDiveConfig dc;
  dc.duration_s = 120.0;
  dc.seed = 5;
  dc.pixel_size_sigma = 0.0;
  dc.dr_scale_error = 0.02;
  dc.model = FilterConfig();
  dc.model.initial_pixel_size_correction_sigma = 1e-4;
  dc.model.initial_dr_scale_sigma = 0.03;
  dc.model.dr_offset_noise_m2_per_m = 1e-5;
  const SyntheticDive dive = makeSyntheticDive(dc);
  NavigationFilter filter(dc.model);
  filter.initialize(dc.t0_s, dive.initial_estimate, dive.initial_covariance);
  for (const NavEvent& e : dive.events) feed(filter, e);
  const FilterState s = filter.current();
  EXPECT_NEAR(s.dr_scale_error, 0.02, 3.0 * s.dr_scale_error_sigma);
  EXPECT_LT(s.dr_scale_error_sigma, 0.005);
  // Without the state: the same dive, the scale error left to the offset's random walk.
  FilterConfig no_scale = dc.model;
  no_scale.initial_dr_scale_sigma = 0.0;
  no_scale.dr_scale_noise_per_sqrt_s = 0.0;
  NavigationFilter plain(no_scale);
  plain.initialize(dc.t0_s, dive.initial_estimate, dive.initial_covariance);
  for (const NavEvent& e : dive.events) feed(plain, e);
  EXPECT_NEAR(plain.current().dr_scale_error, 0.0, 1e-12);
  const auto rmse_at_images = [&](const NavigationFilter& f) {
    double sum = 0.0;
    int count = 0;
    size_t k = 0;
    for (const FilterStep& step : f.log().steps) {
      while (k < dive.image_stamps_s.size() && dive.image_stamps_s[k] < step.stamp_s) ++k;
      if (k == dive.image_stamps_s.size()) break;
      if (step.stamp_s != dive.image_stamps_s[k]) continue;
      sum += (step.x_posterior.head<2>() - dive.truth_at_images[k]).squaredNorm();
      ++count;
    }
    return std::sqrt(sum / count);
  };
  EXPECT_LT(rmse_at_images(filter), 0.8 * rmse_at_images(plain));
  std::cout << "with the scale state " << rmse_at_images(filter) << " m, without " << rmse_at_images(plain)
            << " m; scale " << s.dr_scale_error << " +- " << s.dr_scale_error_sigma << "\n";
}

TEST(NavigationFilter, FilterEqualsBatchLeastSquaresOnALinearModel) {
  SyntheticDiveConfig dc;
  dc.model = linearConfig();
  dc.duration_s = 20.0;
  dc.heading_sigma_rad = dc.heading_drift_sigma_rps = dc.pixel_size_sigma = 0.0;
  dc.dr_rate_hz = dc.fps;  // DR at the image stamps
  dc.dr_shares_heading = false;
  dc.seed = 11;
  const SyntheticDive dive = makeSyntheticDive(dc);
  NavigationFilter filter(dc.model);
  filter.initialize(dc.t0_s, dive.initial_estimate, dive.initial_covariance);
  for (const NavEvent& e : dive.events) ASSERT_EQ(feed(filter, e).status, UpdateStatus::kApplied);
  const std::vector<Eigen::Vector4d> batch =
      batchLeastSquares(dc.model, dc.t0_s, dive.initial_estimate, dive.initial_covariance, dive.events, true);
  ASSERT_EQ(batch.size(), filter.log().steps.size());
  const FilterState last = filter.current();
  EXPECT_LT((last.position_en_m - batch.back().head<2>()).norm(), 1e-6);
  EXPECT_LT((last.dr_offset_en_m - batch.back().tail<2>()).norm(), 1e-6);
}

TEST(NavigationFilter, GatingRejectsAnOutlyingFixAndSaysSo) {
  NavigationFilter filter{FilterConfig()};
  filter.initialize(0.0, Eigen::Vector2d(10.0, 20.0), 0.04 * Eigen::Matrix2d::Identity());
  Eigen::Vector2d truth(10.0, 20.0);
  for (int k = 1; k <= 50; ++k) {
    truth += Eigen::Vector2d(0.08, 0.0);
    filter.addImageMotion((k - 1) * 0.2, k * 0.2, motionOf(Eigen::Vector2d(0.08, 0.0), 5e-4));
    if (k % 5 == 0) {
      ASSERT_EQ(filter.addAbsoluteFix(k * 0.2, truth, 0.25 * Eigen::Matrix2d::Identity()).status,
                UpdateStatus::kApplied);
    }
  }
  const FilterState before = filter.current();
  const UpdateResult r =
      filter.addAbsoluteFix(10.0, truth + Eigen::Vector2d(6.0, -4.0), 0.25 * Eigen::Matrix2d::Identity());
  EXPECT_EQ(r.status, UpdateStatus::kRejectedByGate);
  EXPECT_GT(r.mahalanobis_sq, filter.config().gateThreshold());
  EXPECT_NE(r.detail.find("Mahalanobis^2"), std::string::npos) << r.detail;
  EXPECT_NE(r.detail.find("gate"), std::string::npos) << r.detail;
  EXPECT_LT((filter.current().position_en_m - before.position_en_m).norm(), 1e-12);
  EXPECT_LT((filter.current().P - before.P).norm(), 1e-12);
  EXPECT_EQ(filter.log().steps.back().fixes_rejected, 1);
  // A good fix right after is applied.
  EXPECT_EQ(filter.addAbsoluteFix(10.0, truth, 0.25 * Eigen::Matrix2d::Identity()).status, UpdateStatus::kApplied);
}

TEST(NavigationFilter, GatingChangedMidDiveAppliesToTheNextFix) {
  NavigationFilter filter{FilterConfig()};
  filter.initialize(0.0, Eigen::Vector2d(0.0, 0.0), 0.04 * Eigen::Matrix2d::Identity());
  for (int k = 1; k <= 10; ++k)
    filter.addImageMotion((k - 1) * 0.2, k * 0.2, motionOf(Eigen::Vector2d(0.0, 0.0), 5e-4));
  const Eigen::Matrix2d fix_cov = 0.25 * Eigen::Matrix2d::Identity();
  // An offset whose Mahalanobis^2 lies between the 0.999 gate (13.8) and the 0.999999 gate (27.6).
  const double sigma_m = std::sqrt(filter.current().P(0, 0) + 0.25);
  const Eigen::Vector2d offset(std::sqrt(20.0) * sigma_m, 0.0);
  const UpdateResult tight = filter.addAbsoluteFix(2.0, offset, fix_cov);
  ASSERT_EQ(tight.status, UpdateStatus::kRejectedByGate) << tight.detail;
  EXPECT_GT(tight.mahalanobis_sq, 13.8);
  EXPECT_LT(tight.mahalanobis_sq, 27.6);
  filter.setGating(0.999999, 3);
  EXPECT_NEAR(filter.config().gateThreshold(), 27.63, 0.01);
  EXPECT_EQ(filter.config().recovery_rejections, 3);
  EXPECT_EQ(filter.addAbsoluteFix(2.0, offset, fix_cov).status, UpdateStatus::kApplied);
  // A bad value is refused with its range, and the gate in force is kept.
  try {
    filter.setGating(1.5, 3);
    ADD_FAILURE() << "gate_probability 1.5 accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("gate_probability"), std::string::npos) << e.what();
  }
  EXPECT_THROW(filter.setGating(0.99, 0), std::invalid_argument);
  EXPECT_NEAR(filter.config().gateThreshold(), 27.63, 0.01);
}

TEST(NavigationFilter, RecoversAfterALongDropoutWhenLost) {
  // During a 60 s fix dropout the image motion is biased (a drift its covariance does not admit): the filter ends
  // 6 m off while believing itself within centimetres. The first fixes are rejected; after recovery_rejections of
  // them the filter re-anchors at the fix, and the following fixes are applied.
  FilterConfig config;
  config.recovery_rejections = 4;
  NavigationFilter filter(config);
  Eigen::Vector2d truth(0.0, 0.0);
  filter.initialize(0.0, truth, 0.01 * Eigen::Matrix2d::Identity());
  int k = 0;
  const auto image = [&](const Eigen::Vector2d& true_step, const Eigen::Vector2d& measured) {
    ++k;
    truth += true_step;
    return filter.addImageMotion((k - 1) * 0.2, k * 0.2, motionOf(measured, 2e-4));
  };
  for (int i = 0; i < 50; ++i) {
    image({0.08, 0.0}, {0.08, 0.0});
    if (k % 5 == 0) filter.addAbsoluteFix(k * 0.2, truth, 0.25 * Eigen::Matrix2d::Identity());
  }
  for (int i = 0; i < 300; ++i) image({0.08, 0.02}, {0.08, 0.0});  // 60 s, 6 m of unseen drift
  EXPECT_GT((filter.current().position_en_m - truth).norm(), 5.0);
  std::vector<UpdateResult> results;
  for (int i = 0; i < 60; ++i) {
    image({0.08, 0.0}, {0.08, 0.0});
    if (k % 5 == 0) results.push_back(filter.addAbsoluteFix(k * 0.2, truth, 0.25 * Eigen::Matrix2d::Identity()));
  }
  ASSERT_GE(results.size(), 6u);
  for (int i = 0; i < 3; ++i) EXPECT_EQ(results[i].status, UpdateStatus::kRejectedByGate) << i;
  EXPECT_EQ(results[3].status, UpdateStatus::kApplied);
  EXPECT_NE(results[3].detail.find("recovery"), std::string::npos) << results[3].detail;
  for (size_t i = 4; i < results.size(); ++i) EXPECT_EQ(results[i].status, UpdateStatus::kApplied) << i;
  EXPECT_LT((filter.current().position_en_m - truth).norm(), 1.0);
  EXPECT_EQ(filter.counters().recoveries, 1);
}

TEST(NavigationFilter, OutOfSequenceFixEqualsInOrderProcessing) {
  SyntheticDiveConfig dc;
  dc.duration_s = 60.0;
  dc.seed = 5;
  dc.fix_outlier_probability = 0.05;
  dc.model = FilterConfig();
  const SyntheticDive dive = makeSyntheticDive(dc);
  NavigationFilter late(dc.model), ordered(dc.model);
  late.initialize(dc.t0_s, dive.initial_estimate, dive.initial_covariance);
  ordered.initialize(dc.t0_s, dive.initial_estimate, dive.initial_covariance);
  for (const NavEvent& e : dive.events) {
    const UpdateResult r = feed(late, e);
    ASSERT_TRUE(r.status == UpdateStatus::kApplied || r.status == UpdateStatus::kRejectedByGate) << r.detail;
  }
  for (const NavEvent& e : inStampOrder(dive.events)) feed(ordered, e);
  EXPECT_GT(late.counters().rewinds, 50);
  const auto& a = late.log().steps;
  const auto& b = ordered.log().steps;
  ASSERT_EQ(a.size(), b.size());
  double worst = 0.0;
  for (size_t i = 0; i < a.size(); ++i) {
    ASSERT_EQ(a[i].stamp_s, b[i].stamp_s);
    worst = std::max(worst, (a[i].x_posterior - b[i].x_posterior).cwiseAbs().maxCoeff());
    worst = std::max(worst, (a[i].P_posterior - b[i].P_posterior).cwiseAbs().maxCoeff());
    EXPECT_EQ(a[i].fixes_rejected, b[i].fixes_rejected);
  }
  EXPECT_LT(worst, 1e-9);
  EXPECT_LT((late.current().position_en_m - ordered.current().position_en_m).norm(), 1e-9);
}

TEST(NavigationFilter, StateAtALateImagesStampIsThePosteriorThereNotTheLatest) {
  // The images 2 s behind the navigation (a registration that lags, a stalled replay): each motion is applied behind
  // newer dead reckoning and fixes. The state at its stamp is what a filter fed in order had there; the latest state
  // is 2 s of travel further on (what a key frame or a fused pose must not take).
  SyntheticDiveConfig dc;
  dc.duration_s = 60.0;
  dc.seed = 9;
  dc.model = FilterConfig();
  const SyntheticDive dive = makeSyntheticDive(dc);
  std::vector<NavEvent> events = inStampOrder(dive.events);
  NavigationFilter ordered(dc.model);
  ordered.initialize(dc.t0_s, dive.initial_estimate, dive.initial_covariance);
  for (const NavEvent& e : events) feed(ordered, e);
  for (NavEvent& e : events)
    e.arrival_s = e.stamp_s + (e.kind == NavEvent::kImage || e.kind == NavEvent::kImageFailure ? 2.0 : 0.0);
  std::stable_sort(events.begin(), events.end(),
                   [](const NavEvent& a, const NavEvent& b) { return a.arrival_s < b.arrival_s; });
  NavigationFilter late(dc.model);
  late.initialize(dc.t0_s, dive.initial_estimate, dive.initial_covariance);
  double worst_m = 0.0, largest_lead_m = 0.0;
  int checked = 0;
  for (const NavEvent& e : events) {
    const UpdateResult r = feed(late, e);
    if (e.kind != NavEvent::kImage || r.status != UpdateStatus::kApplied) continue;
    const auto& steps = ordered.log().steps;
    const auto there = std::find_if(steps.begin(), steps.end(), [&](const FilterStep& s) { return s.stamp_s == e.stamp_s; });
    ASSERT_NE(there, steps.end());
    const FilterState at = late.stateAt(e.stamp_s);
    EXPECT_DOUBLE_EQ(at.stamp_s, e.stamp_s);
    worst_m = std::max(worst_m, (at.position_en_m - FilterState::from(there->stamp_s, there->x_posterior,
                                                                        there->P_posterior).position_en_m).norm());
    largest_lead_m = std::max(largest_lead_m, (late.current().position_en_m - at.position_en_m).norm());
    ++checked;
  }
  EXPECT_GT(checked, 200);
  EXPECT_LT(worst_m, 1e-9);
  // 0.4 m/s over up to 2 s: the latest state is well ahead of the image's.
  EXPECT_GT(largest_lead_m, 0.5);
}

TEST(NavigationFilter, TooOldFixIsReported) {
  FilterConfig config;
  config.history_s = 5.0;
  NavigationFilter filter(config);
  filter.initialize(100.0, Eigen::Vector2d(0.0, 0.0), 0.01 * Eigen::Matrix2d::Identity());
  for (int k = 1; k <= 100; ++k)
    filter.addImageMotion(100.0 + (k - 1) * 0.2, 100.0 + k * 0.2, motionOf({0.05, 0.0}, 5e-4));
  const FilterState before = filter.current();
  // The camera moves 0.25 m/s east: at 112 s it was at 3 m.
  const UpdateResult r = filter.addAbsoluteFix(112.0, Eigen::Vector2d(3.0, 0.0), 0.25 * Eigen::Matrix2d::Identity());
  EXPECT_EQ(r.status, UpdateStatus::kTooOld);
  EXPECT_NE(r.detail.find("history_s"), std::string::npos) << r.detail;
  EXPECT_LT((filter.current().x - before.x).norm(), 1e-15);
  // Within the window it is applied (at its own stamp, 4 s back).
  const UpdateResult ok = filter.addAbsoluteFix(116.0, Eigen::Vector2d(4.0, 0.0), 0.25 * Eigen::Matrix2d::Identity());
  EXPECT_EQ(ok.status, UpdateStatus::kApplied) << ok.detail;
  // Before the initialisation: too old as well.
  NavigationFilter young(config);
  young.initialize(100.0, Eigen::Vector2d(0.0, 0.0), 0.01 * Eigen::Matrix2d::Identity());
  EXPECT_EQ(young.addAbsoluteFix(99.0, Eigen::Vector2d(0.0, 0.0), 0.25 * Eigen::Matrix2d::Identity()).status,
            UpdateStatus::kTooOld);
}

TEST(NavigationFilter, DropoutCovarianceGrowsThenShrinksAtTheNextFix) {
  // A straight line (on an out-and-back the return legitimately shrinks the uncertainty that the heading and pixel
  // size errors built on the way out), images only, no fixes for 50 s.
  SyntheticDiveConfig dc;
  dc.duration_s = 100.0;
  dc.out_and_back = false;
  dc.with_dr = false;
  dc.fix_dropouts_s = {{20.0, 70.0}};
  dc.seed = 7;
  dc.model = FilterConfig();
  const SyntheticDive dive = makeSyntheticDive(dc);
  NavigationFilter filter(dc.model);
  filter.initialize(dc.t0_s, dive.initial_estimate, dive.initial_covariance);
  for (const NavEvent& e : dive.events) feed(filter, e);
  // In the final log (late fixes in place): the position covariance's trace along the dive.
  double previous = 0.0, at_start = 0.0, at_end = 0.0;
  bool monotonic = true, checked_fix = false;
  for (const FilterStep& s : filter.log().steps) {
    const double t = s.stamp_s - dc.t0_s;
    const double trace = s.P_posterior.block<2, 2>(0, 0).trace();
    if (t > 19.5 && t < 20.5) at_start = trace;
    if (t > 20.0 && t < 70.0) {
      if (trace < previous) monotonic = false;
      at_end = trace;
    }
    if (t >= 70.0 && s.fixes_applied > 0) {
      const double prior_trace = s.P_prior.block<2, 2>(0, 0).trace();
      EXPECT_LT(trace, prior_trace);
      EXPECT_LT(trace, at_end);
      checked_fix = true;
      break;
    }
    previous = trace;
  }
  EXPECT_TRUE(monotonic);
  EXPECT_TRUE(checked_fix);
  EXPECT_GT(at_end, 2.0 * at_start) << "from " << at_start << " to " << at_end;
  // The growth is deserved: the error at the end of the dropout is within it.
  const FilterStep* end = nullptr;
  for (const FilterStep& s : filter.log().steps)
    if (s.stamp_s - dc.t0_s < 69.9) end = &s;
  ASSERT_NE(end, nullptr);
  const size_t k = static_cast<size_t>(std::lround((end->stamp_s - dc.t0_s) * dc.fps));
  EXPECT_LT(positionNees(FilterState::from(end->stamp_s, end->x_posterior, end->P_posterior), dive.truth_at_images[k]),
            13.8);
}

TEST(NavigationFilter, RegistrationFailureFallsBackToDeadReckoning) {
  SyntheticDiveConfig dc;
  dc.duration_s = 80.0;
  dc.image_failures_s = {{30.0, 45.0}};
  dc.fix_dropouts_s = {{25.0, 50.0}};  // no fixes either: the DR alone carries the position
  dc.seed = 9;
  dc.model = FilterConfig();
  const SyntheticDive dive = makeSyntheticDive(dc);
  NavigationFilter filter(dc.model);
  filter.initialize(dc.t0_s, dive.initial_estimate, dive.initial_covariance);
  for (const NavEvent& e : dive.events) feed(filter, e);
  // Without DR, the same failure leaves the position to the no-motion random walk.
  SyntheticDiveConfig no_dr = dc;
  no_dr.with_dr = false;
  const SyntheticDive dive_no_dr = makeSyntheticDive(no_dr);
  NavigationFilter blind(dc.model);
  blind.initialize(dc.t0_s, dive_no_dr.initial_estimate, dive_no_dr.initial_covariance);
  for (const NavEvent& e : dive_no_dr.events) feed(blind, e);

  double worst_error = 0.0, worst_sigma = 0.0, worst_nees = 0.0;
  for (size_t k = 0; k < dive.image_stamps_s.size(); ++k) {
    const double t = dive.image_stamps_s[k] - dc.t0_s;
    if (t < 30.0 || t > 45.0) continue;
    for (const FilterStep& s : filter.log().steps) {
      if (s.stamp_s != dive.image_stamps_s[k]) continue;
      const FilterState fs = FilterState::from(s.stamp_s, s.x_posterior, s.P_posterior);
      worst_error = std::max(worst_error, (fs.position_en_m - dive.truth_at_images[k]).norm());
      worst_sigma = std::max(worst_sigma, std::sqrt(fs.position_covariance_m2.trace()));
      worst_nees = std::max(worst_nees, positionNees(fs, dive.truth_at_images[k]));
    }
  }
  // Moved by the DR over 6 m of track: errors of centimetres, covariance to match (not the no-motion walk's).
  EXPECT_LT(worst_error, 0.25);
  EXPECT_LT(worst_sigma, 0.3);
  EXPECT_LT(worst_nees, 20.0);
  const auto sigma_at = [&](const NavigationFilter& f, double t) {
    for (const FilterStep& s : f.log().steps)
      if (s.stamp_s - dc.t0_s >= t) return std::sqrt(s.P_posterior.block<2, 2>(0, 0).trace());
    return 0.0;
  };
  EXPECT_GT(sigma_at(blind, 44.9), 3.0 * sigma_at(filter, 44.9));
  EXPECT_GT(sigma_at(blind, 44.9), 1.0);
}

// A fusion restarted mid-dive resumes from the state it saved (its whole state, the dead-reckoning offset known):
// over the seconds it was down no image motion covers the time, and the first dead reckoning after the gap carries
// the position by its own increment. Started from the saved position and covariance alone, the first dead reckoning
// would set its offset from a position that is seconds stale instead.
TEST(NavigationFilter, ResumedFromASavedStateTheDeadReckoningCarriesThePositionOverTheGap) {
  SyntheticDiveConfig dc;
  dc.duration_s = 80.0;
  dc.seed = 21;
  dc.model = FilterConfig();
  const SyntheticDive dive = makeSyntheticDive(dc);
  const double crash_s = dc.t0_s + 40.0, back_s = dc.t0_s + 43.0;  // 3 s of inputs lost while the node restarts
  NavigationFilter before(dc.model);
  before.initialize(dc.t0_s, dive.initial_estimate, dive.initial_covariance);
  for (const NavEvent& e : dive.events)
    if (e.stamp_s < crash_s) feed(before, e);
  const FilterState saved = before.current();
  ASSERT_TRUE(before.drOffsetKnown());

  NavigationFilter resumed(dc.model), blind(dc.model);
  resumed.resume(saved.stamp_s, saved.x, saved.P, true);
  EXPECT_TRUE(resumed.drOffsetKnown());
  EXPECT_NEAR((resumed.current().position_en_m - saved.position_en_m).norm(), 0.0, 1e-12);
  blind.initialize(saved.stamp_s, saved.position_en_m, saved.position_covariance_m2);
  for (const NavEvent& e : dive.events) {
    if (e.stamp_s < back_s || (e.kind == NavEvent::kImage && e.previous_stamp_s < back_s)) continue;
    feed(resumed, e);
    feed(blind, e);
  }
  const auto error_at = [&](const NavigationFilter& f, double after_s, double* sigma_m) {
    for (size_t k = 0; k < dive.image_stamps_s.size(); ++k) {
      if (dive.image_stamps_s[k] < after_s) continue;
      for (const FilterStep& s : f.log().steps) {
        if (s.stamp_s != dive.image_stamps_s[k]) continue;
        const FilterState fs = FilterState::from(s.stamp_s, s.x_posterior, s.P_posterior);
        if (sigma_m) *sigma_m = std::sqrt(fs.position_covariance_m2.trace() / 2.0);
        return (fs.position_en_m - dive.truth_at_images[k]).norm();
      }
    }
    return std::nan("");
  };
  double sigma_m = 0.0;
  const double resumed_error_m = error_at(resumed, back_s + 1.0, &sigma_m);
  const double blind_error_m = error_at(blind, back_s + 1.0, nullptr);
  std::cout << "[ info     ] 1 s after a 3 s gap: resumed error " << resumed_error_m << " m (1-sigma " << sigma_m
            << " m), started from the position alone " << blind_error_m << " m" << std::endl;
  EXPECT_LT(resumed_error_m, 0.25);
  EXPECT_LT(sigma_m, 0.3);
  EXPECT_GT(blind_error_m, 3.0 * resumed_error_m);
  EXPECT_GT(blind_error_m, 0.5) << "the vehicle moved ~1.2 m while the node was down";
  // Invalid states are refused, leaving the filter as it was.
  StateMatrix bad = saved.P;
  bad(0, 1) += 1.0;
  EXPECT_THROW(resumed.resume(saved.stamp_s, saved.x, bad, true), std::invalid_argument);
  EXPECT_THROW(resumed.resume(std::nan(""), saved.x, saved.P, true), std::invalid_argument);
  EXPECT_TRUE(resumed.initialized());
}

TEST(NavigationFilter, ImageMotionAloneCarriesTheTrackFromAnOperatorPosition) {
  SyntheticDiveConfig dc;
  dc.duration_s = 60.0;
  dc.out_and_back = false;
  dc.with_dr = false;
  dc.with_fixes = false;
  dc.seed = 13;
  dc.model = FilterConfig();
  const SyntheticDive dive = makeSyntheticDive(dc);
  NavigationFilter filter(dc.model);
  filter.initialize(dc.t0_s, dive.initial_estimate, dive.initial_covariance);
  double previous_trace = 0.0;
  int k = 0;
  for (const NavEvent& e : dive.events) {
    ASSERT_EQ(feed(filter, e).status, UpdateStatus::kApplied);
    ++k;
    const FilterState s = filter.current();
    EXPECT_GE(s.position_covariance_m2.trace(), previous_trace - 1e-15);
    previous_trace = s.position_covariance_m2.trace();
  }
  const FilterState s = filter.current();
  EXPECT_NEAR(s.stamp_s, dive.image_stamps_s.back(), 1e-9);
  // Heading (0.01 rad) and pixel-size (1 %) errors over a 24 m line: decimetres, within the covariance.
  EXPECT_LT(positionNees(s, dive.truth_at_images.back()), 13.8);
  EXPECT_LT((s.position_en_m - dive.truth_at_images.back()).norm(), 0.5);
  EXPECT_GT(s.position_covariance_m2.trace(), dive.initial_covariance.trace());
}

TEST(NavigationFilter, InvalidInputsLeaveTheStateUntouched) {
  NavigationFilter filter{FilterConfig()};
  const Eigen::Matrix2d I = Eigen::Matrix2d::Identity();
  EXPECT_EQ(filter.addAbsoluteFix(1.0, Eigen::Vector2d(0, 0), I).status, UpdateStatus::kNotInitialized);
  EXPECT_EQ(filter.addDeadReckoning(1.0, Eigen::Vector2d(0, 0), I).status, UpdateStatus::kNotInitialized);
  EXPECT_EQ(filter.addImageMotion(0.8, 1.0, motionOf({0, 0}, 1e-3)).status, UpdateStatus::kNotInitialized);
  EXPECT_EQ(filter.addImageFailure(0.8, 1.0).status, UpdateStatus::kNotInitialized);
  EXPECT_THROW(filter.initialize(0.0, Eigen::Vector2d(std::nan(""), 0.0), I), std::invalid_argument);
  EXPECT_THROW(filter.initialize(0.0, Eigen::Vector2d(0.0, 0.0), -I), std::invalid_argument);

  filter.initialize(0.0, Eigen::Vector2d(0.0, 0.0), 0.01 * I);
  for (int k = 1; k <= 10; ++k) filter.addImageMotion((k - 1) * 0.2, k * 0.2, motionOf({0.05, 0.0}, 5e-4));
  filter.addDeadReckoning(2.0, Eigen::Vector2d(0.5, 0.0), I);
  const FilterState before = filter.current();
  const size_t steps = filter.log().steps.size();
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  const auto expect_invalid = [&](const UpdateResult& r, const std::string& words) {
    EXPECT_EQ(r.status, UpdateStatus::kInvalid) << r.detail;
    EXPECT_NE(r.detail.find(words), std::string::npos) << r.detail;
    EXPECT_EQ(filter.log().steps.size(), steps);
    EXPECT_LT((filter.current().x - before.x).norm(), 1e-15);
    EXPECT_LT((filter.current().P - before.P).norm(), 1e-15);
  };
  expect_invalid(filter.addAbsoluteFix(1.9, Eigen::Vector2d(nan, 0.0), I), "not finite");
  expect_invalid(filter.addAbsoluteFix(1.9, Eigen::Vector2d(0.4, 0.0), (Eigen::Matrix2d() << 1, 2, 2, 1).finished()),
                 "positive definite");
  expect_invalid(filter.addAbsoluteFix(1.9, Eigen::Vector2d(0.4, 0.0), inf * I), "not finite");
  expect_invalid(filter.addAbsoluteFix(nan, Eigen::Vector2d(0.4, 0.0), I), "stamp");
  expect_invalid(filter.addDeadReckoning(2.2, Eigen::Vector2d(0.5, inf), I), "not finite");
  expect_invalid(filter.addDeadReckoning(2.2, Eigen::Vector2d(0.5, 0.0), Eigen::Matrix2d::Zero()), "positive definite");
  expect_invalid(filter.addDeadReckoning(1.5, Eigen::Vector2d(0.5, 0.0), I), "stamp order");  // goes back
  MetricMotion invalid = motionOf({0.05, 0.0}, 5e-4);
  invalid.valid = false;
  invalid.error = "height <= 0";
  expect_invalid(filter.addImageMotion(2.0, 2.2, invalid), "addImageFailure");
  MetricMotion nan_motion = motionOf({nan, 0.0}, 5e-4);
  expect_invalid(filter.addImageMotion(2.0, 2.2, nan_motion), "not finite");
  MetricMotion singular = motionOf({0.05, 0.0}, 5e-4);
  singular.covariance_m2(1, 1) = 0.0;
  expect_invalid(filter.addImageMotion(2.0, 2.2, singular), "positive definite");
  expect_invalid(filter.addImageMotion(1.6, 1.8, motionOf({0.05, 0.0}, 5e-4)), "stamp order");  // goes back
  expect_invalid(filter.addImageMotion(2.2, 2.0, motionOf({0.05, 0.0}, 5e-4)), "before stamp_s");
  expect_invalid(filter.addImageMotion(2.0, 1.0e6, motionOf({0.05, 0.0}, 5e-4)), "max_prediction_gap_s");
  // A clock jump backwards beyond the window: invalid for the streams, too old for a fix; reset() starts again.
  expect_invalid(filter.addDeadReckoning(-50.0 + 3.0, Eigen::Vector2d(0.5, 0.0), I), "stamp order");
  EXPECT_EQ(filter.addAbsoluteFix(-50.0, Eigen::Vector2d(0.0, 0.0), I).status, UpdateStatus::kTooOld);
  filter.reset();
  EXPECT_FALSE(filter.initialized());
  EXPECT_TRUE(filter.log().steps.empty());
  EXPECT_EQ(filter.addAbsoluteFix(-50.0, Eigen::Vector2d(0.0, 0.0), I).status, UpdateStatus::kNotInitialized);
}

TEST(NavigationFilter, PredictedAtExtrapolatesWithoutChangingTheState) {
  NavigationFilter filter{FilterConfig()};
  filter.initialize(0.0, Eigen::Vector2d(0.0, 0.0), 0.01 * Eigen::Matrix2d::Identity());
  for (int k = 1; k <= 10; ++k) filter.addImageMotion((k - 1) * 0.2, k * 0.2, motionOf({0.08, 0.0}, 5e-4));
  const FilterState now = filter.current();
  const FilterState later = filter.predictedAt(2.5);
  EXPECT_DOUBLE_EQ(later.stamp_s, 2.5);
  EXPECT_NEAR(later.position_en_m.x(), now.position_en_m.x() + 0.2, 1e-9);  // 0.4 m/s for 0.5 s
  EXPECT_GT(later.position_covariance_m2.trace(), now.position_covariance_m2.trace());
  EXPECT_LT((filter.current().x - now.x).norm(), 1e-15);
  EXPECT_DOUBLE_EQ(filter.predictedAt(1.0).stamp_s, now.stamp_s);  // not later: the current state
}

/// A minute's dive for a filter whose history window is 4 s, and two filters of that model started on it.
struct ShortWindowDive {
  explicit ShortWindowDive(unsigned seed) {
    dc.duration_s = 60.0;
    dc.seed = seed;
    dc.model = FilterConfig();
    dc.model.history_s = 4.0;
    dive = makeSyntheticDive(dc);
  }
  void start(NavigationFilter* filter) const {
    filter->initialize(dc.t0_s, dive.initial_estimate, dive.initial_covariance);
  }
  SyntheticDiveConfig dc;
  SyntheticDive dive;
};

TEST(NavigationFilter, LogOffKeepsOnlyTheWindowAndGivesTheSameEstimates) {
  const ShortWindowDive d(21);
  const SyntheticDive& dive = d.dive;
  NavigationFilter full(d.dc.model), bounded(d.dc.model);
  bounded.setKeepLog(false);
  d.start(&full);
  d.start(&bounded);
  size_t largest = 0;
  for (const NavEvent& e : dive.events) {
    const UpdateResult a = feed(full, e), b = feed(bounded, e);
    EXPECT_EQ(a.status, b.status);
    largest = std::max(largest, bounded.log().steps.size());
  }
  EXPECT_LT((full.current().x - bounded.current().x).norm(), 1e-12);
  EXPECT_GT(full.log().steps.size(), 600u);
  EXPECT_LT(largest, 4.0 * 16 + 20);  // 4 s of 10 DR + 5 image + 1 fix stamps, and a margin
}

TEST(NavigationFilter, LogWrittenOutStaysBoundedInMemoryAndReadsBackWhole) {
  const ShortWindowDive d(22);
  const SyntheticDive& dive = d.dive;
  const std::string path = (std::filesystem::temp_directory_path() / "exocet_test_filter_steps.bin").string();
  NavigationFilter full(d.dc.model), written(d.dc.model);
  written.setLogFile(path);
  d.start(&full);
  d.start(&written);
  size_t largest = 0;
  for (const NavEvent& e : dive.events) {
    feed(full, e);
    feed(written, e);  // out-of-sequence fixes included: a rewind never reaches the written steps
    largest = std::max(largest, written.log().steps.size());
  }
  EXPECT_LT(largest, 4.0 * 16 + 20);
  EXPECT_GT(written.loggedToFile(), 500u);
  EXPECT_EQ(std::filesystem::file_size(path), written.loggedToFile() * FilterStepFile::recordBytes());
  const FilterLog whole = written.wholeLog();
  ASSERT_EQ(whole.steps.size(), full.log().steps.size());
  for (size_t i = 0; i < whole.steps.size(); ++i) {
    const FilterStep &a = whole.steps[i], &b = full.log().steps[i];
    ASSERT_EQ(a.stamp_s, b.stamp_s) << i;
    EXPECT_EQ(a.x_posterior, b.x_posterior) << i;
    EXPECT_EQ(a.P_prior, b.P_prior) << i;
    EXPECT_EQ(a.transition, b.transition) << i;
    EXPECT_EQ(a.image_motion, b.image_motion) << i;
    EXPECT_EQ(a.fixes_applied, b.fixes_applied) << i;
    EXPECT_EQ(a.dr_initialized, b.dr_initialized) << i;
  }
  // Back to memory: the written steps return, the file goes.
  written.setLogFile("");
  EXPECT_EQ(written.log().steps.size(), full.log().steps.size());
  EXPECT_FALSE(std::filesystem::exists(path));
  EXPECT_THROW(written.setLogFile("/proc/exocet_no_such_folder/steps.bin"), std::runtime_error);
}

TEST(NavigationFilter, ConsistentOnDivesGeneratedFromItsModel) {
  // Monte Carlo: the average over runs of the position NEES at each image epoch lies in the two-sided 95 %
  // interval of a chi-square with 2 x runs dof divided by runs (Bar-Shalom's consistency test).
  const int runs = 24;
  SyntheticDiveConfig dc;
  dc.duration_s = 80.0;
  dc.fix_outlier_probability = 0.0;
  dc.model = FilterConfig();
  // The registration's extra noise anisotropic, as measured on the simulated dives (larger across the motion).
  dc.model.image_step_noise_along_m = 0.0004;
  dc.model.image_step_noise_across_m = 0.002;
  dc.dr_scale_sigma = dc.model.initial_dr_scale_sigma;
  std::vector<double> sum_nees;
  for (int run = 0; run < runs; ++run) {
    dc.seed = 100 + run;
    const SyntheticDive dive = makeSyntheticDive(dc);
    NavigationFilter filter(dc.model);
    filter.initialize(dc.t0_s, dive.initial_estimate, dive.initial_covariance);
    for (const NavEvent& e : dive.events) feed(filter, e);
    sum_nees.resize(dive.image_stamps_s.size(), 0.0);
    size_t k = 0;
    for (const FilterStep& s : filter.log().steps) {
      while (k < dive.image_stamps_s.size() && dive.image_stamps_s[k] < s.stamp_s) ++k;
      if (k == dive.image_stamps_s.size()) break;
      if (s.stamp_s != dive.image_stamps_s[k]) continue;
      sum_nees[k] += positionNees(FilterState::from(s.stamp_s, s.x_posterior, s.P_posterior), dive.truth_at_images[k]);
    }
  }
  const double lower = chiSquareQuantile(2.0 * runs, -1.95996) / runs;
  const double upper = chiSquareQuantile(2.0 * runs, 1.95996) / runs;
  int inside = 0;
  double mean = 0.0;
  for (double s : sum_nees) {
    const double avg = s / runs;
    inside += avg >= lower && avg <= upper;
    mean += avg / sum_nees.size();
  }
  const double fraction = double(inside) / sum_nees.size();
  EXPECT_GT(fraction, 0.9) << "bounds [" << lower << ", " << upper << "], mean NEES " << mean;
  EXPECT_NEAR(mean, 2.0, 0.3);
}
