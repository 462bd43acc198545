// Registration on whole sequences: a simulated dive against its ground truth (turbid and dark stretches included),
// the real Sparus AUV frames against a SIFT + RANSAC reference; the motion models, the encodings, method auto.
#include <cmath>
#include <filesystem>
#include <iomanip>
#include <sstream>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "exocet_mosaic/registration/fallback_registrar.h"
#include "exocet_mosaic/registration/gray_converter.h"
#include "exocet_mosaic/registration/normalizing_registrar.h"
#include "exocet_mosaic/registration/registration_config.h"
#include "exocet_mosaic/registration/sequence_evaluation.h"
#include "exocet_mosaic/registration/sift_reference.h"
#include "exocet_mosaic/sim/dive_description.h"
#include "exocet_mosaic/sim/image_motion_truth.h"
#include "exocet_mosaic/sim/rendered_dive.h"
#include "exocet_common/testing/paths.h"
#include "registration_fixtures.h"
#include "shared_data.h"

namespace {

using namespace exocet_mosaic;
using namespace exocet_mosaic::registration;
namespace fixtures = exocet_mosaic::registration::testing;

RegistrationConfig config(RegistrationMethod method, MotionModel model) {
  RegistrationConfig c;
  c.method = method;
  c.model = model;
  return c;
}

// ---- Motion models ---------------------------------------------------------------------------------------------

TEST(MotionModel, ParametersAndMatricesRoundTrip) {
  const Eigen::Vector2d centre(359.5, 287.5);
  Eigen::VectorXd p(8);
  p << 12.5, -3.25, 0.01, -0.02, 0.015, -0.005, 2e-5, -1e-5;
  for (MotionModel model : {MotionModel::kTranslation, MotionModel::kSimilarity, MotionModel::kAffine,
                            MotionModel::kHomography}) {
    const Eigen::VectorXd q = p.head(parameterCount(model));
    const Eigen::Matrix3d h = pixelMatrix(model, q, centre);
    const Eigen::VectorXd back = parametersFromPixelMatrix(model, h, centre, 720, 576);
    EXPECT_LT((back - q).norm(), 1e-9) << toString(model);
    EXPECT_EQ(motionModelFromString(toString(model)), model);
  }
  EXPECT_THROW(motionModelFromString("projective"), std::invalid_argument);
}

TEST(MotionModel, WarpJacobianMatchesFiniteDifferences) {
  Eigen::VectorXd p(8);
  p << 4.0, -2.0, 0.02, -0.01, 0.03, 0.01, 3e-4, -2e-4;
  for (MotionModel model : {MotionModel::kSimilarity, MotionModel::kAffine, MotionModel::kHomography}) {
    const Eigen::VectorXd q = p.head(parameterCount(model));
    const double u = 150.0, v = -90.0;
    const Eigen::MatrixXd j = warpJacobian(model, q, u, v);
    for (int k = 0; k < q.size(); ++k) {
      const double step = 1e-6;
      Eigen::VectorXd qp = q, qm = q;
      qp[k] += step;
      qm[k] -= step;
      const Eigen::Vector3d wp = centredMatrix(model, qp) * Eigen::Vector3d(u, v, 1.0);
      const Eigen::Vector3d wm = centredMatrix(model, qm) * Eigen::Vector3d(u, v, 1.0);
      const Eigen::Vector2d d = (wp.head<2>() / wp.z() - wm.head<2>() / wm.z()) / (2.0 * step);
      EXPECT_NEAR(j(0, k), d.x(), 1e-4 * (1.0 + std::abs(d.x()))) << toString(model) << " parameter " << k;
      EXPECT_NEAR(j(1, k), d.y(), 1e-4 * (1.0 + std::abs(d.y()))) << toString(model) << " parameter " << k;
    }
  }
}

TEST(ImageMotionTruth, PlaneHomographyAgreesWithRayCasting) {
  const exocet_common::CameraModel camera = exocet_common::CameraModel::pal();
  Eigen::Isometry3d a = Eigen::Isometry3d::Identity(), b = Eigen::Isometry3d::Identity();
  // Looking down (camera z to -z of the local frame) from 2.5 m, then moved, turned and tilted a little.
  a.linear() = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()).toRotationMatrix();
  a.translation() = Eigen::Vector3d(1.0, 2.0, 2.5);
  b.linear() = Eigen::AngleAxisd(0.05, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(0.03, Eigen::Vector3d::UnitX()) *
               a.linear();
  b.translation() = Eigen::Vector3d(1.1, 2.05, 2.45);
  const Eigen::Matrix3d h = sim::seabedPlaneHomography(camera, a, b);
  sim::FlatRelief flat;
  for (const Eigen::Vector2d& px : {Eigen::Vector2d(0, 0), Eigen::Vector2d(719, 0), Eigen::Vector2d(300, 400)}) {
    Eigen::Vector2d via_rays;
    ASSERT_TRUE(sim::transferThroughSeabed(camera, a, b, flat, px, &via_rays));
    EXPECT_LT((transferPoint(h, px) - via_rays).norm(), 1e-6);
  }
}

// ---- Encodings -----------------------------------------------------------------------------------------------------

TEST(GrayConverter, EveryEncodingGivesTheSameGrey) {
  const cv::Mat picture = fixtures::seabedPicture(300);
  const cv::Mat gray = picture(cv::Rect(10, 10, 200, 150)).clone();
  GrayConverter converter;
  cv::Mat bgr, rgb, bgra, mono16;
  cv::cvtColor(gray, bgr, cv::COLOR_GRAY2BGR);
  cv::cvtColor(gray, rgb, cv::COLOR_GRAY2RGB);
  cv::cvtColor(gray, bgra, cv::COLOR_GRAY2BGRA);
  for (const auto& [image, encoding] : std::vector<std::pair<cv::Mat, std::string>>{
           {gray, "mono8"}, {bgr, "bgr8"}, {rgb, "rgb8"}, {bgra, "bgra8"}}) {
    const cv::Mat out = converter.convert(image, encoding);
    EXPECT_EQ(cv::norm(out, gray, cv::NORM_INF), 0.0) << encoding;
  }
  // A 12-bit camera in a 16-bit container: scaled by 16, not 256 (which would be nearly black).
  gray.convertTo(mono16, CV_16U, 16.0);
  const cv::Mat out16 = converter.convert(mono16, "mono16");
  EXPECT_LE(cv::norm(out16, gray, cv::NORM_INF), 1.0);
  // A Bayer image of a grey scene demosaics to about the same grey.
  const cv::Mat bayer = converter.convert(gray, "bayer_rggb8");
  EXPECT_LT(cv::norm(bayer(cv::Rect(2, 2, 196, 146)), gray(cv::Rect(2, 2, 196, 146)), cv::NORM_L1) / (196 * 146), 6.0);
}

TEST(GrayConverter, RejectsWhatItCannotReadWithAClearMessage) {
  GrayConverter converter;
  try {
    converter.convert(cv::Mat(10, 10, CV_32FC1, cv::Scalar(0.5)), "32FC1");
    FAIL() << "32FC1 accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("32FC1"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("mono8"), std::string::npos) << e.what();
  }
  EXPECT_THROW(converter.convert(cv::Mat(10, 10, CV_8UC1), "bgr8"), std::invalid_argument);
  EXPECT_THROW(converter.convert(cv::Mat(), "mono8"), std::invalid_argument);
}

// ---- Method auto ---------------------------------------------------------------------------------------------------

TEST(FallbackRegistrar, RmrTakesOverWhereKltFindsNoFeatures) {
  const cv::Mat picture = fixtures::seabedPicture(900);
  const Eigen::Matrix3d truth = fixtures::similarityAboutCentre(0.01, 1.0, 4.0, -3.0, 640, 480);
  const fixtures::WarpedPair pair = fixtures::makeWarpedPair(picture, truth, 640, 480, 1.0);
  RegistrationConfig c = config(RegistrationMethod::kAuto, MotionModel::kSimilarity);
  c.klt.min_eigenvalue = 0.5;  // no corner of a seabed is this strong: KLT finds too little texture
  std::unique_ptr<FrameRegistrar> registrar = makeRegistrar(c);
  auto* normalizing = dynamic_cast<NormalizingRegistrar*>(registrar.get());
  ASSERT_NE(normalizing, nullptr);
  auto* fallback = dynamic_cast<FallbackRegistrar*>(&normalizing->inner());
  ASSERT_NE(fallback, nullptr);
  registrar->registerNext(pair.a);
  const MotionEstimate e = registrar->registerNext(pair.b);
  ASSERT_FALSE(e.failed) << toString(e.failure) << ": " << e.failure_detail;
  EXPECT_EQ(e.method, RegistrationMethod::kRmr);
  EXPECT_LT(cornerTransferError_px(e.pixel_matrix, truth, 640, 480), 0.1);
  EXPECT_EQ(fallback->fallbackAttempts(), 1);
  EXPECT_EQ(fallback->fallbackSuccesses(), 1);
}

TEST(FallbackRegistrar, BothFailingIsOneFailureThatNamesBoth) {
  const cv::Mat blank(480, 640, CV_8UC1, cv::Scalar(100));
  RegistrationConfig c = config(RegistrationMethod::kAuto, MotionModel::kAffine);
  c.illumination.enabled = false;  // the normaliser would stop a blank image before either method sees it
  std::unique_ptr<FrameRegistrar> registrar = makeRegistrar(c);
  registrar->registerNext(blank);
  const MotionEstimate e = registrar->registerNext(blank);
  EXPECT_TRUE(e.failed);
  EXPECT_NE(e.failure_detail.find("rmr also failed"), std::string::npos) << e.failure_detail;
}

TEST(NormalizingRegistrar, DarkAndBlankImagesFailBeforeNormalisationCouldMakeTextureOfNoise) {
  const cv::Mat picture = fixtures::seabedPicture(700);
  const cv::Mat image = picture(cv::Rect(0, 0, 640, 480)).clone();
  cv::Mat dark;
  image.convertTo(dark, CV_8U, 0.02);  // mean about 2 grey levels: noise once stretched
  std::unique_ptr<FrameRegistrar> r = makeRegistrar(config(RegistrationMethod::kAuto, MotionModel::kSimilarity));
  r->registerNext(image);
  MotionEstimate e = r->registerNext(dark);
  EXPECT_TRUE(e.failed);
  EXPECT_EQ(e.failure, FailureReason::kTooDark) << e.failure_detail;
  r->registerNext(image);
  e = r->registerNext(cv::Mat(480, 640, CV_8UC1, cv::Scalar(100)));
  EXPECT_TRUE(e.failed);
  EXPECT_EQ(e.failure, FailureReason::kTooLittleTexture) << e.failure_detail;
}

TEST(RegistrationConfig, RejectsBadValuesNamingTheField) {
  RegistrationConfig c;
  c.klt.window_px = 2;
  EXPECT_NE(c.validate().find("window_px"), std::string::npos) << c.validate();
  EXPECT_THROW(makeRegistrar(c), std::invalid_argument);
  c = RegistrationConfig();
  c.rmr.tukey_constant = 0.0;
  EXPECT_NE(c.validate().find("tukey_constant"), std::string::npos) << c.validate();
}

// ---- A simulated dive against ground truth -------------------------------------------------------------------------

class SimulatedDive : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    // 5 s of the benchmark's dive at video rate, with a turbid second and a dark second moved into it.
    const sim::DiveDescription dive =
        sim::loadDiveDescription(exocet_common::testing::configDir() + "/dives/bench_registration.yaml",
                                 {"duration_s=4.99",
                                  "imaging.segments=[{start_s: 1.0, end_s: 2.0, turbidity: 3.0, light_gain: 1.0}, "
                                  "{start_s: 3.0, end_s: 4.0, turbidity: 1.0, light_gain: 0.3}]"});
    dive_ = new sim::RenderedDive(sim::renderDive(dive, 2));
    truth_.assign(dive_->gray.size(), Eigen::Matrix3d::Identity());
    for (size_t i = 1; i < dive_->gray.size(); ++i)
      truth_[i] = sim::seabedPlaneHomography(dive_->camera, dive_->local_from_camera[i - 1], dive_->local_from_camera[i]);
  }
  static void TearDownTestSuite() { delete dive_; }

  static sim::RenderedDive* dive_;
  static std::vector<Eigen::Matrix3d> truth_;
};
sim::RenderedDive* SimulatedDive::dive_ = nullptr;
std::vector<Eigen::Matrix3d> SimulatedDive::truth_;

TEST_F(SimulatedDive, EveryMethodMeetsTheAccuracyTargets) {
  ASSERT_EQ(dive_->gray.size(), 125u);
  for (RegistrationMethod method : {RegistrationMethod::kKlt, RegistrationMethod::kRmr, RegistrationMethod::kAuto}) {
    SequenceRegistrar r(makeRegistrar(config(method, MotionModel::kHomography)), SequenceRegistrarConfig());
    const std::vector<double>& t = dive_->stamps_s;
    const SequenceScore s = evaluateSequence(r, dive_->gray, t, truth_);
    const SequenceScore dark =
        evaluateSequence(r, dive_->gray, t, truth_, 2.0, [&](int i) { return dive_->light_gain[i] < 1.0; });
    const SequenceScore turbid =
        evaluateSequence(r, dive_->gray, t, truth_, 2.0, [&](int i) { return dive_->turbidity[i] > 1.0; });
    const SequenceScore clear = evaluateSequence(
        r, dive_->gray, t, truth_, 2.0, [&](int i) { return dive_->turbidity[i] == 1.0 && dive_->light_gain[i] == 1.0; });
    std::cout << toString(method) << ": median " << s.median_px << " px, p95 " << s.p95_px << " px, failures "
              << s.failures << ", gross " << s.gross_failures << ", NEES ratio " << s.nees_ratio
              << "; dark stretch: median " << dark.median_px << " p95 " << dark.p95_px << " px over "
              << dark.pairs.size() << " pairs; turbid: median " << turbid.median_px << " p95 " << turbid.p95_px
              << "; clear: median " << clear.median_px << " p95 " << clear.p95_px << "\n";
    EXPECT_LE(s.median_px, 0.1) << toString(method);
    EXPECT_LE(s.p95_px, 0.5) << toString(method);
    EXPECT_EQ(s.gross_failures, 0) << toString(method);
    EXPECT_LE(s.failures, 2) << toString(method);
    EXPECT_LE(dark.median_px, 0.2) << toString(method);
    // The covariance is what the navigation fusion weights the motion by: it must be about right.
    EXPECT_GT(s.nees_ratio, 0.2) << toString(method);
    EXPECT_LT(s.nees_ratio, 5.0) << toString(method);
  }
}

TEST_F(SimulatedDive, TheSimilarityModelIsLimitedByPerspectiveOnly) {
  // The vehicle rolls and pitches by 2 degrees: a similarity cannot follow, but stays within half a pixel.
  SequenceRegistrar r(makeRegistrar(config(RegistrationMethod::kKlt, MotionModel::kSimilarity)),
                      SequenceRegistrarConfig());
  const SequenceScore s = evaluateSequence(r, dive_->gray, dive_->stamps_s, truth_);
  EXPECT_LE(s.median_px, 0.6);
  EXPECT_EQ(s.gross_failures, 0);
}

// ---- Real seabed: the Sparus AUV -----------------------------------------------------------------------------------

TEST(SparusFrames, EstimatesAgreeWithSiftRansacWithinOnePixel) {
  // Undistorted with the dataset's intrinsics, as registration_node does with a camera_info.
  const std::vector<cv::Mat> frames = testing_data::loadSparusFrames(exocet_common::testing::sharedDataDir(), true);
  ASSERT_GE(frames.size(), 20u) << "Sparus frames missing under " << exocet_common::testing::sharedDataDir();
  for (RegistrationMethod method : {RegistrationMethod::kKlt, RegistrationMethod::kRmr}) {
    std::unique_ptr<FrameRegistrar> r = makeRegistrar(config(method, MotionModel::kHomography));
    double worst = 0.0;
    for (size_t i = 0; i < frames.size(); ++i) {
      const MotionEstimate e = r->registerNext(frames[i]);
      if (i == 0) continue;
      const SiftReference ref = siftReferenceHomography(frames[i - 1], frames[i]);
      ASSERT_TRUE(ref.found) << "pair " << i;
      ASSERT_FALSE(e.failed) << toString(method) << " pair " << i << ": " << e.failure_detail;
      const double d = cornerTransferError_px(e.pixel_matrix, ref.pixel_matrix, frames[i].cols, frames[i].rows);
      worst = std::max(worst, d);
      EXPECT_LE(d, 1.0) << toString(method) << " pair " << i;
    }
    std::cout << toString(method) << " on Sparus: largest corner difference to SIFT + RANSAC " << worst << " px\n";
  }
}

}  // namespace
