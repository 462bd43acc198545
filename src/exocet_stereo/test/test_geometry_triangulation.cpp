// Triangulation (2D4 report section 3.2.3): linear DLT over N views, Lindstrom's optimal two-view correction against
// OpenCV's Hartley-Sturm implementation (cv::correctMatches), the Gauss-Newton N-view refinement, and real SIFT
// matches of the temple ring triangulated with the exact cameras.
#include <cmath>
#include <iostream>
#include <map>
#include <random>
#include <string>

#include <gtest/gtest.h>
#include <Eigen/Geometry>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>

#include "exocet_common/testing/paths.h"
#include "exocet_stereo/geometry/epipolar.h"
#include "exocet_stereo/geometry/feature_matching.h"
#include "exocet_stereo/geometry/fundamental_ransac.h"
#include "exocet_stereo/geometry/triangulation.h"

namespace {

using namespace exocet_stereo::geometry;

const std::string kTempleDir = exocet_common::testing::sharedDataDir() + "/temple_sparse_ring";

std::vector<PinholeView> threeViews() {
  std::vector<PinholeView> views(3);
  for (auto& v : views) v.K << 900, 0, 320, 0, 900, 240, 0, 0, 1;
  views[1].R = Eigen::AngleAxisd(0.15, Eigen::Vector3d::UnitY()).toRotationMatrix();
  views[1].t = Eigen::Vector3d(-0.8, 0.0, 0.1);
  views[2].R = Eigen::AngleAxisd(-0.1, Eigen::Vector3d(0.2, 1.0, 0.0).normalized()).toRotationMatrix();
  views[2].t = Eigen::Vector3d(0.7, 0.2, -0.1);
  return views;
}

TEST(Triangulation, LinearIsExactWithoutNoise) {
  const auto views = threeViews();
  const Eigen::Vector3d X(0.3, -0.2, 5.0);
  std::vector<Projection> P;
  std::vector<Eigen::Vector2d> x;
  for (const auto& v : views) {
    P.push_back(v.projection());
    x.push_back(v.project(X));
  }
  EXPECT_LT((triangulateLinear(P, x) - X).norm(), 1e-9);
  EXPECT_LT((triangulateLinear({P[0], P[2]}, {x[0], x[2]}) - X).norm(), 1e-9);
  EXPECT_THROW(triangulateLinear({P[0]}, {x[0]}), std::invalid_argument);
  EXPECT_THROW(triangulateLinear(P, {x[0]}), std::invalid_argument);
}

// 200 noisy matches (1 px): niter2 gives OpenCV's Hartley-Sturm solution, the corrected pixels satisfy the epipolar
// constraint, and the Gauss-Newton refinement from the linear point reaches the same (optimal) reprojection cost.
TEST(Triangulation, OptimalTwoViewMatchesHartleySturmAndRefinement) {
  const auto views = threeViews();
  const Eigen::Matrix3d F = fundamentalFromViews(views[0], views[1]);
  cv::Mat F_cv(3, 3, CV_64F);
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) F_cv.at<double>(r, c) = F(r, c);
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::normal_distribution<double> noise(0.0, 1.0);
  double worst_vs_cv = 0.0, worst_residual = 0.0, worst_cost_gap = 0.0, linear_cost = 0.0, optimal_cost = 0.0;
  for (int i = 0; i < 200; ++i) {
    const Eigen::Vector3d X(u(rng), u(rng), 5.0 + u(rng));
    const Eigen::Vector2d a = views[0].project(X) + Eigen::Vector2d(noise(rng), noise(rng));
    const Eigen::Vector2d b = views[1].project(X) + Eigen::Vector2d(noise(rng), noise(rng));
    const auto [a_opt, b_opt] = correctMatchOptimal(F, a, b);
    cv::Mat pa = (cv::Mat_<double>(1, 2) << a.x(), a.y()), pb = (cv::Mat_<double>(1, 2) << b.x(), b.y());
    cv::Mat ca, cb;
    cv::correctMatches(F_cv, pa.reshape(2, 1), pb.reshape(2, 1), ca, cb);
    const Eigen::Vector2d a_cv(ca.at<cv::Vec2d>(0)[0], ca.at<cv::Vec2d>(0)[1]);
    const Eigen::Vector2d b_cv(cb.at<cv::Vec2d>(0)[0], cb.at<cv::Vec2d>(0)[1]);
    worst_vs_cv = std::max({worst_vs_cv, (a_opt - a_cv).norm(), (b_opt - b_cv).norm()});
    worst_residual = std::max(worst_residual, sampsonDistance_px(F, a_opt, b_opt));

    const std::vector<Projection> P = {views[0].projection(), views[1].projection()};
    const Eigen::Vector3d X_opt = triangulateOptimalTwoView(views[0], views[1], a, b);
    const Eigen::Vector3d X_lin = triangulateLinear(P, {a, b});
    const TriangulationRefinement refined = refineTriangulation(P, {a, b}, X_lin);
    const double cost_opt = std::pow(reprojectionRms_px(P, {a, b}, X_opt), 2);
    const double cost_ref = std::pow(refined.final_rms_px, 2);
    worst_cost_gap = std::max(worst_cost_gap, std::abs(cost_opt - cost_ref));
    EXPECT_LE(refined.final_rms_px, refined.initial_rms_px + 1e-12);
    linear_cost += std::pow(reprojectionRms_px(P, {a, b}, X_lin), 2);
    optimal_cost += cost_opt;
  }
  std::cout << "niter2 vs cv::correctMatches " << worst_vs_cv << " px; residual " << worst_residual
            << " px; refinement-optimal cost gap " << worst_cost_gap << " px^2; mean cost linear " << linear_cost / 200
            << " optimal " << optimal_cost / 200 << "\n";
  EXPECT_LT(worst_vs_cv, 1e-6);
  EXPECT_LT(worst_residual, 1e-8);
  EXPECT_LT(worst_cost_gap, 1e-6);
  EXPECT_LE(optimal_cost, linear_cost + 1e-9);
}

// Real SIFT matches of temple views 1 and 2, and tracks seen in views 1, 2 and 10, triangulated with the exact
// Middlebury cameras: the reprojection error is the matching and calibration noise, below 1 px.
TEST(Triangulation, TempleMatchesReprojectBelowOnePixel) {
  const auto views = readMiddleburyViews(kTempleDir + "/templeSR_par.txt");
  ASSERT_EQ(views.size(), 16u);
  SiftMatchingConfig sift;
  sift.contrast_threshold = 0.02;
  std::vector<ImageFeatures> f;
  for (int i : {0, 1, 9})
    f.push_back(detectSift(cv::imread(kTempleDir + "/" + views[i].name, cv::IMREAD_GRAYSCALE), sift));
  ASSERT_FALSE(f[0].keypoints.empty());
  const PinholeView& v1 = views[0];
  const PinholeView& v2 = views[1];
  const PinholeView& v10 = views[9];

  // Inliers of views 1-2 (RANSAC on F), then of 1-10: keypoints of view 1 matched in both form 3-view tracks.
  auto inlierMatches = [&](int other) {
    std::map<int, int> kept;
    const auto matches = matchSift(f[0], f[other], sift);
    std::vector<Eigen::Vector2d> a, b;
    for (const auto& m : matches) {
      a.push_back(f[0].pixel(m.queryIdx));
      b.push_back(f[other].pixel(m.trainIdx));
    }
    const FundamentalFit fit = fitFundamentalRansac(a, b);
    for (size_t k = 0; k < matches.size(); ++k)
      if (fit.inliers[k]) kept[matches[k].queryIdx] = matches[k].trainIdx;
    return kept;
  };
  const auto m12 = inlierMatches(1), m110 = inlierMatches(2);
  ASSERT_GT(m12.size(), 150u);
  const std::vector<Projection> P2 = {v1.projection(), v2.projection()};
  double sum2 = 0.0;
  for (const auto& [k1, k2] : m12) {
    const Eigen::Vector2d a = f[0].pixel(k1), b = f[1].pixel(k2);
    const Eigen::Vector3d X = triangulateOptimalTwoView(v1, v2, a, b);
    EXPECT_GT(v1.depth(X), 0.0);
    sum2 += std::pow(reprojectionRms_px(P2, {a, b}, X), 2);
  }
  const double rms_two = std::sqrt(sum2 / m12.size());

  const std::vector<Projection> P3 = {v1.projection(), v2.projection(), v10.projection()};
  double sum3 = 0.0;
  int tracks = 0;
  for (const auto& [k1, k2] : m12) {
    const auto it = m110.find(k1);
    if (it == m110.end()) continue;
    const std::vector<Eigen::Vector2d> x = {f[0].pixel(k1), f[1].pixel(k2), f[2].pixel(it->second)};
    const TriangulationRefinement r = refineTriangulation(P3, x, triangulateLinear(P3, x));
    sum3 += r.final_rms_px * r.final_rms_px;
    ++tracks;
  }
  ASSERT_GT(tracks, 30);
  const double rms_three = std::sqrt(sum3 / tracks);
  std::cout << m12.size() << " two-view matches: reprojection rms " << rms_two << " px; " << tracks
            << " three-view tracks: " << rms_three << " px\n";
  EXPECT_LT(rms_two, 1.0);
  EXPECT_LT(rms_three, 1.0);
}

}  // namespace
