// The 2-D pose graph (graph/pose_graph.h, graph/background_pose_graph.h): exact answers of small graphs, the
// switchable loops, the interpolated position fixes, the windowed solve, the background worker, bad input.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <functional>
#include <mutex>
#include <random>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include <Eigen/Dense>

#include "exocet_mosaic/graph/background_pose_graph.h"
#include "exocet_mosaic/graph/pose_graph.h"

namespace exocet_mosaic {
namespace graph {
namespace {

constexpr double kPi = 3.14159265358979323846;

Pose2d poseOf(double e, double n, double yaw) {
  Pose2d p;
  p.position_en_m = Eigen::Vector2d(e, n);
  p.yaw_rad = yaw;
  return p;
}

Eigen::Matrix3d diag3(double sigma_m, double sigma_rad) {
  return Eigen::Vector3d(sigma_m * sigma_m, sigma_m * sigma_m, sigma_rad * sigma_rad).asDiagonal();
}

Eigen::Matrix2d diag2(double sigma_m) { return Eigen::Matrix2d::Identity() * sigma_m * sigma_m; }

/// Expects `f` to throw std::invalid_argument whose message contains `needle`.
void expectInvalid(const std::function<void()>& f, const std::string& needle) {
  try {
    f();
    ADD_FAILURE() << "no std::invalid_argument; expected one mentioning '" << needle << "'";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << "message: " << e.what();
  }
}

TEST(PoseGraph, WrapAngleIsHalfOpenInterval) {
  EXPECT_DOUBLE_EQ(wrapAngle(kPi), kPi);
  EXPECT_DOUBLE_EQ(wrapAngle(-kPi), kPi);
  EXPECT_NEAR(wrapAngle(3 * kPi + 0.1), -kPi + 0.1, 1e-12);
  EXPECT_NEAR(wrapAngle(-0.2), -0.2, 1e-15);
  const Pose2d a = poseOf(1, 2, 0.3), b = poseOf(-4, 5, -2.9);
  const Pose2d back = compose(a, between(a, b));
  EXPECT_NEAR((back.position_en_m - b.position_en_m).norm(), 0.0, 1e-12);
  EXPECT_NEAR(wrapAngle(back.yaw_rad - b.yaw_rad), 0.0, 1e-12);
}

// A unit square driven counter-clockwise with exact odometry and a closing loop, started from perturbed poses:
// the solution is the square, held at the first key frame by the gauge prior.
TEST(PoseGraph, SquareWithLoopConvergesToExactSquare) {
  const std::vector<Pose2d> truth = {poseOf(0, 0, 0), poseOf(1, 0, kPi / 2), poseOf(1, 1, kPi), poseOf(0, 1, -kPi / 2)};
  PoseGraphConfig config;
  config.window_policy = PoseGraphConfig::WindowPolicy::kFull;
  PoseGraph g(config);
  const std::vector<Eigen::Vector3d> perturb = {{0, 0, 0}, {0.2, -0.1, 0.1}, {-0.15, 0.2, -0.2}, {0.1, 0.1, 0.15}};
  for (int k = 0; k < 4; ++k) {
    Pose2d initial = truth[k];
    initial.position_en_m += perturb[k].head<2>();
    initial.yaw_rad += perturb[k].z();
    g.addKeyFrame(10 + k, 100.0 + k, initial);
  }
  for (int k = 0; k < 3; ++k) g.addOdometry(10 + k, 11 + k, between(truth[k], truth[k + 1]), diag3(0.05, 0.01));
  const int loop = g.addLoop(13, 10, between(truth[3], truth[0]), diag3(0.05, 0.01));
  const SolveReport report = g.solve();
  EXPECT_TRUE(report.converged) << report.message;
  EXPECT_TRUE(report.full);
  for (int k = 0; k < 4; ++k) {
    const Pose2d p = g.pose(10 + k);
    EXPECT_NEAR((p.position_en_m - truth[k].position_en_m).norm(), 0.0, 1e-6) << "key frame " << k;
    EXPECT_NEAR(wrapAngle(p.yaw_rad - truth[k].yaw_rad), 0.0, 1e-6) << "key frame " << k;
  }
  EXPECT_TRUE(g.loopAccepted(loop));
  EXPECT_NEAR(g.loop(loop).switch_value, 1.0, 1e-6);
  EXPECT_EQ(report.loops_accepted, 1);
  EXPECT_EQ(report.loops_rejected, 0);
}

// Three key frames along east, inconsistent odometry and two fixes (one between key frames 0 and 1), plain least
// squares: the east coordinates are the solution of a 3x3 linear system, north and yaw stay 0.
TEST(PoseGraph, TwoFixesMatchDenseLeastSquares) {
  PoseGraphConfig config;
  config.position_fix_cauchy_scale = 0.0;  // plain least squares: the answer is linear
  config.window_policy = PoseGraphConfig::WindowPolicy::kFull;
  PoseGraph g(config);
  const double sigma_odo = 0.1, sigma_fix = 0.3;
  g.addKeyFrame(0, 0.0, poseOf(0.3, 0.2, 0.05));
  g.addKeyFrame(1, 1.0, poseOf(1.1, -0.3, -0.04));
  g.addKeyFrame(2, 2.0, poseOf(2.4, 0.25, 0.03));
  RelativePose2d d1, d2;
  d1.translation_m = Eigen::Vector2d(1.0, 0.0);
  d2.translation_m = Eigen::Vector2d(1.2, 0.0);
  g.addOdometry(0, 1, d1, diag3(sigma_odo, 0.01));
  g.addOdometry(1, 2, d2, diag3(sigma_odo, 0.01));
  for (int k = 0; k < 3; ++k) g.addHeading(k, 0.0, 0.02);
  EXPECT_TRUE(g.addPositionFix(0.5, Eigen::Vector2d(0.4, 0.0), diag2(sigma_fix)));
  EXPECT_TRUE(g.addPositionFix(2.0, Eigen::Vector2d(2.5, 0.0), diag2(sigma_fix)));
  EXPECT_EQ(g.numPositionFixes(), 2u);
  const SolveReport report = g.solve();
  EXPECT_TRUE(report.converged) << report.message;

  // Rows of the whitened linear system J x = b over (x0, x1, x2).
  Eigen::Matrix<double, 4, 3> J;
  Eigen::Vector4d b;
  J << -1, 1, 0, 0, -1, 1, 0.5, 0.5, 0, 0, 0, 1;
  b << 1.0, 1.2, 0.4, 2.5;
  J.topRows<2>() /= sigma_odo;
  b.head<2>() /= sigma_odo;
  J.bottomRows<2>() /= sigma_fix;
  b.tail<2>() /= sigma_fix;
  const Eigen::Matrix3d normal = J.transpose() * J;
  const Eigen::Vector3d x = normal.ldlt().solve(J.transpose() * b);
  for (int k = 0; k < 3; ++k) {
    const Pose2d p = g.pose(k);
    EXPECT_NEAR(p.position_en_m.x(), x(k), 1e-6) << "key frame " << k;
    EXPECT_NEAR(p.position_en_m.y(), 0.0, 1e-6) << "key frame " << k;
    EXPECT_NEAR(p.yaw_rad, 0.0, 1e-6) << "key frame " << k;
  }
  // East is decoupled from north and yaw at this solution: its marginal variance is that of the linear system, with
  // the weak prior the marginals put on every key frame (a direction nothing constrains has a 1-sigma).
  const Eigen::Matrix3d normal_with_priors =
      normal + Eigen::Matrix3d::Identity() / (config.gauge_sigma_m * config.gauge_sigma_m);
  const Eigen::Matrix3d inverse = normal_with_priors.inverse();
  for (int k = 0; k < 3; ++k) {
    const std::optional<Eigen::Matrix3d> c = g.covariance(k);
    ASSERT_TRUE(c.has_value());
    EXPECT_NEAR((*c)(0, 0), inverse(k, k), 1e-9 + 1e-6 * inverse(k, k)) << "key frame " << k;
  }
  // All the key frames' position blocks at once: the same east variances, and each the 3x3 block's corner.
  const std::vector<Eigen::Matrix2d> positions = g.positionCovariances();
  ASSERT_EQ(positions.size(), 3u);
  for (int k = 0; k < 3; ++k) {
    EXPECT_NEAR(positions[k](0, 0), inverse(k, k), 1e-9 + 1e-6 * inverse(k, k)) << "key frame " << k;
    EXPECT_TRUE(positions[k].isApprox(g.covariance(k)->topLeftCorner<2, 2>(), 1e-9)) << "key frame " << k;
  }
}

/// Truth and noisy odometry of an out-and-back: out east along north = 0, back west along north = 2 m.
struct OutAndBack {
  std::vector<Pose2d> truth;
  std::vector<RelativePose2d> odometry;  ///< k -> k + 1
  std::vector<double> headings_rad;      ///< attitude sensor, 1-sigma heading_sigma_rad
  double sigma_m = 0.01, sigma_rad = 0.002, heading_sigma_rad = 0.005;
  explicit OutAndBack(int per_leg = 41, unsigned seed = 7) {
    for (int k = 0; k < per_leg; ++k) truth.push_back(poseOf(k, 0, 0));
    for (int k = 0; k < per_leg; ++k) truth.push_back(poseOf(per_leg - 1 - k, 2, kPi));
    std::mt19937 rng(seed);
    std::normal_distribution<double> normal;
    for (size_t k = 0; k + 1 < truth.size(); ++k) {
      RelativePose2d d = between(truth[k], truth[k + 1]);
      d.translation_m += sigma_m * Eigen::Vector2d(normal(rng), normal(rng));
      d.yaw_rad += sigma_rad * normal(rng);
      odometry.push_back(d);
    }
    for (const Pose2d& p : truth) headings_rad.push_back(p.yaw_rad + heading_sigma_rad * normal(rng));
  }
  /// The graph with the odometry (and the headings), key frames initialised by chaining it, key frame 0 at the
  /// truth.
  void fill(PoseGraph* g, bool with_headings = false) const {
    Pose2d p = truth[0];
    for (size_t k = 0; k < truth.size(); ++k) {
      if (k > 0) p = compose(p, odometry[k - 1]);
      g->addKeyFrame(static_cast<int64_t>(k), 0.4 * k, p);
    }
    for (size_t k = 0; k + 1 < truth.size(); ++k) g->addOdometry(k, k + 1, odometry[k], diag3(sigma_m, sigma_rad));
    if (with_headings)
      for (size_t k = 0; k < truth.size(); ++k) g->addHeading(k, headings_rad[k], heading_sigma_rad);
  }
  double maxError(const PoseGraph& g) const {
    double e = 0.0;
    for (size_t k = 0; k < truth.size(); ++k)
      e = std::max(e, (g.pose(static_cast<int64_t>(k)).position_en_m - truth[k].position_en_m).norm());
    return e;
  }
};

// With a cap on the key frames computed, the computed ones (evenly spread, the first and the last) are exact and the
// others are interpolated between them: along an odometry chain with fixes the variance varies smoothly.
TEST(PoseGraph, PositionCovariancesWithACapInterpolateBetweenComputedKeyFrames) {
  const OutAndBack run;
  PoseGraph g;
  run.fill(&g, true);
  for (size_t k = 0; k < run.truth.size(); k += 10)
    EXPECT_TRUE(g.addPositionFix(0.4 * k, run.truth[k].position_en_m, diag2(0.05)));
  ASSERT_TRUE(g.solveFull().converged);
  const std::vector<Eigen::Matrix2d> every = g.positionCovariances();
  const std::vector<Eigen::Matrix2d> capped = g.positionCovariances(12);
  const int n = static_cast<int>(run.truth.size());
  ASSERT_EQ(every.size(), static_cast<size_t>(n));
  ASSERT_EQ(capped.size(), static_cast<size_t>(n));
  // 82 key frames, at most 12 computed: a stride of 9 (0, 9, ..., 81).
  double max_relative = 0.0;
  for (int k = 0; k < n; ++k) {
    const double exact = std::sqrt(every[k].trace()), approximate = std::sqrt(capped[k].trace());
    if (k % 9 == 0 || k == n - 1) {
      EXPECT_TRUE(capped[k].isApprox(every[k], 1e-9)) << "computed key frame " << k;
    }
    max_relative = std::max(max_relative, std::abs(approximate - exact) / exact);
  }
  EXPECT_GT(max_relative, 0.0) << "nothing was interpolated";
  EXPECT_LT(max_relative, 0.25);
  EXPECT_EQ(g.positionCovariances(1000).size(), static_cast<size_t>(n));
}

// One fix and no heading leave the graph free to turn about the fix: the marginals still exist (the weak priors'),
// small at the fix and as large as that turn makes them at the far end.
TEST(PoseGraph, PositionCovariancesOfAGraphFreeToTurnAboutItsFix) {
  const OutAndBack run;
  PoseGraph g;
  run.fill(&g, false);
  EXPECT_TRUE(g.addPositionFix(0.0, run.truth[0].position_en_m, diag2(0.05)));
  ASSERT_TRUE(g.solveFull().converged);
  const std::vector<Eigen::Matrix2d> marginals = g.positionCovariances();
  ASSERT_EQ(marginals.size(), run.truth.size());
  EXPECT_LT(std::sqrt(marginals.front().trace()), 0.1);
  EXPECT_GT(std::sqrt(marginals[40].trace()), 10.0) << "40 m from the fix, turning freely (3 rad prior)";
}

// A false loop 1 m off with a 5 mm 1-sigma is switched off and does not bend the map; the true loops in the same
// graph are accepted and remove most of the drift. Odometry alone first (a long yaw drift), then with headings.
class LoopRejection : public ::testing::TestWithParam<bool> {};

TEST_P(LoopRejection, FalseLoopRejectedTrueLoopAccepted) {
  const bool with_headings = GetParam();
  const OutAndBack run;
  const int n = static_cast<int>(run.truth.size());
  PoseGraphConfig config;
  config.window_policy = PoseGraphConfig::WindowPolicy::kFull;

  PoseGraph odometry_only(config);
  run.fill(&odometry_only, with_headings);
  odometry_only.solve();
  const double drift_m = run.maxError(odometry_only);

  const auto add_true_loops = [&](PoseGraph* g) {
    std::vector<int> loops;
    for (const int k : {0, 10, 30}) {
      const int j = n - 1 - k;  // same east on the way back
      loops.push_back(g->addLoop(k, j, between(run.truth[k], run.truth[j]), diag3(0.01, 0.002)));
    }
    return loops;
  };
  PoseGraph with_true(config);
  run.fill(&with_true, with_headings);
  add_true_loops(&with_true);
  with_true.solve();

  PoseGraph g(config);
  run.fill(&g, with_headings);
  const std::vector<int> true_loops = add_true_loops(&g);
  RelativePose2d false_delta = between(run.truth[20], run.truth[n - 21]);
  false_delta.translation_m.x() += 1.0;
  const int false_loop = g.addLoop(20, n - 21, false_delta, diag3(0.005, 0.001));
  const SolveReport report = g.solve();

  EXPECT_FALSE(g.loopAccepted(false_loop)) << "switch " << g.loop(false_loop).switch_value;
  EXPECT_LT(g.loop(false_loop).switch_value, 0.1);
  for (const int l : true_loops) EXPECT_TRUE(g.loopAccepted(l)) << "loop " << l << " switch " << g.loop(l).switch_value;
  EXPECT_EQ(report.loops_accepted, 3);
  EXPECT_EQ(report.loops_rejected, 1);
  double bend_m = 0.0;
  for (int k = 0; k < n; ++k)
    bend_m = std::max(bend_m, (g.pose(k).position_en_m - with_true.pose(k).position_en_m).norm());
  const double error_m = run.maxError(g);
  std::cout << "out-and-back" << (with_headings ? " with headings" : "") << ": drift without loops " << drift_m
            << " m, with loops " << error_m << " m, false loop bends the map by " << bend_m << " m (switch "
            << g.loop(false_loop).switch_value << ")\n";
  EXPECT_LT(bend_m, 0.02);
  EXPECT_LT(error_m, 0.5 * drift_m);
  // With headings the map is within the along-track random walk of the odometry (1 cm per step) of the truth.
  if (with_headings) {
    EXPECT_LT(error_m, 0.1);
  }
}

INSTANTIATE_TEST_SUITE_P(PoseGraph, LoopRejection, ::testing::Values(false, true),
                         [](const ::testing::TestParamInfo<bool>& info) {
                           return info.param ? "WithHeadings" : "OdometryOnly";
                         });

// A fix at 2.25 s between key frames 2 (2 s) and 3 (3 s) pulls those two, key frame 2 (weight 0.75) the most.
TEST(PoseGraph, InterpolatedFixPullsTheTwoKeyFramesAroundIt) {
  PoseGraphConfig config;
  config.position_fix_cauchy_scale = 0.0;
  PoseGraph g(config);
  for (int k = 0; k < 6; ++k) g.addKeyFrame(k, k, poseOf(k, 0, 0));
  RelativePose2d step;
  step.translation_m = Eigen::Vector2d(1, 0);
  for (int k = 0; k < 5; ++k) g.addOdometry(k, k + 1, step, diag3(0.2, 0.01));
  for (int k = 0; k < 6; ++k) g.addHeading(k, 0.0, 0.01);
  g.addPositionFix(0.0, Eigen::Vector2d(0, 0), diag2(0.01));
  g.addPositionFix(5.0, Eigen::Vector2d(5, 0), diag2(0.01));
  g.solveFull();
  // The fix arrives after its key frames (a late USBL message) and the window policy solves around it.
  g.addPositionFix(2.25, Eigen::Vector2d(2.25, 0.5), diag2(0.05));
  const SolveReport report = g.solve();
  EXPECT_TRUE(report.converged) << report.message;
  std::vector<double> north(6);
  for (int k = 0; k < 6; ++k) north[k] = g.pose(k).position_en_m.y();
  EXPECT_GT(north[2], north[3]);
  EXPECT_GT(north[3], north[1]);
  EXPECT_GT(north[3], north[4]);
  EXPECT_GT(north[2], 0.1);
  EXPECT_NEAR(north[0], 0.0, 0.01);
  EXPECT_NEAR(north[5], 0.0, 0.01);
  const double interpolated = 0.75 * north[2] + 0.25 * north[3];
  EXPECT_GT(interpolated, 0.25) << "the fix should win over loose odometry";

  // A fix after the last key frame waits for the next one and is then interpolated between key frames 5 and 6.
  EXPECT_TRUE(g.addPositionFix(5.5, Eigen::Vector2d(5.5, -0.5), diag2(0.05)));
  EXPECT_EQ(g.numPendingPositionFixes(), 1u);
  g.addKeyFrame(6, 6.0, poseOf(6, 0, 0));
  EXPECT_EQ(g.numPendingPositionFixes(), 0u);
  EXPECT_EQ(g.numPositionFixes(), 4u);
  g.addOdometry(5, 6, step, diag3(0.2, 0.01));
  g.solve();
  // Key frame 5 is held by the fix at 5 s: key frame 6 takes the pull.
  EXPECT_LT(g.pose(6).position_en_m.y(), -0.5);
  EXPECT_NEAR(g.pose(5).position_en_m.y(), 0.0, 0.01);
  // Before the first key frame: dropped.
  EXPECT_FALSE(g.addPositionFix(-1.0, Eigen::Vector2d(0, 0), diag2(0.05)));
}

// A hand-built case: a prior on key frame 0 and two relative positions, each in the axes of the key frame before
// (turned by its yaw, which the headings hold), place the three key frames exactly.
TEST(PoseGraph, RelativePositionsInTheEarlierKeyFramesAxes) {
  PoseGraph g;
  const double yaw = M_PI / 2;  // x axis to the north
  for (int k = 0; k < 3; ++k) {
    g.addKeyFrame(k, k, poseOf(0.3 * k, -0.2 * k, yaw + 0.1));  // started off
    g.addHeading(k, yaw, 1e-4);
  }
  g.addPositionFix(0.0, Eigen::Vector2d(1, 2), diag2(0.01), false);
  g.addRelativePosition(0, 1, Eigen::Vector2d(1, 0), diag2(0.01));
  g.addRelativePosition(1, 2, Eigen::Vector2d(2, 0.5), diag2(0.01));
  EXPECT_EQ(g.numRelativePositions(), 2u);
  const SolveReport report = g.solveFull();
  EXPECT_TRUE(report.converged) << report.message;
  EXPECT_NEAR(g.pose(1).position_en_m.x(), 1.0, 1e-6);
  EXPECT_NEAR(g.pose(1).position_en_m.y(), 3.0, 1e-6);
  EXPECT_NEAR(g.pose(2).position_en_m.x(), 0.5, 1e-6);  // 0.5 to the left of the north-facing x axis: west
  EXPECT_NEAR(g.pose(2).position_en_m.y(), 5.0, 1e-6);
  EXPECT_THROW(g.addRelativePosition(2, 1, Eigen::Vector2d(1, 0), diag2(0.01)), std::invalid_argument);
  EXPECT_THROW(g.addRelativePosition(0, 7, Eigen::Vector2d(1, 0), diag2(0.01)), std::invalid_argument);
  EXPECT_THROW(g.addRelativePosition(0, 1, Eigen::Vector2d(std::nan(""), 0), diag2(0.01)), std::invalid_argument);
  EXPECT_THROW(g.addRelativePosition(0, 1, Eigen::Vector2d(1, 0), -diag2(0.01)), std::invalid_argument);
}

// A prior added as not robust keeps its weight however far the fixes' average pulls: 391 fixes of 0.5 m, all 0.6 m
// east (their average's 1-sigma, 2.5 cm, against a 1 cm prior), on a rigid track. The fixes under their Cauchy loss
// (weight w = 1 / (1 + (e / 0.5)^2 / 9) at an error e) and the prior at full weight put the track at
// x = 0.6 * 1564 w / (1564 w + 10000), 7.3 cm east; a robust prior, 7 of its sigmas off, loses its hold.
TEST(PoseGraph, APriorNotRobustKeepsItsWeightAgainstTheFixes) {
  for (const bool robust : {false, true}) {
    PoseGraph g;
    RelativePose2d step;
    step.translation_m = Eigen::Vector2d(0.1, 0);
    for (int k = 0; k < 40; ++k) {
      g.addKeyFrame(k, k, poseOf(0.1 * k, 0, 0));
      if (k > 0) g.addOdometry(k - 1, k, step, diag3(1e-5, 1e-6));
      g.addHeading(k, 0.0, 1e-4);
    }
    g.addPositionFix(0.0, Eigen::Vector2d(0, 0), diag2(0.01), robust);
    for (int i = 0; i <= 390; ++i) g.addPositionFix(0.1 * i, Eigen::Vector2d(0.01 * i + 0.6, 0), diag2(0.5));
    g.solveFull();
    const double east_m = g.pose(0).position_en_m.x();
    double expected_m = 0.0;
    for (int iteration = 0; iteration < 50; ++iteration) {
      const double w = 1.0 / (1.0 + std::pow((0.6 - expected_m) / 0.5, 2) / 9.0);
      expected_m = 0.6 * 1564 * w / (1564 * w + 10000);
    }
    if (robust)
      EXPECT_GT(east_m, 0.2) << "under the Cauchy loss";
    else
      EXPECT_NEAR(east_m, expected_m, 0.001);
  }
}

// The Cauchy loss: a 20-sigma outlier fix among good ones barely moves the track.
TEST(PoseGraph, OutlierFixHasLittlePull) {
  PoseGraph g;
  RelativePose2d step;
  step.translation_m = Eigen::Vector2d(1, 0);
  for (int k = 0; k < 20; ++k) {
    g.addKeyFrame(k, k, poseOf(k, 0, 0));
    if (k > 0) g.addOdometry(k - 1, k, step, diag3(0.02, 0.002));
    g.addHeading(k, 0.0, 0.01);
    g.addPositionFix(k, Eigen::Vector2d(k, 0), diag2(0.5));
  }
  g.addPositionFix(10.0, Eigen::Vector2d(10, 10), diag2(0.5));  // 20 sigmas off
  g.solveFull();
  EXPECT_LT(std::abs(g.pose(10).position_en_m.y()), 0.05);
}

// The windowed solve frees the span of a new loop (plus the margin) only, and agrees with the full solve.
TEST(PoseGraph, WindowedSolveAroundNewLoop) {
  const OutAndBack run(60);
  const int n = static_cast<int>(run.truth.size());
  PoseGraphConfig config;
  config.window_margin_keyframes = 3;
  config.loop_margin_keyframes = 10;
  PoseGraph g(config), full(config);
  for (PoseGraph* graph : {&g, &full}) {
    run.fill(graph);
    for (int k = 0; k < n; ++k) graph->addHeading(k, run.truth[k].yaw_rad, 0.01);
    for (int k = 0; k < n; k += 5) graph->addPositionFix(0.4 * k, run.truth[k].position_en_m, diag2(0.1));
    graph->solve();
  }
  const int a = 40, b = n - 41;
  for (PoseGraph* graph : {&g, &full}) graph->addLoop(a, b, between(run.truth[a], run.truth[b]), diag3(0.01, 0.002));
  const SolveReport windowed = g.solve();
  const SolveReport all = full.solveFull();
  EXPECT_FALSE(windowed.full);
  EXPECT_EQ(windowed.keyframes_optimized, b - a + 1 + 2 * config.loop_margin_keyframes);
  EXPECT_EQ(windowed.keyframes_held, 2);
  EXPECT_TRUE(all.full);
  EXPECT_GT(windowed.keyframes_moved, 0);
  double diff_m = 0.0;
  for (int k = 0; k < n; ++k) diff_m = std::max(diff_m, (g.pose(k).position_en_m - full.pose(k).position_en_m).norm());
  std::cout << "windowed solve of " << windowed.keyframes_optimized << " key frames vs full solve of " << n
            << ": largest difference " << diff_m << " m\n";
  EXPECT_LT(diff_m, 0.1) << "windowed vs full";
  EXPECT_EQ(g.loopAccepted(0), full.loopAccepted(0));
  EXPECT_LT((g.pose(a).position_en_m - full.pose(a).position_en_m).norm(), 0.02);
  EXPECT_LT((g.pose(b).position_en_m - full.pose(b).position_en_m).norm(), 0.02);
  EXPECT_FALSE(g.hasPendingChanges());
  // Nothing new: an empty window.
  EXPECT_EQ(g.solve().keyframes_optimized, 0);
}

TEST(PoseGraph, BadInputIsRejectedWithItsReason) {
  PoseGraph g;
  g.addKeyFrame(1, 10.0, poseOf(0, 0, 0));
  g.addKeyFrame(2, 11.0, poseOf(1, 0, 0));
  RelativePose2d d;
  d.translation_m = Eigen::Vector2d(1, 0);
  const Eigen::Matrix3d good = diag3(0.1, 0.01);
  expectInvalid([&] { g.addOdometry(1, 99, d, good); }, "unknown key frame id 99");
  expectInvalid([&] { g.addHeading(7, 0.0, 0.1); }, "unknown key frame id 7");
  expectInvalid([&] { g.addLoop(42, 2, d, good); }, "unknown key frame id 42");
  expectInvalid([&] { g.pose(3); }, "unknown key frame id 3");
  expectInvalid([&] { g.addOdometry(2, 1, d, good); }, "not before");
  expectInvalid([&] { g.addLoop(2, 2, d, good); }, "same key frame");
  Eigen::Matrix3d negative = good;
  negative(2, 2) = -1e-4;
  expectInvalid([&] { g.addOdometry(1, 2, d, negative); }, "not positive definite");
  Eigen::Matrix3d asymmetric = good;
  asymmetric(0, 1) = 0.005;
  expectInvalid([&] { g.addLoop(1, 2, d, asymmetric); }, "not symmetric");
  Eigen::Matrix3d nan_cov = good;
  nan_cov(1, 1) = std::nan("");
  expectInvalid([&] { g.addOdometry(1, 2, d, nan_cov); }, "non-finite");
  expectInvalid([&] { g.addPositionFix(10.5, Eigen::Vector2d(0, 0), Eigen::Matrix2d::Zero()); },
                "not positive definite");
  RelativePose2d nan_delta = d;
  nan_delta.yaw_rad = std::nan("");
  expectInvalid([&] { g.addOdometry(1, 2, nan_delta, good); }, "non-finite delta");
  expectInvalid([&] { g.addPositionFix(std::nan(""), Eigen::Vector2d(0, 0), diag2(1)); }, "non-finite");
  expectInvalid([&] { g.addHeading(1, 0.0, 0.0); }, "sigma_rad");
  expectInvalid([&] { g.addKeyFrame(2, 12.0, poseOf(0, 0, 0)); }, "not greater than the last id 2");
  expectInvalid([&] { g.addKeyFrame(3, 11.0, poseOf(0, 0, 0)); }, "not after the last stamp");
  expectInvalid([&] { g.addKeyFrame(3, 12.0, poseOf(std::nan(""), 0, 0)); }, "non-finite");
  expectInvalid([&] { g.loop(0); }, "out of range");
  EXPECT_EQ(g.numFactors(), 1u) << "only the gauge prior: nothing rejected was added";

  PoseGraphConfig bad;
  bad.loop_gate_chi2 = 0.0;
  bad.max_iterations = 0;
  expectInvalid([&] { PoseGraph x(bad); }, "loop_gate_chi2 = 0 out of range (0, inf)");
  expectInvalid([&] { PoseGraph x(bad); }, "max_iterations = 0 out of range [1, inf)");
  BackgroundPoseGraphConfig bad_background;
  bad_background.idle_wait_s = -1.0;
  expectInvalid([&] { BackgroundPoseGraph x(bad_background); }, "idle_wait_s");

  BackgroundPoseGraph background;
  background.addKeyFrame(5, 1.0, poseOf(0, 0, 0));
  expectInvalid([&] { background.addOdometry(5, 6, d, good); }, "unknown key frame id 6");
  expectInvalid([&] { background.addLoop(4, 5, d, good); }, "unknown key frame id 4");
  expectInvalid([&] { background.addHeading(5, 0.0, -1.0); }, "sigma_rad");
  expectInvalid([&] { background.addPositionFix(1.0, Eigen::Vector2d(0, 0), diag2(0)); }, "not positive definite");
  expectInvalid([&] { background.addKeyFrame(5, 2.0, poseOf(0, 0, 0)); }, "not greater");
  EXPECT_TRUE(background.waitIdle(10.0));
  EXPECT_EQ(background.snapshot()->last_error, "");
}

/// The inputs of a back-and-forth survey of `lanes` lanes of `per_lane` key frames, in the order a live chain
/// produces them.
struct SurveyInputs {
  struct Step {
    int64_t id;
    double stamp_s;
    Pose2d initial;
    bool has_odometry;
    RelativePose2d odometry;
    double heading_rad;
    std::vector<std::pair<double, Eigen::Vector2d>> fixes;
    std::vector<std::pair<int64_t, RelativePose2d>> loops;  ///< from an earlier key frame to this one
  };
  std::vector<Step> steps;
  SurveyInputs(int lanes, int per_lane, unsigned seed) {
    std::mt19937 rng(seed);
    std::normal_distribution<double> normal;
    std::vector<Pose2d> truth;
    for (int lane = 0; lane < lanes; ++lane)
      for (int k = 0; k < per_lane; ++k) {
        const bool east = lane % 2 == 0;
        truth.push_back(poseOf(0.2 * (east ? k : per_lane - 1 - k), 2.0 * lane, east ? 0.0 : kPi));
      }
    Pose2d chained = truth[0];
    for (size_t i = 0; i < truth.size(); ++i) {
      Step s;
      s.id = 1000 + static_cast<int64_t>(i);
      s.stamp_s = 0.4 * i;
      s.has_odometry = i > 0;
      if (s.has_odometry) {
        s.odometry = between(truth[i - 1], truth[i]);
        s.odometry.translation_m += 0.005 * Eigen::Vector2d(normal(rng), normal(rng));
        s.odometry.yaw_rad += 0.003 * normal(rng);
        chained = compose(chained, s.odometry);
      }
      s.initial = chained;
      s.heading_rad = truth[i].yaw_rad + 0.017 * normal(rng);
      if (i % 5 == 2)
        s.fixes.push_back({s.stamp_s - 0.2, truth[i].position_en_m + 0.5 * Eigen::Vector2d(normal(rng), normal(rng))});
      const int lane = static_cast<int>(i) / per_lane, k = static_cast<int>(i) % per_lane;
      if (lane > 0 && k % 25 == 12) {
        const int j = (lane - 1) * per_lane + (per_lane - 1 - k);  // same east on the lane before
        RelativePose2d d = between(truth[j], truth[i]);
        d.translation_m += 0.02 * Eigen::Vector2d(normal(rng), normal(rng));
        s.loops.push_back({1000 + j, d});
      }
      steps.push_back(s);
    }
  }
  template <typename Graph>
  void add(Graph* g, size_t i) const {
    const Step& s = steps[i];
    g->addKeyFrame(s.id, s.stamp_s, s.initial);
    if (s.has_odometry) g->addOdometry(s.id - 1, s.id, s.odometry, diag3(0.005, 0.003));
    g->addHeading(s.id, s.heading_rad, 0.017);
    for (const auto& [stamp, en] : s.fixes) g->addPositionFix(stamp, en, diag2(0.5));
    for (const auto& [from, d] : s.loops) g->addLoop(from, s.id, d, diag3(0.02, 0.005));
  }
};

// 2000 key frames from a producer thread while the worker solves: snapshots monotonic, adds never wait for a
// solve, the settled result equals a synchronous full solve, stop() is prompt.
TEST(BackgroundPoseGraph, ProducerAndWorkerAgreeWithSynchronousSolve) {
  const SurveyInputs survey(20, 100, 11);
  std::mutex seen_mutex;
  std::vector<uint64_t> sequences;
  BackgroundPoseGraph background(BackgroundPoseGraphConfig(), [&](const std::shared_ptr<const GraphSnapshot>& s) {
    std::lock_guard<std::mutex> lock(seen_mutex);
    sequences.push_back(s->sequence);
  });

  std::atomic<bool> producing{true};
  std::atomic<bool> monotonic{true};
  std::atomic<int> reads{0};
  std::thread consumer([&] {
    uint64_t last_sequence = 0, last_applied = 0;
    size_t last_size = 0;
    while (producing) {
      const std::shared_ptr<const GraphSnapshot> s = background.snapshot();
      if (s->sequence < last_sequence || s->inputs_applied < last_applied || s->key_frames.size() < last_size)
        monotonic = false;
      last_sequence = s->sequence;
      last_applied = s->inputs_applied;
      last_size = s->key_frames.size();
      ++reads;
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
  });
  double max_add_s = 0.0;
  std::thread producer([&] {
    for (size_t i = 0; i < survey.steps.size(); ++i) {
      const auto t0 = std::chrono::steady_clock::now();
      survey.add(&background, i);
      max_add_s = std::max(max_add_s, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
      if (i % 50 == 0) std::this_thread::sleep_for(std::chrono::milliseconds(2));  // a live chain's pace, roughly
    }
  });
  producer.join();
  ASSERT_TRUE(background.waitIdle(120.0)) << "the worker did not settle within 120 s";
  producing = false;
  consumer.join();
  const std::shared_ptr<const GraphSnapshot> final_snapshot = background.snapshot();

  PoseGraph sync;
  for (size_t i = 0; i < survey.steps.size(); ++i) survey.add(&sync, i);
  const SolveReport sync_report = sync.solveFull();
  ASSERT_TRUE(sync_report.converged) << sync_report.message;

  EXPECT_TRUE(monotonic);
  {
    std::lock_guard<std::mutex> lock(seen_mutex);
    ASSERT_FALSE(sequences.empty());
    for (size_t i = 1; i < sequences.size(); ++i) EXPECT_EQ(sequences[i], sequences[i - 1] + 1);
    std::cout << "background: " << sequences.size() << " snapshots, " << reads << " reads, longest add "
              << 1e3 * max_add_s << " ms, final " << final_snapshot->report.message << "\n";
  }
  EXPECT_LT(max_add_s, 0.25) << "an add waited for a solve";
  EXPECT_TRUE(final_snapshot->settled);
  EXPECT_EQ(final_snapshot->last_error, "");
  ASSERT_EQ(final_snapshot->key_frames.size(), survey.steps.size());
  ASSERT_EQ(final_snapshot->loop_accepted.size(), sync.numLoops());
  double max_diff_m = 0.0, max_diff_rad = 0.0;
  for (const KeyFramePose& k : final_snapshot->key_frames) {
    const Pose2d p = sync.pose(k.id);
    max_diff_m = std::max(max_diff_m, (p.position_en_m - k.pose.position_en_m).norm());
    max_diff_rad = std::max(max_diff_rad, std::abs(wrapAngle(p.yaw_rad - k.pose.yaw_rad)));
    const Pose2d initial = sync.initialPose(k.id);
    EXPECT_NEAR((initial.position_en_m + k.correction_en_m - k.pose.position_en_m).norm(), 0.0, 1e-9);
  }
  EXPECT_LT(max_diff_m, 1e-6);
  EXPECT_LT(max_diff_rad, 1e-6);
  for (size_t l = 0; l < sync.numLoops(); ++l)
    EXPECT_EQ(bool(final_snapshot->loop_accepted[l]), sync.loopAccepted(static_cast<int>(l))) << "loop " << l;
  ASSERT_NE(final_snapshot->find(1000), nullptr);
  EXPECT_EQ(final_snapshot->find(999), nullptr);

  const auto t0 = std::chrono::steady_clock::now();
  background.stop();
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 1.0);
  EXPECT_FALSE(background.waitIdle(0.1)) << "stopped";
}

// Once the graph is settled, the worker computes the key frames' position marginals (within its duty cycle) and
// publishes them with the solution they are of; they equal the synchronous graph's. With a duty cycle of 0, never.
TEST(BackgroundPoseGraph, PublishesThePositionMarginalsOfTheSettledGraph) {
  const SurveyInputs survey(6, 60, 5);
  PoseGraph sync;
  for (size_t i = 0; i < survey.steps.size(); ++i) survey.add(&sync, i);
  ASSERT_TRUE(sync.solveFull().converged);
  const std::vector<Eigen::Matrix2d> expected = sync.positionCovariances();
  ASSERT_EQ(expected.size(), sync.numKeyFrames());

  for (const double duty : {0.5, 0.0}) {
    BackgroundPoseGraphConfig config;
    config.marginals_duty_cycle = duty;
    BackgroundPoseGraph background(config);
    for (size_t i = 0; i < survey.steps.size(); ++i) survey.add(&background, i);
    ASSERT_TRUE(background.waitIdle(60.0));
    std::shared_ptr<const GraphSnapshot> s = background.snapshot();
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
    while (duty > 0 && s->marginals_sequence + 1 < s->sequence && std::chrono::steady_clock::now() < deadline) {
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
      s = background.snapshot();
    }
    if (duty == 0.0) {
      std::this_thread::sleep_for(std::chrono::milliseconds(200));
      s = background.snapshot();
      EXPECT_TRUE(s->position_covariance_m2.empty());
      EXPECT_EQ(s->marginals_sequence, 0u);
      continue;
    }
    ASSERT_TRUE(s->settled);
    // The snapshot after the settled one carries the marginals of its solution.
    EXPECT_EQ(s->marginals_sequence + 1, s->sequence);
    EXPECT_GT(s->marginals_cpu_s, 0.0);
    ASSERT_EQ(s->position_covariance_m2.size(), s->key_frames.size());
    double max_relative = 0.0;
    for (size_t k = 0; k < expected.size(); ++k) {
      ASSERT_TRUE(s->position_covariance_m2[k].allFinite()) << "key frame " << k;
      max_relative =
          std::max(max_relative, (s->position_covariance_m2[k] - expected[k]).norm() / expected[k].norm());
    }
    EXPECT_LT(max_relative, 1e-4);
  }
}

// stop() while the worker is busy with a long backlog returns promptly.
TEST(BackgroundPoseGraph, StopWhileSolvingIsPrompt) {
  const SurveyInputs survey(10, 100, 3);
  BackgroundPoseGraph background;
  for (size_t i = 0; i < survey.steps.size(); ++i) survey.add(&background, i);
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  const auto t0 = std::chrono::steady_clock::now();
  background.stop();
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 1.0);
}

}  // namespace
}  // namespace graph
}  // namespace exocet_mosaic
