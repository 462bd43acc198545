// RMR registration (robust multiresolution, Odobez-Bouthemy): exact recovery of known warps, robustness to noise,
// outliers and lighting, covariance calibration, explicit failures, sequences, and a speed report.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "exocet_mosaic/registration/rmr_registrar.h"
#include "registration_fixtures.h"

namespace exocet_mosaic {
namespace registration {
namespace {

using testing::makeWarpedPair;
using testing::sampleImage;
using testing::seabedPicture;
using testing::similarityAboutCentre;
using testing::WarpedPair;

constexpr int kWidth = 640;
constexpr int kHeight = 480;

const cv::Mat& picture() {
  static const cv::Mat p = seabedPicture(900, 7);
  return p;
}

// A homography about the image centre: similarity-like part plus perspective terms (a tilted seabed).
Eigen::Matrix3d homographyAboutCentre(double a11, double a12, double a21, double a22, double tx, double ty, double g1,
                                      double g2, int width, int height) {
  Eigen::Matrix3d c = Eigen::Matrix3d::Identity(), m;
  c(0, 2) = -0.5 * (width - 1);
  c(1, 2) = -0.5 * (height - 1);
  m << 1.0 + a11, a12, tx, a21, 1.0 + a22, ty, g1, g2, 1.0;
  return c.inverse() * m * c;
}

double cornerError(const MotionEstimate& e, const Eigen::Matrix3d& truth, int width = kWidth, int height = kHeight) {
  return cornerTransferError_px(e.pixel_matrix, truth, width, height);
}

RmrConfig configFor(MotionModel model) {
  RmrConfig c;
  c.model = model;
  return c;
}

std::string describe(const MotionEstimate& e) {
  return toString(e.failure) + ": " + e.failure_detail + " (iterations " + std::to_string(e.iterations) +
         ", observations " + std::to_string(e.observations) + ", inliers " + std::to_string(e.inliers) + ", scale " +
         std::to_string(e.residual_scale) + ")";
}

struct Case {
  const char* name;
  MotionModel model;
  Eigen::Matrix3d truth;
};

std::vector<Case> knownWarps() {
  return {
      {"similarity", MotionModel::kSimilarity, similarityAboutCentre(0.02, 1.015, 6.3, -4.7, kWidth, kHeight)},
      {"affine", MotionModel::kAffine,
       homographyAboutCentre(0.012, -0.021, 0.018, -0.008, -5.2, 7.9, 0.0, 0.0, kWidth, kHeight)},
      {"homography", MotionModel::kHomography,
       homographyAboutCentre(0.01, -0.02, 0.015, -0.005, 4.4, 3.1, 6e-5, -4e-5, kWidth, kHeight)},
  };
}

TEST(RmrRegistration, RecoversKnownWarpsExactlyWithoutNoise) {
  for (const Case& c : knownWarps()) {
    const WarpedPair pair = makeWarpedPair(picture(), c.truth, kWidth, kHeight);
    RmrRegistrar rmr(configFor(c.model));
    const MotionEstimate e = rmr.registerPair(pair.a, pair.b);
    ASSERT_FALSE(e.failed) << c.name << " " << describe(e);
    const double error = cornerError(e, pair.truth_ab);
    std::printf("[ RMR      ] %-10s noise-free: corner error %.4f px, %d iterations, %d observations, %.1f ms\n",
                c.name, error, e.iterations, e.observations, e.elapsed_ms);
    EXPECT_LT(error, 0.05) << c.name;
    EXPECT_EQ(e.method, RegistrationMethod::kRmr);
    EXPECT_EQ(e.model, c.model);
    EXPECT_EQ(e.parameters.size(), parameterCount(c.model));
    EXPECT_EQ(e.covariance.rows(), parameterCount(c.model));
    EXPECT_NEAR(e.centre_px.x(), 0.5 * (kWidth - 1), 1e-12);
    EXPECT_TRUE(e.pixel_matrix.isApprox(pixelMatrix(c.model, e.parameters, e.centre_px), 1e-12));
    EXPECT_GT(e.inlier_fraction, 0.9);
    EXPECT_EQ(e.weights.type(), CV_32F);
    EXPECT_EQ(e.weights.size(), pair.a.size());
  }
}

// Pair with noise and blobs, and the same pair without the blobs (same noise) to know where the blobs are.
struct BlobPair {
  WarpedPair pair;
  cv::Mat blob_mask_b;  // 255 where a blob changed B
};

BlobPair makeBlobPair(const Eigen::Matrix3d& truth, double noise_sigma, int blobs, uint64_t noise_seed) {
  BlobPair out;
  cv::theRNG().state = noise_seed;
  out.pair = makeWarpedPair(picture(), truth, kWidth, kHeight, noise_sigma, blobs, 11);
  cv::theRNG().state = noise_seed;
  const WarpedPair clean = makeWarpedPair(picture(), truth, kWidth, kHeight, noise_sigma, 0, 11);
  cv::Mat diff;
  cv::absdiff(out.pair.b, clean.b, diff);
  out.blob_mask_b = diff > 0;
  return out;
}

// A pure sub-pixel translation gives every pixel the same fractional offset, so interpolation phase errors do not
// average out: the fixture's bicubic resampling and the registration's bilinear sampling each shift fine texture by
// a few hundredths of a pixel at quarter-pixel offsets (measured on exactly shifted band-limited images: 0.015 px for
// the registration with the default smoothing). Rotation and scale spread the offsets, as in the tests above.
TEST(RmrRegistration, RecoversASubPixelTranslation) {
  const Eigen::Matrix3d truth = similarityAboutCentre(0.0, 1.0, -7.6, 3.3, kWidth, kHeight);
  const WarpedPair pair = makeWarpedPair(picture(), truth, kWidth, kHeight);
  RmrRegistrar rmr(configFor(MotionModel::kTranslation));
  const MotionEstimate e = rmr.registerPair(pair.a, pair.b);
  ASSERT_FALSE(e.failed) << describe(e);
  const double error = cornerError(e, pair.truth_ab);
  std::printf("[ RMR      ] translation (-7.6, 3.3) noise-free: corner error %.4f px\n", error);
  EXPECT_LT(error, 0.1);
  EXPECT_EQ(e.parameters.size(), 2);
}

TEST(RmrRegistration, RecoversWarpsWithNoiseAndOutlierBlobsAndFlagsTheBlobs) {
  for (const Case& c : knownWarps()) {
    const BlobPair bp = makeBlobPair(c.truth, 2.0, 12, 1234);
    RmrRegistrar rmr(configFor(c.model));
    const MotionEstimate e = rmr.registerPair(bp.pair.a, bp.pair.b);
    ASSERT_FALSE(e.failed) << c.name << " " << describe(e);
    const double error = cornerError(e, bp.pair.truth_ab);
    std::printf("[ RMR      ] %-10s noise 2 + 12 blobs: corner error %.4f px, inliers %.3f, scale %.2f\n", c.name,
                error, e.inlier_fraction, e.residual_scale);
    EXPECT_LT(error, 0.2) << c.name;

    // Weights: blob pixels (well inside a blob) mostly outliers, pixels away from any blob mostly inliers.
    cv::Mat inside, near;
    cv::erode(bp.blob_mask_b, inside, cv::Mat(), cv::Point(-1, -1), 2);
    cv::dilate(bp.blob_mask_b, near, cv::Mat(), cv::Point(-1, -1), 3);
    int blob_total = 0, blob_outliers = 0, clean_total = 0, clean_inliers = 0;
    for (int r = 0; r < e.weights.rows; ++r) {
      for (int col = 0; col < e.weights.cols; ++col) {
        const float w = e.weights.at<float>(r, col);
        if (std::isnan(w)) continue;
        EXPECT_GE(w, 0.0f);
        EXPECT_LE(w, 1.0f);
        const Eigen::Vector2d q = transferPoint(bp.pair.truth_ab, Eigen::Vector2d(col, r));
        const int qx = static_cast<int>(std::lround(q.x())), qy = static_cast<int>(std::lround(q.y()));
        if (qx < 0 || qy < 0 || qx >= kWidth || qy >= kHeight) continue;
        if (inside.at<uint8_t>(qy, qx)) {
          ++blob_total;
          blob_outliers += w < 0.5f;
        } else if (!near.at<uint8_t>(qy, qx)) {
          ++clean_total;
          clean_inliers += w > 0.5f;
        }
      }
    }
    ASSERT_GT(blob_total, 100) << c.name;
    const double blob_outlier_share = double(blob_outliers) / blob_total;
    const double clean_inlier_share = double(clean_inliers) / clean_total;
    std::printf("[ RMR      ] %-10s weights: %.3f of %d blob pixels < 0.5, %.3f of %d clean pixels > 0.5\n", c.name,
                blob_outlier_share, blob_total, clean_inlier_share, clean_total);
    EXPECT_GT(blob_outlier_share, 0.8) << c.name;
    EXPECT_GT(clean_inlier_share, 0.9) << c.name;
  }
}

TEST(RmrRegistration, RecoversTheMotionUnderAGlobalLightingChange) {
  const Eigen::Matrix3d truth = similarityAboutCentre(-0.015, 0.99, -3.6, 5.2, kWidth, kHeight);
  WarpedPair pair = makeWarpedPair(picture(), truth, kWidth, kHeight, 1.0);
  pair.b.convertTo(pair.b, CV_8U, 1.3, -20.0);
  RmrConfig config = configFor(MotionModel::kSimilarity);
  config.estimate_illumination = true;
  RmrRegistrar rmr(config);
  const MotionEstimate e = rmr.registerPair(pair.a, pair.b);
  ASSERT_FALSE(e.failed) << describe(e);
  const double error = cornerError(e, pair.truth_ab);
  std::printf("[ RMR      ] lighting gain 1.3 offset -20: corner error %.4f px\n", error);
  EXPECT_LT(error, 0.1);
}

TEST(RmrRegistration, CovarianceMatchesTheScatterOverNoiseSeeds) {
  const Eigen::Matrix3d truth = homographyAboutCentre(0.01, -0.015, 0.012, 0.004, 3.3, -2.7, 0.0, 0.0, kWidth, kHeight);
  const MotionModel model = MotionModel::kAffine;
  const int n = parameterCount(model);
  const Eigen::VectorXd truth_p = parametersFromPixelMatrix(
      model, truth, Eigen::Vector2d(0.5 * (kWidth - 1), 0.5 * (kHeight - 1)), kWidth, kHeight);
  RmrConfig config = configFor(model);
  config.covariance_inflation = 1.0;  // the noise-driven part of the covariance, which this test checks
  RmrRegistrar rmr(config);
  const int runs = 24;
  std::vector<Eigen::VectorXd> errors;
  Eigen::MatrixXd predicted = Eigen::MatrixXd::Zero(n, n);
  for (int run = 0; run < runs; ++run) {
    cv::theRNG().state = 1000 + 17 * run;
    const WarpedPair pair = makeWarpedPair(picture(), truth, kWidth, kHeight, 4.0);
    const MotionEstimate e = rmr.registerPair(pair.a, pair.b);
    ASSERT_FALSE(e.failed) << describe(e);
    errors.push_back(e.parameters - truth_p);
    predicted += e.covariance / runs;
  }
  // Compare variances with the mean error removed (the bilinear interpolation leaves a tiny deterministic bias).
  Eigen::VectorXd mean = Eigen::VectorXd::Zero(n);
  for (const auto& d : errors) mean += d / runs;
  Eigen::MatrixXd empirical = Eigen::MatrixXd::Zero(n, n);
  for (const auto& d : errors) empirical += (d - mean) * (d - mean).transpose() / (runs - 1);
  std::printf("[ RMR      ] covariance (affine, noise 4, %d seeds): empirical / predicted variance:", runs);
  for (int j = 0; j < n; ++j) {
    const double ratio = empirical(j, j) / predicted(j, j);
    std::printf(" %.2f", ratio);
    EXPECT_GT(ratio, 1.0 / 3.0) << "parameter " << j;
    EXPECT_LT(ratio, 3.0) << "parameter " << j;
  }
  // Whole-matrix summary: mean Mahalanobis distance^2 / n of the errors (1 when calibrated).
  double mahalanobis = 0.0;
  const Eigen::MatrixXd inv = predicted.inverse();
  for (const auto& d : errors) mahalanobis += (d - mean).dot(inv * (d - mean)) / (n * (runs - 1));
  std::printf("; Mahalanobis^2 / n %.2f\n", mahalanobis);
  EXPECT_GT(mahalanobis, 1.0 / 3.0);
  EXPECT_LT(mahalanobis, 3.0);
}

TEST(RmrRegistration, ReportsFailureOnBlankDarkAndUnrelatedImages) {
  const Eigen::Matrix3d truth = similarityAboutCentre(0.01, 1.0, 2.0, 1.0, kWidth, kHeight);
  const WarpedPair pair = makeWarpedPair(picture(), truth, kWidth, kHeight, 1.0);
  RmrRegistrar rmr(configFor(MotionModel::kAffine));

  const cv::Mat blank(kHeight, kWidth, CV_8UC1, cv::Scalar(128));
  MotionEstimate e = rmr.registerPair(pair.a, blank);
  EXPECT_TRUE(e.failed);
  std::printf("[ RMR      ] blank: %s\n", describe(e).c_str());
  e = rmr.registerPair(blank, blank);
  EXPECT_TRUE(e.failed);

  cv::Mat dark;
  pair.b.convertTo(dark, CV_8U, 0.03, 0.0);
  cv::Mat noise(dark.size(), CV_8UC1);
  cv::randu(noise, 0, 2);
  dark += noise;
  e = rmr.registerPair(pair.a, dark);
  EXPECT_TRUE(e.failed);
  EXPECT_EQ(e.failure, FailureReason::kTooDark) << describe(e);
  std::printf("[ RMR      ] dark: %s\n", describe(e).c_str());

  for (const uint64_t seed : {11u, 23u, 37u}) {
    const cv::Mat other_picture = seabedPicture(700, seed);
    const WarpedPair other = makeWarpedPair(other_picture, Eigen::Matrix3d::Identity(), kWidth, kHeight, 1.0);
    for (const MotionModel model : {MotionModel::kSimilarity, MotionModel::kAffine, MotionModel::kHomography}) {
      RmrRegistrar r(configFor(model));
      e = r.registerPair(pair.a, other.b);
      EXPECT_TRUE(e.failed) << "seed " << seed << " " << toString(model) << " corner shift "
                            << cornerTransferError_px(e.pixel_matrix, Eigen::Matrix3d::Identity(), kWidth, kHeight);
      std::printf("[ RMR      ] unrelated (seed %d, %s): %s\n", int(seed), toString(model).c_str(),
                  describe(e).c_str());
    }
  }
}

// Frames of a smooth survey over the picture: frame k sees the picture through `frameToPicture(k)`.
Eigen::Matrix3d frameToPicture(int k, int width, int height, const cv::Mat& pic) {
  const double angle = 0.004 * k, scale = 1.0 + 0.002 * std::sin(0.3 * k);
  Eigen::Matrix3d m = similarityAboutCentre(angle, scale, 0.0, 0.0, width, height);
  Eigen::Matrix3d t = Eigen::Matrix3d::Identity();
  t(0, 2) = 0.5 * (pic.cols - width) + 3.1 * k - 40.0;
  t(1, 2) = 0.5 * (pic.rows - height) + 1.7 * k * std::cos(0.1 * k) - 20.0;
  return t * m;
}

TEST(RmrRegistration, RegistersASequenceWithRegisterNext) {
  RmrRegistrar rmr(configFor(MotionModel::kSimilarity));
  const cv::Mat& pic = picture();
  Eigen::Matrix3d previous_to_picture = Eigen::Matrix3d::Identity();
  std::vector<double> errors;
  for (int k = 0; k < 8; ++k) {
    const Eigen::Matrix3d to_picture = frameToPicture(k, kWidth, kHeight, pic);
    const cv::Mat frame = sampleImage(pic, to_picture, kWidth, kHeight);
    const MotionEstimate e = rmr.registerNext(frame);
    if (k == 0) {
      EXPECT_TRUE(e.failed);
      EXPECT_EQ(e.failure, FailureReason::kNoPreviousFrame);
    } else {
      ASSERT_FALSE(e.failed) << "frame " << k << " " << describe(e);
      const Eigen::Matrix3d truth = to_picture.inverse() * previous_to_picture;  // x_B ~ truth x_A
      errors.push_back(cornerError(e, truth));
      EXPECT_LT(errors.back(), 0.1) << "frame " << k;
    }
    previous_to_picture = to_picture;
  }
  std::printf("[ RMR      ] sequence: worst corner error %.4f px\n", *std::max_element(errors.begin(), errors.end()));
  rmr.reset();
  EXPECT_EQ(rmr.registerNext(sampleImage(pic, frameToPicture(0, kWidth, kHeight, pic), kWidth, kHeight)).failure,
            FailureReason::kNoPreviousFrame);
}

TEST(RmrRegistration, SizeChangeAndBadInputAreInvalidInput) {
  RmrRegistrar rmr(configFor(MotionModel::kAffine));
  const WarpedPair pair = makeWarpedPair(picture(), Eigen::Matrix3d::Identity(), kWidth, kHeight);
  EXPECT_EQ(rmr.registerNext(pair.a).failure, FailureReason::kNoPreviousFrame);
  cv::Mat smaller;
  cv::resize(pair.b, smaller, cv::Size(320, 240));
  MotionEstimate e = rmr.registerNext(smaller);
  EXPECT_TRUE(e.failed);
  EXPECT_EQ(e.failure, FailureReason::kInvalidInput);
  // The smaller image became the previous one.
  cv::Mat smaller2;
  cv::resize(pair.a, smaller2, cv::Size(320, 240));
  e = rmr.registerNext(smaller2);
  EXPECT_FALSE(e.failed) << describe(e);

  EXPECT_EQ(rmr.registerPair(pair.a, smaller).failure, FailureReason::kInvalidInput);
  EXPECT_EQ(rmr.registerPair(pair.a, cv::Mat()).failure, FailureReason::kInvalidInput);
  cv::Mat color;
  cv::cvtColor(pair.b, color, cv::COLOR_GRAY2BGR);
  EXPECT_EQ(rmr.registerPair(pair.a, color).failure, FailureReason::kInvalidInput);
  EXPECT_EQ(rmr.registerNext(color).failure, FailureReason::kInvalidInput);
}

TEST(RmrRegistration, FinestLevelOneGivesHalfResolutionWeightsAndFullResolutionParameters) {
  const Eigen::Matrix3d truth =
      homographyAboutCentre(0.01, -0.02, 0.015, -0.005, 4.4, 3.1, 6e-5, -4e-5, kWidth, kHeight);
  const WarpedPair pair = makeWarpedPair(picture(), truth, kWidth, kHeight, 1.0);
  RmrConfig config = configFor(MotionModel::kHomography);
  config.finest_level = 1;
  RmrRegistrar rmr(config);
  const MotionEstimate e = rmr.registerPair(pair.a, pair.b);
  ASSERT_FALSE(e.failed) << describe(e);
  const double error = cornerError(e, pair.truth_ab);
  std::printf("[ RMR      ] homography, finest level 1: corner error %.4f px\n", error);
  EXPECT_LT(error, 0.1);
  EXPECT_EQ(e.weights.cols, kWidth / 2);
  EXPECT_EQ(e.weights.rows, kHeight / 2);
  // The covariance is of the full-resolution parameters: about 4 times the translation variance of level 0's.
  RmrRegistrar full(configFor(MotionModel::kHomography));
  const MotionEstimate e0 = full.registerPair(pair.a, pair.b);
  ASSERT_FALSE(e0.failed) << describe(e0);
  EXPECT_GT(e.covariance(0, 0), e0.covariance(0, 0));
}

TEST(RmrRegistration, ConfigValidation) {
  EXPECT_EQ(RmrConfig().validate(), "");
  RmrConfig c;
  c.pyramid_levels = 0;
  c.tukey_constant = -1.0;
  const std::string message = c.validate();
  EXPECT_NE(message.find("pyramid_levels"), std::string::npos) << message;
  EXPECT_NE(message.find("tukey_constant"), std::string::npos) << message;
  EXPECT_THROW(RmrRegistrar{c}, std::invalid_argument);
}

TEST(RmrRegistration, PyramidCapturesALargeMotion) {
  const Eigen::Matrix3d truth = similarityAboutCentre(3.0 * M_PI / 180.0, 1.0, 40.0, -12.0, kWidth, kHeight);
  const WarpedPair pair = makeWarpedPair(picture(), truth, kWidth, kHeight, 2.0);
  for (const MotionModel model : {MotionModel::kSimilarity, MotionModel::kAffine, MotionModel::kHomography}) {
    RmrRegistrar rmr(configFor(model));
    const MotionEstimate e = rmr.registerPair(pair.a, pair.b);
    ASSERT_FALSE(e.failed) << toString(model) << " " << describe(e);
    const double error = cornerError(e, pair.truth_ab);
    std::printf("[ RMR      ] 40 px + 3 deg (%s): corner error %.4f px\n", toString(model).c_str(), error);
    EXPECT_LT(error, 0.2);
  }
  // The prediction helps too: from a prediction near the truth.
  RmrRegistrar rmr(configFor(MotionModel::kSimilarity));
  const MotionEstimate e =
      rmr.registerPair(pair.a, pair.b, similarityAboutCentre(2.5 * M_PI / 180.0, 1.0, 37.0, -10.0, kWidth, kHeight));
  ASSERT_FALSE(e.failed) << describe(e);
  EXPECT_LT(cornerError(e, pair.truth_ab), 0.2);
}

// Frames per second of registerNext in steady state on one thread (printed, not asserted): of wall time, and of the
// thread's CPU time (which other processes on the machine do not inflate).
struct Speed {
  double wall_fps = 0.0;
  double cpu_fps = 0.0;
  double worst_error_px = 0.0;
};

double threadCpuSeconds() {
  timespec t;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return t.tv_sec + 1e-9 * t.tv_nsec;
}

Speed measureSpeed(int width, int height, MotionModel model) {
  cv::setNumThreads(1);
  const cv::Mat pic = seabedPicture(std::max(width, height) + 300, 5);
  const int frames = 40;
  std::vector<cv::Mat> images;
  std::vector<Eigen::Matrix3d> to_picture;
  for (int k = 0; k < frames; ++k) {
    to_picture.push_back(frameToPicture(k, width, height, pic));
    cv::Mat image = sampleImage(pic, to_picture.back(), width, height);
    cv::Mat noise(image.size(), CV_32F);
    cv::randn(noise, 0.0, 1.5);
    cv::Mat f;
    image.convertTo(f, CV_32F);
    cv::Mat(f + noise).convertTo(image, CV_8U);
    images.push_back(image);
  }
  RmrRegistrar rmr(configFor(model));
  Speed speed;
  int registered = 0;
  double wall_s = 0.0, cpu_s = 0.0;
  for (int repeat = 0; repeat < 3; ++repeat) {
    rmr.reset();
    rmr.registerNext(images[0]);
    rmr.registerNext(images[1]);  // warm-up
    const auto start = std::chrono::steady_clock::now();
    const double cpu_start = threadCpuSeconds();
    Eigen::Matrix3d prediction = Eigen::Matrix3d::Identity();
    for (int k = 2; k < frames; ++k) {
      const MotionEstimate e = rmr.registerNext(images[k], prediction);
      EXPECT_FALSE(e.failed) << describe(e);
      prediction = e.failed ? Eigen::Matrix3d::Identity() : e.pixel_matrix;
      speed.worst_error_px =
          std::max(speed.worst_error_px,
                   cornerTransferError_px(e.pixel_matrix, to_picture[k].inverse() * to_picture[k - 1], width, height));
      ++registered;
    }
    wall_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    cpu_s += threadCpuSeconds() - cpu_start;
  }
  cv::setNumThreads(-1);
  speed.wall_fps = registered / wall_s;
  speed.cpu_fps = registered / cpu_s;
  return speed;
}

TEST(RmrRegistration, SpeedReport) {
  for (const MotionModel model : {MotionModel::kSimilarity, MotionModel::kAffine, MotionModel::kHomography}) {
    const Speed pal = measureSpeed(720, 576, model);
    const Speed hd = measureSpeed(1920, 1080, model);
    std::printf(
        "[ RMR      ] speed (%s, one thread, registerNext): PAL 720x576 %.0f frames/s (%.0f per CPU second; worst "
        "corner error %.3f px), HD 1920x1080 %.0f frames/s (%.0f per CPU second; worst %.3f px)\n",
        toString(model).c_str(), pal.wall_fps, pal.cpu_fps, pal.worst_error_px, hd.wall_fps, hd.cpu_fps,
        hd.worst_error_px);
  }
}

}  // namespace
}  // namespace registration
}  // namespace exocet_mosaic
