// Cross-pass batch smoother (Ceres): relative constraints between the return and the outbound passes align them.
#include <cmath>
#include <iostream>

#include <gtest/gtest.h>

#include "exocet_mosaic/fusion/cross_pass_smoother.h"
#include "exocet_mosaic/fusion/navigation_filter.h"
#include "exocet_mosaic/fusion/rts_smoother.h"
#include "fusion_fixtures.h"

namespace {

using namespace exocet_mosaic::fusion;
using namespace exocet_mosaic::fusion::testing;

struct Scenario {
  SyntheticDive dive;
  FilterLog log;
  std::vector<FilterState> smoothed;
  std::vector<int> frame_step;  ///< log step of each image
  std::vector<AbsoluteConstraint> fixes;
  std::vector<std::pair<int, int>> pairs;  ///< (return image, nearest outbound image)
};

Scenario makeScenario() {
  SyntheticDiveConfig dc;
  dc.duration_s = 200.0;
  dc.image_sigma_m = 0.002;
  dc.heading_drift_sigma_rps = 4e-4;
  dc.seed = 31;
  dc.model = FilterConfig();
  Scenario s;
  s.dive = makeSyntheticDive(dc);
  NavigationFilter filter(dc.model);
  filter.initialize(dc.t0_s, s.dive.initial_estimate, s.dive.initial_covariance);
  for (const NavEvent& e : s.dive.events) {
    feed(filter, e);
    if (e.kind == NavEvent::kFix) s.fixes.push_back({e.stamp_s, e.value, e.covariance});
  }
  s.log = filter.log();
  s.smoothed = smoothRts(s.log);
  const size_t n = s.dive.image_stamps_s.size();
  s.frame_step.assign(n, -1);
  for (size_t i = 0, k = 0; i < s.log.steps.size() && k < n; ++i)
    if (s.log.steps[i].stamp_s == s.dive.image_stamps_s[k]) s.frame_step[k++] = static_cast<int>(i);
  const size_t half = n / 2;
  for (size_t r = half + 10; r < n; r += 5) {
    size_t best = 0;
    for (size_t o = 0; o + 10 < half; ++o)
      if ((s.dive.truth_at_images[o] - s.dive.truth_at_images[r]).norm() <
          (s.dive.truth_at_images[best] - s.dive.truth_at_images[r]).norm())
        best = o;
    if ((s.dive.truth_at_images[best] - s.dive.truth_at_images[r]).norm() < 0.5) s.pairs.emplace_back(r, best);
  }
  return s;
}

/// Median of |(est_r - est_o) - (true_r - true_o)| over the pairs.
double medianMisalignment(const Scenario& s, const std::vector<Eigen::Vector2d>& at_step) {
  std::vector<double> e;
  for (const auto& [r, o] : s.pairs) {
    const Eigen::Vector2d est = at_step[s.frame_step[r]] - at_step[s.frame_step[o]];
    e.push_back((est - (s.dive.truth_at_images[r] - s.dive.truth_at_images[o])).norm());
  }
  std::sort(e.begin(), e.end());
  return e[e.size() / 2];
}

}  // namespace

TEST(CrossPassSmoother, RelativeConstraintsAlignTheReturnPass) {
  const Scenario s = makeScenario();
  ASSERT_GT(s.pairs.size(), 50u);
  std::vector<Eigen::Vector2d> rts;
  for (const FilterState& f : s.smoothed) rts.push_back(f.position_en_m);
  const double before = medianMisalignment(s, rts);

  std::mt19937 rng(2);
  std::normal_distribution<double> n01;
  std::vector<RelativeConstraint> cross;
  for (const auto& [r, o] : s.pairs) {
    RelativeConstraint c;
    c.from_stamp_s = s.dive.image_stamps_s[o];
    c.to_stamp_s = s.dive.image_stamps_s[r];
    c.delta_en_m = s.dive.truth_at_images[r] - s.dive.truth_at_images[o] + Eigen::Vector2d(1e-3 * n01(rng), 1e-3 * n01(rng));
    c.covariance_m2 = 1e-6 * Eigen::Matrix2d::Identity();
    cross.push_back(c);
  }
  // One wrong registration: 40 cm off. The Huber loss keeps it from bending the track.
  cross[cross.size() / 2].delta_en_m += Eigen::Vector2d(0.4, 0.0);

  const CrossPassResult result = smoothWithCrossPassConstraints(s.log, s.smoothed, s.fixes, cross);
  EXPECT_TRUE(result.converged) << result.message;
  EXPECT_EQ(result.relative_used, static_cast<int>(cross.size()));
  EXPECT_EQ(result.absolute_used, static_cast<int>(s.fixes.size()));
  ASSERT_EQ(result.positions_en_m.size(), s.log.steps.size());
  const double after = medianMisalignment(s, result.positions_en_m);
  std::cout << "median pass misalignment: RTS " << 1000.0 * before << " mm, with the constraints " << 1000.0 * after
            << " mm\n";
  EXPECT_GT(before, 0.01) << "the scenario must start misaligned";
  EXPECT_LT(after, 0.003) << "before " << before;
  EXPECT_LT(after, 0.2 * before);
  // The absolute track stays as good as the RTS one.
  double rts_sq = 0.0, cross_sq = 0.0;
  for (size_t k = 0; k < s.frame_step.size(); ++k) {
    rts_sq += (rts[s.frame_step[k]] - s.dive.truth_at_images[k]).squaredNorm();
    cross_sq += (result.positions_en_m[s.frame_step[k]] - s.dive.truth_at_images[k]).squaredNorm();
  }
  EXPECT_LT(cross_sq, 1.5 * rts_sq);
}

TEST(CrossPassSmoother, WithoutRelativeConstraintsStaysNearTheRtsSolution) {
  const Scenario s = makeScenario();
  const CrossPassResult result = smoothWithCrossPassConstraints(s.log, s.smoothed, s.fixes, {});
  EXPECT_TRUE(result.converged) << result.message;
  double worst = 0.0;
  for (size_t i = 0; i < s.smoothed.size(); ++i)
    worst = std::max(worst, (result.positions_en_m[i] - s.smoothed[i].position_en_m).norm());
  EXPECT_LT(worst, 0.1);
}

TEST(CrossPassSmoother, RejectsMismatchedInput) {
  const Scenario s = makeScenario();
  std::vector<FilterState> short_list(s.smoothed.begin(), s.smoothed.end() - 1);
  EXPECT_THROW(smoothWithCrossPassConstraints(s.log, short_list, s.fixes, {}), std::invalid_argument);
  CrossPassSmootherConfig bad;
  bad.max_iterations = 0;
  EXPECT_NE(bad.validate().find("max_iterations"), std::string::npos);
  EXPECT_THROW(smoothWithCrossPassConstraints(s.log, s.smoothed, s.fixes, {}, bad), std::invalid_argument);
  const CrossPassResult empty = smoothWithCrossPassConstraints(FilterLog(), {}, {}, {});
  EXPECT_TRUE(empty.positions_en_m.empty());
}
