// Tests of the KLT registration (2D3 report 3.1): the robust motion fitter on synthetic correspondences, and the
// KltRegistrar on image pairs and sequences with exactly known motion. No ROS.

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Dense>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include "exocet_mosaic/registration/klt_registrar.h"
#include "exocet_mosaic/registration/motion_model.h"
#include "exocet_mosaic/registration/robust_motion_fitter.h"
#include "registration_fixtures.h"

namespace exocet_mosaic {
namespace registration {
namespace {

using testing::makeWarpedPair;
using testing::sampleImage;
using testing::seabedPicture;
using testing::similarityAboutCentre;

constexpr int kWidth = 640;
constexpr int kHeight = 480;

const cv::Mat& picture() {
  static const cv::Mat p = seabedPicture(1024, 7);
  return p;
}

Eigen::Vector2d centreOf(int width, int height) { return {0.5 * (width - 1), 0.5 * (height - 1)}; }

/// A homography about the image centre: similarity, a little shear and a perspective tilt.
Eigen::Matrix3d homographyAboutCentre(double rotation_rad, double scale, double tx, double ty, double shear, double g1,
                                      double g2, int width, int height) {
  const Eigen::Vector2d c = centreOf(width, height);
  Eigen::Matrix3d t = Eigen::Matrix3d::Identity(), m = Eigen::Matrix3d::Identity();
  t(0, 2) = -c.x();
  t(1, 2) = -c.y();
  m << scale * std::cos(rotation_rad), -scale * std::sin(rotation_rad) + shear, tx,  //
      scale * std::sin(rotation_rad), scale * std::cos(rotation_rad), ty,            //
      g1, g2, 1.0;
  return t.inverse() * m * t;
}

Eigen::VectorXd truthParameters(MotionModel model, const Eigen::Matrix3d& h, int width = kWidth, int height = kHeight) {
  return parametersFromPixelMatrix(model, h, centreOf(width, height), width, height);
}

// --- Synthetic correspondences ---

struct Correspondences {
  std::vector<Eigen::Vector2d> from, to;
  std::vector<uint8_t> is_inlier;
};

/// `count` points x_A over the image, x_B = truth(x_A) + Gaussian noise; the first outlier_fraction of them (then
/// shuffled) are false matches displaced by outlier_min_px to 50 px in a random direction.
Correspondences makeCorrespondences(const Eigen::Matrix3d& truth, int count, double noise_px, double outlier_fraction,
                                    uint32_t seed, double outlier_min_px = 5.0) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> ux(0.0, kWidth - 1.0), uy(0.0, kHeight - 1.0);
  std::uniform_real_distribution<double> offset(outlier_min_px, 50.0), angle(0.0, 2.0 * M_PI);
  std::normal_distribution<double> noise(0.0, noise_px);
  Correspondences c;
  const int outliers = static_cast<int>(std::lround(outlier_fraction * count));
  for (int i = 0; i < count; ++i) {
    const Eigen::Vector2d a(ux(rng), uy(rng));
    Eigen::Vector2d b = transferPoint(truth, a) + Eigen::Vector2d(noise(rng), noise(rng));
    const bool outlier = i < outliers;
    if (outlier) {
      const double r = offset(rng), t = angle(rng);
      b += Eigen::Vector2d(r * std::cos(t), r * std::sin(t));
    }
    c.from.push_back(a);
    c.to.push_back(b);
    c.is_inlier.push_back(!outlier);
  }
  // Shuffle so that the outliers are not the first points.
  std::vector<int> order(count);
  for (int i = 0; i < count; ++i) order[i] = i;
  std::shuffle(order.begin(), order.end(), rng);
  Correspondences shuffled;
  for (int i : order) {
    shuffled.from.push_back(c.from[i]);
    shuffled.to.push_back(c.to[i]);
    shuffled.is_inlier.push_back(c.is_inlier[i]);
  }
  return shuffled;
}

Eigen::Matrix3d truthFor(MotionModel model) {
  switch (model) {
    case MotionModel::kTranslation:
      return similarityAboutCentre(0.0, 1.0, 7.3, -4.1, kWidth, kHeight);
    case MotionModel::kSimilarity:
      return similarityAboutCentre(0.05, 1.03, 12.5, -6.25, kWidth, kHeight);
    case MotionModel::kAffine:
      return homographyAboutCentre(0.04, 0.98, -9.0, 5.5, 0.02, 0.0, 0.0, kWidth, kHeight);
    case MotionModel::kHomography:
      return homographyAboutCentre(0.03, 1.02, 8.0, 4.0, 0.01, 4e-5, -3e-5, kWidth, kHeight);
  }
  return Eigen::Matrix3d::Identity();
}

const MotionModel kAllModels[] = {MotionModel::kTranslation, MotionModel::kSimilarity, MotionModel::kAffine,
                                  MotionModel::kHomography};

TEST(RobustMotionFitter, RecoversExactMotionOfEveryModel) {
  for (MotionModel model : kAllModels) {
    SCOPED_TRACE(toString(model));
    RobustFitConfig config;
    config.model = model;
    const RobustMotionFitter fitter(config);
    const Eigen::Matrix3d truth = truthFor(model);
    const Correspondences c = makeCorrespondences(truth, 60, 0.0, 0.0, 11);
    const RobustFit fit = fitter.fit(c.from, c.to, centreOf(kWidth, kHeight));
    ASSERT_TRUE(fit.ok) << fit.failure_detail;
    EXPECT_EQ(fit.inliers, 60);
    EXPECT_LT((fit.parameters - truthParameters(model, truth)).norm(), 1e-8);
    EXPECT_LT(
        cornerTransferError_px(pixelMatrix(model, fit.parameters, centreOf(kWidth, kHeight)), truth, kWidth, kHeight),
        1e-8);
    // A perfect fit still has a non-zero covariance (the residual scale floor).
    EXPECT_GT(fit.covariance.diagonal().minCoeff(), 0.0);
    EXPECT_TRUE(fit.covariance.allFinite());
  }
}

TEST(RobustMotionFitter, StrikesOffExactlyTheGrossOutliers) {
  for (MotionModel model : kAllModels) {
    SCOPED_TRACE(toString(model));
    RobustFitConfig config;
    config.model = model;
    const RobustMotionFitter fitter(config);
    const Eigen::Matrix3d truth = truthFor(model);
    const Correspondences c = makeCorrespondences(truth, 200, 0.3, 0.3, 21);
    const RobustFit fit = fitter.fit(c.from, c.to, centreOf(kWidth, kHeight));
    ASSERT_TRUE(fit.ok) << fit.failure_detail;
    EXPECT_EQ(fit.inliers, 140);
    EXPECT_NEAR(fit.inlier_fraction, 0.7, 1e-12);
    int mismatches = 0;
    for (size_t i = 0; i < c.is_inlier.size(); ++i) mismatches += fit.inlier_mask[i] != c.is_inlier[i];
    EXPECT_EQ(mismatches, 0);
    EXPECT_NEAR(fit.residual_scale_px, 0.3, 0.06);
    const double error =
        cornerTransferError_px(pixelMatrix(model, fit.parameters, centreOf(kWidth, kHeight)), truth, kWidth, kHeight);
    EXPECT_LT(error, 0.3);
  }
}

TEST(RobustMotionFitter, IsDeterministic) {
  RobustFitConfig config;
  config.model = MotionModel::kHomography;
  const RobustMotionFitter fitter(config);
  const Correspondences c = makeCorrespondences(truthFor(MotionModel::kHomography), 150, 0.5, 0.4, 5);
  const RobustFit a = fitter.fit(c.from, c.to, centreOf(kWidth, kHeight));
  const RobustFit b = fitter.fit(c.from, c.to, centreOf(kWidth, kHeight));
  ASSERT_TRUE(a.ok);
  EXPECT_EQ(a.parameters, b.parameters);
  EXPECT_EQ(a.inlier_mask, b.inlier_mask);
}

TEST(RobustMotionFitter, ReportsTooFewInliersAndBadInput) {
  const RobustMotionFitter fitter;
  // 70 % of random matches: no motion has the support that min_inlier_fraction (0.5) requires.
  const Correspondences c = makeCorrespondences(truthFor(MotionModel::kSimilarity), 100, 0.3, 0.7, 8);
  const RobustFit fit = fitter.fit(c.from, c.to, centreOf(kWidth, kHeight));
  EXPECT_FALSE(fit.ok);
  EXPECT_EQ(fit.failure, FailureReason::kTooFewInliers) << fit.failure_detail;

  const RobustFit one = fitter.fit(std::vector<Eigen::Vector2d>{{1.0, 2.0}}, std::vector<Eigen::Vector2d>{{3.0, 4.0}},
                                   centreOf(kWidth, kHeight));
  EXPECT_EQ(one.failure, FailureReason::kTooFewInliers);
  const RobustFit mismatched =
      fitter.fit(std::vector<Eigen::Vector2d>(3), std::vector<Eigen::Vector2d>(4), centreOf(kWidth, kHeight));
  EXPECT_EQ(mismatched.failure, FailureReason::kInvalidInput);
  // All points at one place: the similarity is not determined.
  const RobustFit degenerate = fitter.fit(std::vector<Eigen::Vector2d>(20, {5.0, 5.0}),
                                          std::vector<Eigen::Vector2d>(20, {6.0, 5.0}), centreOf(kWidth, kHeight));
  EXPECT_FALSE(degenerate.ok);
}

// The local scale tells a model error that varies smoothly over the image (the seabed's relief, lens distortion)
// from points that move independently of their neighbours (particles at various depths).
TEST(RobustMotionFitter, LocalScaleSeparatesSmoothModelErrorFromIndependentMotion) {
  RobustFitConfig config;
  config.rejection_k = 20.0;  // keep every point: this is about the residuals, not the rejection
  const RobustMotionFitter fitter(config);
  // A similarity fitted to a perspective motion: residuals of about a pixel, smooth over the image.
  const Correspondences smooth = makeCorrespondences(
      homographyAboutCentre(0.02, 1.0, 4.0, 2.0, 0.0, 2e-5, 0.0, kWidth, kHeight), 150, 0.05, 0.0, 41);
  const RobustFit a = fitter.fit(smooth.from, smooth.to, centreOf(kWidth, kHeight));
  // Each point displaced on its own by 0.7 px (1 sigma per coordinate).
  const Correspondences independent = makeCorrespondences(truthFor(MotionModel::kSimilarity), 150, 0.7, 0.0, 42);
  const RobustFit b = fitter.fit(independent.from, independent.to, centreOf(kWidth, kHeight));
  std::printf("[ info ] smooth model error: residual %.3f px, local %.3f px; independent: residual %.3f, local %.3f\n",
              a.residual_scale_px, a.local_scale_px, b.residual_scale_px, b.local_scale_px);
  EXPECT_GT(a.residual_scale_px, 0.3);
  EXPECT_LT(a.local_scale_px, 0.3 * a.residual_scale_px);
  EXPECT_NEAR(b.residual_scale_px, 0.7, 0.1);
  EXPECT_NEAR(b.local_scale_px, 0.7, 0.2);
}

TEST(RobustMotionFitter, ConfigValidationNamesTheField) {
  RobustFitConfig config;
  EXPECT_EQ(config.validate(), "");
  config.rejection_k = 1.0;
  config.min_inlier_fraction = 1.5;
  const std::string error = config.validate();
  EXPECT_NE(error.find("rejection_k"), std::string::npos) << error;
  EXPECT_NE(error.find("min_inlier_fraction"), std::string::npos) << error;
  EXPECT_THROW(RobustMotionFitter{config}, std::invalid_argument);
  RobustFitConfig homography;
  homography.model = MotionModel::kHomography;
  homography.min_inliers = 3;
  EXPECT_NE(homography.validate().find("min_inliers"), std::string::npos);
}

// Over repeated noisy point sets, the empirical covariance of the parameters matches the predicted one.
TEST(RobustMotionFitter, CovarianceMatchesEmpiricalScatter) {
  for (MotionModel model : {MotionModel::kSimilarity, MotionModel::kHomography}) {
    SCOPED_TRACE(toString(model));
    RobustFitConfig config;
    config.model = model;
    const RobustMotionFitter fitter(config);
    const Eigen::Matrix3d truth = truthFor(model);
    const Eigen::VectorXd p_true = truthParameters(model, truth);
    const int p = parameterCount(model), trials = 400;
    Eigen::MatrixXd scatter = Eigen::MatrixXd::Zero(p, p), predicted = Eigen::MatrixXd::Zero(p, p);
    for (int t = 0; t < trials; ++t) {
      const Correspondences c = makeCorrespondences(truth, 80, 0.5, 0.1, 1000 + t);
      const RobustFit fit = fitter.fit(c.from, c.to, centreOf(kWidth, kHeight));
      ASSERT_TRUE(fit.ok) << fit.failure_detail;
      const Eigen::VectorXd e = fit.parameters - p_true;
      scatter += e * e.transpose() / trials;
      predicted += fit.covariance / trials;
    }
    for (int i = 0; i < p; ++i) {
      const double ratio = scatter(i, i) / predicted(i, i);
      EXPECT_GT(ratio, 0.5) << "parameter " << i;
      EXPECT_LT(ratio, 2.0) << "parameter " << i;
    }
    // Whole-matrix check: the whitened scatter is close to the identity.
    const Eigen::LLT<Eigen::MatrixXd> llt(predicted);
    const Eigen::MatrixXd l_inv = llt.matrixL().solve(Eigen::MatrixXd::Identity(p, p));
    const Eigen::VectorXd eigen =
        Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(l_inv * scatter * l_inv.transpose()).eigenvalues();
    EXPECT_GT(eigen.minCoeff(), 0.5);
    EXPECT_LT(eigen.maxCoeff(), 2.0);
  }
}

// On the same correspondences, ours is at least as accurate as OpenCV's RANSAC + Levenberg-Marquardt (its default
// 3 px threshold). The false matches include small ones (1.5 to 50 px), like badly converged tracks: our threshold
// follows the measured residual scale.
TEST(RobustMotionFitter, AtLeastAsAccurateAsOpenCvEstimateAffinePartial2D) {
  const RobustMotionFitter fitter;
  const Eigen::Matrix3d truth = truthFor(MotionModel::kSimilarity);
  double ours = 0.0, opencv = 0.0;
  int wins = 0;
  const int trials = 60;
  for (int t = 0; t < trials; ++t) {
    const Correspondences c = makeCorrespondences(truth, 150, 0.3, 0.25, 300 + t, 1.5);
    const RobustFit fit = fitter.fit(c.from, c.to, centreOf(kWidth, kHeight));
    ASSERT_TRUE(fit.ok);
    const double e_ours = cornerTransferError_px(
        pixelMatrix(MotionModel::kSimilarity, fit.parameters, centreOf(kWidth, kHeight)), truth, kWidth, kHeight);
    std::vector<cv::Point2f> a, b;
    for (size_t i = 0; i < c.from.size(); ++i) {
      a.emplace_back(c.from[i].x(), c.from[i].y());
      b.emplace_back(c.to[i].x(), c.to[i].y());
    }
    const cv::Mat m = cv::estimateAffinePartial2D(a, b);
    ASSERT_FALSE(m.empty());
    Eigen::Matrix3d h = Eigen::Matrix3d::Identity();
    for (int r = 0; r < 2; ++r)
      for (int col = 0; col < 3; ++col) h(r, col) = m.at<double>(r, col);
    const double e_cv = cornerTransferError_px(h, truth, kWidth, kHeight);
    ours += e_ours / trials;
    opencv += e_cv / trials;
    wins += e_ours <= e_cv;
  }
  std::printf(
      "[ info ] mean corner error over %d trials: ours %.4f px, cv::estimateAffinePartial2D %.4f px "
      "(ours better or equal in %d)\n",
      trials, ours, opencv, wins);
  EXPECT_LE(ours, opencv);
}

// --- The KLT registrar on image pairs ---

KltConfig configFor(MotionModel model) {
  KltConfig config;
  config.model = model;
  return config;
}

double pairError(KltRegistrar* registrar, const testing::WarpedPair& pair, MotionEstimate* out = nullptr) {
  const MotionEstimate e = registrar->registerPair(pair.a, pair.b);
  if (out) *out = e;
  EXPECT_FALSE(e.failed) << toString(e.failure) << ": " << e.failure_detail;
  if (e.failed) return 1e9;
  return cornerTransferError_px(e.pixel_matrix, pair.truth_ab, pair.a.cols, pair.a.rows);
}

TEST(KltRegistrar, RecoversKnownWarpsWithoutNoise) {
  struct Case {
    MotionModel model;
    Eigen::Matrix3d truth;
  };
  const Case cases[] = {
      {MotionModel::kTranslation, similarityAboutCentre(0.0, 1.0, 6.4, -3.7, kWidth, kHeight)},
      {MotionModel::kSimilarity, similarityAboutCentre(0.03, 1.02, 9.3, -5.1, kWidth, kHeight)},
      {MotionModel::kSimilarity, similarityAboutCentre(-0.06, 0.97, -15.2, 11.8, kWidth, kHeight)},
      {MotionModel::kAffine, homographyAboutCentre(0.02, 1.01, 7.0, 3.5, 0.015, 0.0, 0.0, kWidth, kHeight)},
      {MotionModel::kHomography, homographyAboutCentre(0.02, 1.01, -6.0, 4.5, 0.01, 3e-5, -2e-5, kWidth, kHeight)},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(toString(c.model));
    KltRegistrar registrar(configFor(c.model));
    const testing::WarpedPair pair = makeWarpedPair(picture(), c.truth, kWidth, kHeight);
    MotionEstimate e;
    const double error = pairError(&registrar, pair, &e);
    std::printf("[ info ] %-11s noiseless: corner error %.4f px, %d/%d inliers, residual %.3f px, %.2f ms\n",
                toString(c.model).c_str(), error, e.inliers, e.observations, e.residual_scale, e.elapsed_ms);
    // A pure translation has the same sub-pixel phase at every feature, so the interpolation biases do not average
    // out: the fixture's INTER_CUBIC resampling alone is off by up to 0.04 px at quarter-pixel shifts, and
    // Lucas-Kanade's bilinear interpolation by about as much on this sharp texture.
    EXPECT_LT(error, c.model == MotionModel::kTranslation ? 0.1 : 0.05);
    EXPECT_EQ(e.method, RegistrationMethod::kKlt);
    EXPECT_EQ(e.model, c.model);
    EXPECT_EQ(e.parameters.size(), parameterCount(c.model));
    EXPECT_EQ(e.covariance.rows(), parameterCount(c.model));
    EXPECT_GT(e.covariance.diagonal().minCoeff(), 0.0);
    EXPECT_TRUE(e.pixel_matrix.isApprox(pixelMatrix(c.model, e.parameters, e.centre_px)));
    EXPECT_GT(e.inliers, 50);
    EXPECT_GT(e.elapsed_ms, 0.0);
    EXPECT_TRUE(e.weights.empty());
  }
}

TEST(KltRegistrar, RecoversKnownWarpsWithNoiseAndOutlierBlobs) {
  struct Case {
    MotionModel model;
    Eigen::Matrix3d truth;
  };
  const Case cases[] = {
      {MotionModel::kSimilarity, similarityAboutCentre(0.03, 1.02, 9.3, -5.1, kWidth, kHeight)},
      {MotionModel::kAffine, homographyAboutCentre(0.02, 1.01, 7.0, 3.5, 0.015, 0.0, 0.0, kWidth, kHeight)},
      {MotionModel::kHomography, homographyAboutCentre(0.02, 1.01, -6.0, 4.5, 0.01, 3e-5, -2e-5, kWidth, kHeight)},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(toString(c.model));
    KltRegistrar registrar(configFor(c.model));
    const testing::WarpedPair pair = makeWarpedPair(picture(), c.truth, kWidth, kHeight, 2.0, 12, 17);
    MotionEstimate e;
    const double error = pairError(&registrar, pair, &e);
    std::printf("[ info ] %-11s noise 2 + 12 blobs: corner error %.4f px, %d/%d inliers, residual %.3f px\n",
                toString(c.model).c_str(), error, e.inliers, e.observations, e.residual_scale);
    EXPECT_LT(error, 0.2);
  }
}

TEST(KltRegistrar, FailsOnBlankDarkAndUnrelatedImages) {
  KltRegistrar registrar;
  const testing::WarpedPair pair =
      makeWarpedPair(picture(), similarityAboutCentre(0.0, 1.0, 3.0, 2.0, kWidth, kHeight), kWidth, kHeight);

  const cv::Mat blank(kHeight, kWidth, CV_8UC1, cv::Scalar(128));
  MotionEstimate e = registrar.registerPair(blank, blank);
  EXPECT_TRUE(e.failed);
  EXPECT_TRUE(e.failure == FailureReason::kTooDark || e.failure == FailureReason::kTooLittleTexture)
      << toString(e.failure);
  e = registrar.registerPair(pair.a, blank);
  EXPECT_TRUE(e.failed);

  cv::Mat dark_a, dark_b;
  pair.a.convertTo(dark_a, CV_8U, 0.04);
  pair.b.convertTo(dark_b, CV_8U, 0.04);
  e = registrar.registerPair(dark_a, dark_b);
  EXPECT_TRUE(e.failed);
  EXPECT_EQ(e.failure, FailureReason::kTooDark) << e.failure_detail;

  // Two different seabeds: a failure, never a motion.
  const cv::Mat other = seabedPicture(1024, 99);
  const testing::WarpedPair unrelated = makeWarpedPair(other, Eigen::Matrix3d::Identity(), kWidth, kHeight);
  for (MotionModel model : kAllModels) {
    KltRegistrar r(configFor(model));
    e = r.registerPair(pair.a, unrelated.a);
    EXPECT_TRUE(e.failed) << toString(model);
    std::printf("[ info ] unrelated images, %s: %s (%s)\n", toString(model).c_str(), toString(e.failure).c_str(),
                e.failure_detail.c_str());
  }
}

TEST(KltRegistrar, FailsOnTooLargeMotionAndOnAModelThatDoesNotFit) {
  // A 60 px shift, tracked thanks to the prediction, beyond max_motion_fraction.
  KltConfig bounded;
  bounded.max_motion_fraction = 0.1;  // 48 px on a 640x480 image
  KltRegistrar registrar(bounded);
  const Eigen::Matrix3d shift = similarityAboutCentre(0.0, 1.0, 60.0, 0.0, kWidth, kHeight);
  const testing::WarpedPair far = makeWarpedPair(picture(), shift, kWidth, kHeight);
  MotionEstimate e = registrar.registerPair(far.a, far.b, shift);
  EXPECT_TRUE(e.failed);
  EXPECT_EQ(e.failure, FailureReason::kMotionTooLarge) << e.failure_detail;
  KltRegistrar unbounded;
  e = unbounded.registerPair(far.a, far.b, shift);
  EXPECT_FALSE(e.failed) << e.failure_detail;
  EXPECT_LT(cornerTransferError_px(e.pixel_matrix, shift, kWidth, kHeight), 0.1);

  // A strong perspective (3 % scale change across the image) seen through a similarity: residuals far above the
  // tracking noise, reported as a failure rather than forced into a motion.
  KltRegistrar similarity;
  const testing::WarpedPair tilted = makeWarpedPair(
      picture(), homographyAboutCentre(0.0, 1.0, 3.0, 2.0, 0.0, 1e-4, 6e-5, kWidth, kHeight), kWidth, kHeight);
  e = similarity.registerPair(tilted.a, tilted.b);
  EXPECT_TRUE(e.failed);
  EXPECT_TRUE(e.failure == FailureReason::kInconsistent || e.failure == FailureReason::kTooFewInliers)
      << toString(e.failure) << ": " << e.failure_detail;
  KltRegistrar homography(configFor(MotionModel::kHomography));
  e = homography.registerPair(tilted.a, tilted.b);
  EXPECT_FALSE(e.failed) << e.failure_detail;
  EXPECT_LT(cornerTransferError_px(e.pixel_matrix, tilted.truth_ab, kWidth, kHeight), 0.1);
}

TEST(KltRegistrar, LargeMotionsWithoutPredictionAreFoundByTheCoarseSearch) {
  // 4 degrees and 43 px with no prediction: beyond the 3-level pyramid's reach, most tracks are lost or wrong.
  const Eigen::Matrix3d truth = similarityAboutCentre(4.0 * M_PI / 180.0, 1.0, 43.0, 0.0, kWidth, kHeight);
  const testing::WarpedPair pair = makeWarpedPair(picture(), truth, kWidth, kHeight, 1.0);
  KltConfig local_only = configFor(MotionModel::kHomography);
  local_only.coarse_search = false;
  KltRegistrar without(local_only);
  const MotionEstimate refused = without.registerPair(pair.a, pair.b);
  EXPECT_TRUE(refused.failed) << "the local tracker alone reaches this far: the case no longer tests the search";
  KltRegistrar with(configFor(MotionModel::kHomography));
  const MotionEstimate found = with.registerPair(pair.a, pair.b);
  ASSERT_FALSE(found.failed) << toString(found.failure) << ": " << found.failure_detail;
  EXPECT_TRUE(with.lastDiagnostics().coarse_found);
  EXPECT_LT(cornerTransferError_px(found.pixel_matrix, truth, kWidth, kHeight), 0.1);
  EXPECT_GT(found.inliers, 50);
  std::printf("[ info ] 4 deg / 43 px without prediction: %d inliers, corner error %.4f px, search %.1f ms\n",
              found.inliers, cornerTransferError_px(found.pixel_matrix, truth, kWidth, kHeight),
              with.lastDiagnostics().coarse_ms);

  // Motions up to a third of the image width, in every direction, with rotations and a scale change; through
  // registerNext as well (the sequence path), where a failed pair must not spoil the next one.
  KltRegistrar sequence(configFor(MotionModel::kHomography));
  int k = 0;
  double worst_similarity_px = 0.0, worst_homography_px = 0.0;
  for (const double fraction : {0.15, 0.25, 1.0 / 3.0}) {
    for (const double direction_deg : {0.0, 135.0, 250.0}) {
      const double shift_px = fraction * kWidth;
      const double a = direction_deg * M_PI / 180.0;
      const double rotation = ((k % 3) - 1) * 6.0 * M_PI / 180.0;
      const Eigen::Matrix3d big = similarityAboutCentre(
          rotation, 1.0 + 0.02 * ((k % 2) ? 1 : -1), shift_px * std::cos(a), shift_px * std::sin(a), kWidth, kHeight);
      ++k;
      SCOPED_TRACE("shift " + std::to_string(shift_px) + " px towards " + std::to_string(direction_deg) + " deg");
      const testing::WarpedPair far = makeWarpedPair(picture(), big, kWidth, kHeight, 1.0, 0, 10 + k);
      // The similarity, the truth's model: 0.1 px; the homography's eight parameters, fitted on the overlap (down to
      // half the image), extrapolate to the far corners less well.
      KltRegistrar registrar(configFor(MotionModel::kSimilarity));
      const MotionEstimate e = registrar.registerPair(far.a, far.b);
      ASSERT_FALSE(e.failed) << toString(e.failure) << ": " << e.failure_detail;
      EXPECT_LT(cornerTransferError_px(e.pixel_matrix, big, kWidth, kHeight), 0.1);
      sequence.reset();
      sequence.registerNext(far.a);
      const MotionEstimate next = sequence.registerNext(far.b);
      ASSERT_FALSE(next.failed) << toString(next.failure) << ": " << next.failure_detail;
      EXPECT_LT(cornerTransferError_px(next.pixel_matrix, big, kWidth, kHeight), 0.3);
      worst_similarity_px = std::max(worst_similarity_px, cornerTransferError_px(e.pixel_matrix, big, kWidth, kHeight));
      worst_homography_px =
          std::max(worst_homography_px, cornerTransferError_px(next.pixel_matrix, big, kWidth, kHeight));
    }
  }
  std::printf(
      "[ info ] shifts up to a third of the width, rotations to 6 deg: worst corner error %.4f px (similarity), "
      "%.4f px (homography, sequence path)\n",
      worst_similarity_px, worst_homography_px);
}

TEST(KltRegistrar, TheCoarseSearchDoesNotMakeUnrelatedImagesMatch) {
  KltRegistrar registrar;
  const cv::Mat a = sampleImage(seabedPicture(1024, 7), Eigen::Matrix3d::Identity(), kWidth, kHeight);
  const cv::Mat b = sampleImage(seabedPicture(1024, 99), Eigen::Matrix3d::Identity(), kWidth, kHeight);
  const MotionEstimate e = registrar.registerPair(a, b);
  EXPECT_TRUE(e.failed);
  EXPECT_TRUE(registrar.lastDiagnostics().coarse_searched);
  EXPECT_NE(e.failure_detail.find("coarse search"), std::string::npos) << e.failure_detail;
  KltConfig bad;
  bad.coarse.ratio = 0.0;
  EXPECT_NE(bad.validate().find("coarse: ratio"), std::string::npos) << bad.validate();
}

TEST(KltRegistrar, ReportsInvalidInputAndNoPreviousFrame) {
  KltRegistrar registrar;
  const testing::WarpedPair pair =
      makeWarpedPair(picture(), similarityAboutCentre(0.0, 1.0, 3.0, 2.0, kWidth, kHeight), kWidth, kHeight);
  MotionEstimate e = registrar.registerNext(pair.a);
  EXPECT_TRUE(e.failed);
  EXPECT_EQ(e.failure, FailureReason::kNoPreviousFrame);
  e = registrar.registerNext(pair.b);
  EXPECT_FALSE(e.failed) << e.failure_detail;

  // A size change fails and the new image becomes the previous one.
  const cv::Mat smaller = pair.a(cv::Rect(0, 0, 320, 240)).clone();
  e = registrar.registerNext(smaller);
  EXPECT_TRUE(e.failed);
  EXPECT_EQ(e.failure, FailureReason::kInvalidInput);
  e = registrar.registerNext(pair.b(cv::Rect(0, 0, 320, 240)).clone());
  EXPECT_FALSE(e.failed) << e.failure_detail;

  cv::Mat colour;
  cv::cvtColor(pair.a, colour, cv::COLOR_GRAY2BGR);
  EXPECT_EQ(registrar.registerNext(colour).failure, FailureReason::kInvalidInput);
  EXPECT_EQ(registrar.registerNext(cv::Mat()).failure, FailureReason::kInvalidInput);
  EXPECT_EQ(registrar.registerPair(pair.a, smaller).failure, FailureReason::kInvalidInput);

  registrar.reset();
  EXPECT_EQ(registrar.registerNext(pair.a).failure, FailureReason::kNoPreviousFrame);
}

TEST(KltRegistrar, ConfigValidationNamesTheField) {
  KltConfig config;
  EXPECT_EQ(config.validate(), "");
  config.window_px = 14;
  config.max_motion_fraction = 0.0;
  const std::string error = config.validate();
  EXPECT_NE(error.find("window_px"), std::string::npos) << error;
  EXPECT_NE(error.find("max_motion_fraction"), std::string::npos) << error;
  EXPECT_THROW(KltRegistrar{config}, std::invalid_argument);
  KltConfig homography;
  homography.model = MotionModel::kHomography;
  homography.min_tracks = 3;
  EXPECT_NE(homography.validate().find("min_tracks"), std::string::npos);
}

// --- Sequences ---

/// A camera gliding over the picture: frame k samples the picture through image_to_picture[k]; the motion of pair
/// (k-1, k) is image_to_picture[k]^-1 * image_to_picture[k-1]. Small roll and pitch make it a homography.
struct Sequence {
  std::vector<cv::Mat> frames;
  std::vector<Eigen::Matrix3d> truth;  ///< truth[k]: from frame k-1 to frame k (truth[0] unused)
};

Sequence makeSequence(const cv::Mat& pic, int width, int height, int count, double speed_px, double noise_sigma,
                      bool perspective, uint32_t seed) {
  Sequence s;
  std::mt19937 rng(seed);
  const Eigen::Vector2d c = centreOf(width, height);
  Eigen::Matrix3d previous = Eigen::Matrix3d::Identity();
  for (int k = 0; k < count; ++k) {
    const double t = k;
    // Position of the image centre in the picture, heading, altitude (scale) and tilt vary smoothly.
    const double x = 0.5 * (pic.cols - 1) - 0.5 * speed_px * count + speed_px * t;
    const double y = 0.5 * (pic.rows - 1) + 6.0 * std::sin(0.13 * t);
    const double heading = 0.15 * std::sin(0.05 * t), scale = 1.0 + 0.03 * std::sin(0.07 * t);
    const double g = perspective ? 1.0 / width : 0.0;
    const double g1 = 0.05 * g * std::sin(0.11 * t), g2 = 0.05 * g * std::cos(0.09 * t);
    Eigen::Matrix3d centring = Eigen::Matrix3d::Identity(), m = Eigen::Matrix3d::Identity();
    centring(0, 2) = -c.x();
    centring(1, 2) = -c.y();
    m << scale * std::cos(heading), -scale * std::sin(heading), x,  //
        scale * std::sin(heading), scale * std::cos(heading), y,    //
        g1, g2, 1.0;
    const Eigen::Matrix3d image_to_picture = m * centring;
    cv::Mat frame = sampleImage(pic, image_to_picture, width, height);
    if (noise_sigma > 0.0) {
      cv::Mat f, noise(frame.size(), CV_32F);
      cv::theRNG().state = rng();
      cv::randn(noise, 0.0, noise_sigma);
      frame.convertTo(f, CV_32F);
      f += noise;
      f.convertTo(frame, CV_8U);
    }
    s.frames.push_back(frame);
    s.truth.push_back(k == 0 ? Eigen::Matrix3d::Identity() : Eigen::Matrix3d(image_to_picture.inverse() * previous));
    previous = image_to_picture;
  }
  return s;
}

double percentile(std::vector<double> v, double q) {
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<size_t>(q * v.size()))];
}

TEST(KltRegistrar, RegistersASequenceWithRedetection) {
  const Sequence s = makeSequence(seabedPicture(1400, 5), 720, 576, 40, 8.0, 1.5, true, 4);
  KltRegistrar registrar(configFor(MotionModel::kHomography));
  std::vector<double> errors;
  int detections = 0;
  size_t fewest_features = 1000;
  Eigen::Matrix3d prediction = Eigen::Matrix3d::Identity();
  for (size_t k = 0; k < s.frames.size(); ++k) {
    const MotionEstimate e = registrar.registerNext(s.frames[k], prediction);
    fewest_features = std::min(fewest_features, registrar.features().size());
    if (k == 0) {
      EXPECT_EQ(e.failure, FailureReason::kNoPreviousFrame);
      continue;
    }
    detections += registrar.lastDiagnostics().detected > 0;
    ASSERT_FALSE(e.failed) << "pair " << k << ": " << toString(e.failure) << " " << e.failure_detail;
    errors.push_back(cornerTransferError_px(e.pixel_matrix, s.truth[k], 720, 576));
    prediction = e.pixel_matrix;  // constant velocity
  }
  const double median = percentile(errors, 0.5), p95 = percentile(errors, 0.95);
  std::printf(
      "[ info ] PAL sequence (homography, noise 1.5, 8 px/frame): corner error median %.4f px, 95%% %.4f px, "
      "max %.4f px; %d re-detections in %zu pairs, never fewer than %zu features\n",
      median, p95, *std::max_element(errors.begin(), errors.end()), detections, errors.size(), fewest_features);
  EXPECT_LE(median, 0.1);
  EXPECT_LE(p95, 0.5);
  // The camera travels 40 % of the image width: the features leaving the image are replaced, in the new cells.
  EXPECT_GE(detections, 1);
  EXPECT_GE(fewest_features, 0.6 * registrar.config().max_features);
}

TEST(KltRegistrar, SimilarityOnASimilaritySequence) {
  const Sequence s = makeSequence(seabedPicture(1400, 6), 720, 576, 25, 5.0, 1.0, false, 9);
  KltRegistrar registrar;  // default: similarity
  std::vector<double> errors;
  for (size_t k = 0; k < s.frames.size(); ++k) {
    const MotionEstimate e = registrar.registerNext(s.frames[k]);
    if (k == 0) continue;
    ASSERT_FALSE(e.failed) << "pair " << k << ": " << e.failure_detail;
    errors.push_back(cornerTransferError_px(e.pixel_matrix, s.truth[k], 720, 576));
  }
  std::printf("[ info ] PAL similarity sequence: corner error median %.4f px, 95%% %.4f px\n", percentile(errors, 0.5),
              percentile(errors, 0.95));
  EXPECT_LE(percentile(errors, 0.5), 0.1);
  EXPECT_LE(percentile(errors, 0.95), 0.5);
}

// Derivatives computed around the tracked points only give the same tracks, bit for bit, as whole pyramid levels.
TEST(KltRegistrar, DerivativesOnDemandMatchWholeLevels) {
  const Sequence s = makeSequence(seabedPicture(1400, 8), 720, 576, 30, 9.0, 1.5, true, 21);
  KltConfig on = configFor(MotionModel::kHomography), off = on;
  off.derivatives_on_demand = false;
  KltRegistrar lazy(on), whole(off);
  Eigen::Matrix3d prediction = Eigen::Matrix3d::Identity();
  for (size_t k = 0; k < s.frames.size(); ++k) {
    const MotionEstimate a = lazy.registerNext(s.frames[k], prediction);
    const MotionEstimate b = whole.registerNext(s.frames[k], prediction);
    ASSERT_EQ(a.failed, b.failed) << "frame " << k;
    EXPECT_EQ(a.parameters, b.parameters) << "frame " << k;
    EXPECT_EQ(a.inliers, b.inliers) << "frame " << k;
    EXPECT_EQ(lazy.features(), whole.features()) << "frame " << k;
    if (!a.failed) prediction = a.pixel_matrix;
  }
  const testing::WarpedPair pair =
      makeWarpedPair(picture(), similarityAboutCentre(0.02, 1.01, 5.0, -3.0, kWidth, kHeight), kWidth, kHeight, 2.0);
  EXPECT_EQ(lazy.registerPair(pair.a, pair.b).parameters, whole.registerPair(pair.a, pair.b).parameters);
}

// Prints the steady-state frame rate of registerNext on one thread (no assertion on time): a straight run at
// 8 px per frame, so that features leave the image and detection runs now and then, as on a survey line.
void speedCheck(const char* name, int width, int height, int count, MotionModel model) {
  cv::setNumThreads(1);
  const double speed_px = 8.0;
  const int picture_px = static_cast<int>(std::max(width, height) * 1.3 + speed_px * count);
  const Sequence s = makeSequence(seabedPicture(picture_px, 3), width, height, count, speed_px, 1.5,
                                  model == MotionModel::kHomography, 12);
  KltRegistrar registrar(configFor(model));
  Eigen::Matrix3d prediction = Eigen::Matrix3d::Identity();
  int failures = 0, detections = 0;
  double pyramid = 0, track = 0, fit = 0, detect = 0;
  const int warmup = 3;
  std::chrono::steady_clock::time_point start;
  for (int i = 0; i < count; ++i) {
    if (i == warmup) start = std::chrono::steady_clock::now();
    const MotionEstimate e = registrar.registerNext(s.frames[i], prediction);
    prediction = e.failed ? Eigen::Matrix3d::Identity() : e.pixel_matrix;
    if (i >= warmup) {
      failures += e.failed;
      const KltDiagnostics& d = registrar.lastDiagnostics();
      pyramid += d.pyramid_ms, track += d.track_ms, fit += d.fit_ms, detect += d.detect_ms;
      detections += d.detected > 0;
    }
  }
  const int timed = count - warmup;
  const double elapsed_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf(
      "[ info ] speed %s %dx%d %s, 1 thread: %.0f frames/s (%.3f ms/frame: pyramid %.3f, track %.3f, fit %.3f, "
      "detect %.3f amortised over %d detections); %d failures in %d\n",
      name, width, height, toString(model).c_str(), timed / elapsed_s, 1e3 * elapsed_s / timed, pyramid / timed,
      track / timed, fit / timed, detect / timed, detections, failures, timed);
  EXPECT_EQ(failures, 0);
}

TEST(KltRegistrar, SpeedPal) {
  speedCheck("PAL", 720, 576, 150, MotionModel::kSimilarity);
  speedCheck("PAL", 720, 576, 150, MotionModel::kHomography);
}

TEST(KltRegistrar, SpeedHd) { speedCheck("HD", 1920, 1080, 60, MotionModel::kSimilarity); }

}  // namespace
}  // namespace registration
}  // namespace exocet_mosaic
