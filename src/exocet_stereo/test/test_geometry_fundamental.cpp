// Epipolar geometry and the robust fundamental matrix (2D4 report section 3.2.2): the F of two calibrated views on
// synthetic points, our RANSAC on synthetic matches with 40 % outliers, and on real SIFT matches between two views
// of the Middlebury temple ring against the exact F of the given cameras and against cv::findFundamentalMat
// (FM_RANSAC).
#include <cmath>
#include <iostream>
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
#include "exocet_stereo/geometry/pinhole_view.h"

namespace {

using namespace exocet_stereo::geometry;

const std::string kTempleDir = exocet_common::testing::sharedDataDir() + "/temple_sparse_ring";

struct TwoViews {
  PinholeView v1, v2;
};

TwoViews syntheticPair() {
  TwoViews p;
  p.v1.K << 800, 0, 320, 0, 780, 240, 0, 0, 1;
  p.v2.K << 820, 0, 300, 0, 810, 250, 0, 0, 1;
  p.v2.R = Eigen::AngleAxisd(0.2, Eigen::Vector3d(0.1, 1.0, 0.2).normalized()).toRotationMatrix();
  p.v2.t = Eigen::Vector3d(-1.0, 0.1, 0.2);
  return p;
}

TEST(Epipolar, FundamentalFromViewsSatisfiedByProjections) {
  const TwoViews p = syntheticPair();
  const Eigen::Matrix3d F = fundamentalFromViews(p.v1, p.v2);
  EXPECT_NEAR(F.norm(), 1.0, 1e-12);
  EXPECT_NEAR(F.determinant(), 0.0, 1e-12);
  std::mt19937_64 rng(1);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int i = 0; i < 50; ++i) {
    const Eigen::Vector3d X(u(rng), u(rng), 6.0 + u(rng));
    const Eigen::Vector2d a = p.v1.project(X), b = p.v2.project(X);
    EXPECT_LT(sampsonDistance_px(F, a, b), 1e-9);
    EXPECT_LT(symmetricEpipolarDistance_px(F, a, b), 1e-9);
    // A point moved 3 px across the epipolar line is 3 px from it.
    const Eigen::Vector3d line = F * a.homogeneous();
    const Eigen::Vector2d normal = line.head<2>().normalized();
    EXPECT_NEAR(epipolarLineDistance_px(F, a, b + 3.0 * normal), 3.0, 1e-9);
  }
  // Tolerance for poses off by 0.01 rad and 2 %: f (0.01 + 0.02) + noise.
  EXPECT_NEAR(epipolarToleranceForPoseError_px(1000.0, 0.01, 0.02, 1.0), 31.0, 1e-9);
}

TEST(FundamentalRansac, RejectsBadConfigAndFewMatches) {
  FundamentalRansacConfig config;
  config.threshold_px = -1.0;
  config.confidence = 1.0;
  config.max_samples = 0;
  const std::string error = config.validate();
  EXPECT_NE(error.find("threshold_px must be in (0, 50]"), std::string::npos) << error;
  EXPECT_NE(error.find("confidence must be in (0, 1)"), std::string::npos) << error;
  EXPECT_NE(error.find("max_samples must be in [1, 100000]"), std::string::npos) << error;
  EXPECT_THROW(fitFundamentalRansac({{0, 0}}, {}), std::invalid_argument);
  const FundamentalFit fit = fitFundamentalRansac(std::vector<Eigen::Vector2d>(5), std::vector<Eigen::Vector2d>(5));
  EXPECT_FALSE(fit.ok);
  EXPECT_NE(fit.failure.find("at least 8"), std::string::npos);
}

// 300 true matches with 0.5 px noise and 200 random ones: the outliers are rejected, the true matches kept, and the
// estimate's epipolar lines within 1 px of the exact ones.
TEST(FundamentalRansac, SeparatesSyntheticOutliers) {
  const TwoViews p = syntheticPair();
  const Eigen::Matrix3d F_true = fundamentalFromViews(p.v1, p.v2);
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-1.5, 1.5), px(0.0, 640.0);
  std::normal_distribution<double> noise(0.0, 0.5);
  std::vector<Eigen::Vector2d> a, b;
  std::vector<bool> truly_inlier;
  for (int i = 0; i < 300; ++i) {
    const Eigen::Vector3d X(u(rng), u(rng), 6.0 + u(rng));
    a.push_back(p.v1.project(X) + Eigen::Vector2d(noise(rng), noise(rng)));
    b.push_back(p.v2.project(X) + Eigen::Vector2d(noise(rng), noise(rng)));
    truly_inlier.push_back(true);
  }
  for (int i = 0; i < 200; ++i) {
    a.emplace_back(px(rng), 0.75 * px(rng));
    b.emplace_back(px(rng), 0.75 * px(rng));
    truly_inlier.push_back(sampsonDistance_px(F_true, a.back(), b.back()) < 1.0);
  }
  FundamentalRansacConfig config;
  config.threshold_px = 1.5;
  const FundamentalFit fit = fitFundamentalRansac(a, b, config);
  ASSERT_TRUE(fit.ok) << fit.failure;
  int kept_true = 0, kept_far_outliers = 0;
  double sum2 = 0.0;
  for (size_t i = 0; i < a.size(); ++i) {
    if (i < 300 && fit.inliers[i]) ++kept_true;
    if (i >= 300 && fit.inliers[i] && sampsonDistance_px(F_true, a[i], b[i]) > 3.0) ++kept_far_outliers;
    if (i < 300) {
      const Eigen::Vector2d clean_a = a[i];
      sum2 += std::pow(epipolarLineDistance_px(fit.F, clean_a, b[i]), 2);
    }
  }
  std::cout << "kept " << kept_true << " of 300 true, " << kept_far_outliers << " far outliers, inliers "
            << fit.inlier_count << ", samples " << fit.samples << "\n";
  EXPECT_GE(kept_true, 280);
  // The estimate extrapolates beyond the true points (which cover the image centre only), so a random pair can fall
  // within the gate of the estimate yet 3 px from the exact line: at most 1 % of the outliers.
  EXPECT_LE(kept_far_outliers, 2);
  EXPECT_LT(std::sqrt(sum2 / 300), 1.0);
  EXPECT_LT(fit.samples, 2000);  // adaptive: about 60 % inliers need far fewer than the cap
  // Same seed, same answer.
  const FundamentalFit again = fitFundamentalRansac(a, b, config);
  EXPECT_EQ(again.inliers, fit.inliers);
}

// Real SIFT matches between temple views 1 and 2 (neighbours on the ring, 0.22 m apart).
TEST(FundamentalRansac, TemplePairAgainstExactCamerasAndOpenCv) {
  const std::vector<PinholeView> views = readMiddleburyViews(kTempleDir + "/templeSR_par.txt");
  ASSERT_EQ(views.size(), 16u);
  const cv::Mat im1 = cv::imread(kTempleDir + "/" + views[0].name, cv::IMREAD_GRAYSCALE);
  const cv::Mat im2 = cv::imread(kTempleDir + "/" + views[1].name, cv::IMREAD_GRAYSCALE);
  ASSERT_FALSE(im1.empty());
  ASSERT_FALSE(im2.empty());
  SiftMatchingConfig sift;
  sift.contrast_threshold = 0.02;
  const ImageFeatures f1 = detectSift(im1, sift), f2 = detectSift(im2, sift);
  const std::vector<cv::DMatch> matches = matchSift(f1, f2, sift);
  std::vector<Eigen::Vector2d> a, b;
  std::vector<cv::Point2f> ca, cb;
  for (const auto& m : matches) {
    a.push_back(f1.pixel(m.queryIdx));
    b.push_back(f2.pixel(m.trainIdx));
    ca.push_back(f1.keypoints[m.queryIdx].pt);
    cb.push_back(f2.keypoints[m.trainIdx].pt);
  }
  ASSERT_GT(matches.size(), 200u);
  const Eigen::Matrix3d F_exact = fundamentalFromViews(views[0], views[1]);
  FundamentalRansacConfig config;
  config.threshold_px = 1.0;
  const FundamentalFit fit = fitFundamentalRansac(a, b, config);
  ASSERT_TRUE(fit.ok) << fit.failure;

  cv::Mat cv_mask;
  const cv::Mat F_cv_mat = cv::findFundamentalMat(ca, cb, cv::FM_RANSAC, 1.0, 0.999, cv_mask);
  ASSERT_EQ(F_cv_mat.rows, 3);
  Eigen::Matrix3d F_cv;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) F_cv(r, c) = F_cv_mat.at<double>(r, c);

  // Over our inliers: epipolar distance to the estimate and to the exact F of the cameras.
  double ours2 = 0.0, exact2 = 0.0, cv2 = 0.0;
  int both = 0, either = 0, cv_count = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    const bool cv_in = cv_mask.at<uchar>(static_cast<int>(i)) != 0;
    cv_count += cv_in;
    both += fit.inliers[i] && cv_in;
    either += fit.inliers[i] || cv_in;
    if (!fit.inliers[i]) continue;
    ours2 += std::pow(symmetricEpipolarDistance_px(fit.F, a[i], b[i]), 2);
    exact2 += std::pow(symmetricEpipolarDistance_px(F_exact, a[i], b[i]), 2);
    cv2 += std::pow(symmetricEpipolarDistance_px(F_cv, a[i], b[i]), 2);
  }
  const double n = fit.inlier_count;
  const double rms_ours = std::sqrt(ours2 / n), rms_exact = std::sqrt(exact2 / n), rms_cv = std::sqrt(cv2 / n);
  const double jaccard = static_cast<double>(both) / either;
  std::cout << matches.size() << " matches; inliers ours " << fit.inlier_count << " cv " << cv_count << " (Jaccard "
            << jaccard << "); rms epipolar distance on our inliers: ours " << rms_ours << " exact " << rms_exact
            << " cv " << rms_cv << " px; " << fit.samples << " samples\n";
  EXPECT_LT(rms_ours, 1.0);
  EXPECT_LT(rms_exact, 1.0);  // the inliers are true matches of the real cameras
  EXPECT_GT(jaccard, 0.85);
  EXPECT_LT(rms_ours, 1.3 * rms_cv);
  EXPECT_GT(fit.inlier_count, 0.8 * cv_count);
}

TEST(SiftMatching, ValidatesAndMatchesAnImageWithItselfShifted) {
  SiftMatchingConfig config;
  config.ratio = 1.5;
  config.max_features = 3;
  const std::string error = config.validate();
  EXPECT_NE(error.find("ratio must be in (0, 1]"), std::string::npos) << error;
  EXPECT_NE(error.find("max_features must be in [16, 100000]"), std::string::npos) << error;
  EXPECT_THROW(detectSift(cv::Mat(), SiftMatchingConfig()), std::invalid_argument);
  const cv::Mat image = cv::imread(kTempleDir + "/templeSR0001.png", cv::IMREAD_GRAYSCALE);
  ASSERT_FALSE(image.empty());
  cv::Mat shifted = cv::Mat::zeros(image.size(), image.type());
  image(cv::Rect(0, 0, image.cols - 7, image.rows - 4)).copyTo(shifted(cv::Rect(7, 4, image.cols - 7, image.rows - 4)));
  const ImageFeatures a = detectSift(image), b = detectSift(shifted);
  const auto matches = matchSift(a, b);
  ASSERT_GT(matches.size(), 100u);
  // Coarse octaves see a shift of 7 / 2^k px, so keypoints there move by a fraction of a pixel: 0.5 px gate.
  int exact = 0;
  for (const auto& m : matches)
    exact += (b.pixel(m.trainIdx) - a.pixel(m.queryIdx) - Eigen::Vector2d(7, 4)).norm() < 0.5;
  EXPECT_GT(exact, 0.95 * matches.size()) << matches.size() << " matches";
}

}  // namespace
