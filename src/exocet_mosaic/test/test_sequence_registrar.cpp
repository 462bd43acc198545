// The registration front-end's policy: restarts, the prediction scaled to the frame interval, undistortion from the
// calibration, bad input. A scripted registrar records what the front-end asks of it.
#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <stdexcept>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "exocet_mosaic/registration/frame_registrar.h"
#include "exocet_mosaic/registration/motion_model.h"
#include "exocet_mosaic/registration/registration_config.h"
#include "exocet_mosaic/registration/sequence_registrar.h"

namespace exocet_mosaic {
namespace registration {
namespace {

/// Returns a fixed translation for every pair and records the predictions and images it was given.
class ScriptedRegistrar : public FrameRegistrar {
 public:
  struct Log {
    std::vector<Eigen::Matrix3d> predictions;
    std::vector<cv::Mat> images;
    int resets = 0;
  };
  ScriptedRegistrar(Log* log, Eigen::Vector2d shift_px) : log_(log), shift_px_(shift_px) {}

  void reset() override {
    ++log_->resets;
    have_previous_ = false;
  }
  MotionEstimate registerNext(const cv::Mat& gray, const Eigen::Matrix3d& prediction_px) override {
    log_->images.push_back(gray);
    MotionEstimate e;
    if (!have_previous_) {
      have_previous_ = true;
      return e;  // kNoPreviousFrame
    }
    log_->predictions.push_back(prediction_px);
    e.failed = false;
    e.failure = FailureReason::kNone;
    e.model = MotionModel::kTranslation;
    e.centre_px = Eigen::Vector2d(gray.cols / 2.0, gray.rows / 2.0);
    e.parameters = shift_px_;
    e.covariance = Eigen::Matrix2d::Identity() * 0.01;
    e.pixel_matrix = pixelMatrix(e.model, e.parameters, e.centre_px);
    return e;
  }
  MotionEstimate registerPair(const cv::Mat&, const cv::Mat& current, const Eigen::Matrix3d& prediction) override {
    have_previous_ = false;
    registerNext(current, prediction);
    return registerNext(current, prediction);
  }
  RegistrationMethod method() const override { return RegistrationMethod::kKlt; }

 private:
  Log* log_;
  Eigen::Vector2d shift_px_;
  bool have_previous_ = false;
};

cv::Mat image(int width = 64, int height = 48) {
  cv::Mat m(height, width, CV_8UC1);
  cv::randu(m, 0, 255);
  return m;
}

SequenceRegistrar scripted(ScriptedRegistrar::Log* log, SequenceRegistrarConfig config = {}) {
  return SequenceRegistrar(std::make_unique<ScriptedRegistrar>(log, Eigen::Vector2d(3.0, -1.0)), config);
}

TEST(SequenceRegistrar, TheFirstImageGivesNoMotionTheSecondGivesOneWithThePreviousStamp) {
  ScriptedRegistrar::Log log;
  SequenceRegistrar sequence = scripted(&log);
  const SequenceStep first = sequence.add(image(), 10.0);
  EXPECT_FALSE(first.has_motion);
  EXPECT_TRUE(first.restart_reason.empty());
  const SequenceStep second = sequence.add(image(), 10.04);
  ASSERT_TRUE(second.has_motion);
  EXPECT_FALSE(second.motion.failed);
  EXPECT_DOUBLE_EQ(second.previous_stamp_s, 10.0);
  EXPECT_EQ(second.image_size, cv::Size(64, 48));
  EXPECT_FALSE(second.undistorted);
  EXPECT_FALSE(second.camera_matrix.has_value());
}

TEST(SequenceRegistrar, ThePredictionIsThePreviousMotionScaledToTheIntervalAndCapped) {
  ScriptedRegistrar::Log log;
  SequenceRegistrarConfig config;
  config.max_prediction_ratio = 4.0;
  SequenceRegistrar sequence = scripted(&log, config);
  sequence.add(image(), 1.0);
  sequence.add(image(), 1.04);  // no previous motion yet: identity
  sequence.add(image(), 1.08);  // same interval: the previous motion
  sequence.add(image(), 1.16);  // one dropped frame: twice the previous motion
  sequence.add(image(), 1.96);  // 0.8 s after 0.08 s: ratio 10, capped at 4
  ASSERT_EQ(log.predictions.size(), 4u);
  EXPECT_TRUE(log.predictions[0].isIdentity());
  EXPECT_NEAR(log.predictions[1](0, 2), 3.0, 1e-9);
  EXPECT_NEAR(log.predictions[1](1, 2), -1.0, 1e-9);
  EXPECT_NEAR(log.predictions[2](0, 2), 6.0, 1e-9);
  EXPECT_NEAR(log.predictions[2](1, 2), -2.0, 1e-9);
  EXPECT_NEAR(log.predictions[3](0, 2), 12.0, 1e-9);
  EXPECT_NEAR(log.predictions[3](1, 2), -4.0, 1e-9);
}

TEST(SequenceRegistrar, AGapStampsGoingBackAndASizeChangeRestartTheSequence) {
  ScriptedRegistrar::Log log;
  SequenceRegistrarConfig config;
  config.max_gap_s = 1.0;
  SequenceRegistrar sequence = scripted(&log, config);
  sequence.add(image(), 5.0);
  ASSERT_TRUE(sequence.add(image(), 5.5).has_motion);

  SequenceStep gap = sequence.add(image(), 7.0);
  EXPECT_FALSE(gap.has_motion);
  EXPECT_NE(gap.restart_reason.find("gap of 1.5 s"), std::string::npos) << gap.restart_reason;
  ASSERT_TRUE(sequence.add(image(), 7.1).has_motion);
  // After a restart the prediction starts from identity again.
  ASSERT_EQ(log.predictions.size(), 2u);
  EXPECT_TRUE(log.predictions[1].isIdentity());

  SequenceStep back = sequence.add(image(), 6.0);
  EXPECT_FALSE(back.has_motion);
  EXPECT_NE(back.restart_reason.find("went back"), std::string::npos) << back.restart_reason;

  sequence.add(image(), 6.1);
  SequenceStep resized = sequence.add(image(80, 60), 6.2);
  EXPECT_FALSE(resized.has_motion);
  EXPECT_NE(resized.restart_reason.find("64x48 to 80x60"), std::string::npos) << resized.restart_reason;
  EXPECT_TRUE(sequence.add(image(80, 60), 6.3).has_motion);
}

TEST(SequenceRegistrar, BadInputIsRefusedAndLeavesTheSequenceAsItWas) {
  ScriptedRegistrar::Log log;
  SequenceRegistrar sequence = scripted(&log);
  sequence.add(image(), 1.0);
  EXPECT_THROW(sequence.add(cv::Mat(), 1.04), std::invalid_argument);
  EXPECT_THROW(sequence.add(cv::Mat(48, 64, CV_8UC3), 1.04), std::invalid_argument);
  EXPECT_THROW(sequence.add(image(), std::nan("")), std::invalid_argument);
  EXPECT_THROW(sequence.add(image(), -1.0), std::invalid_argument);
  const SequenceStep next = sequence.add(image(), 1.04);
  EXPECT_TRUE(next.has_motion);
  EXPECT_DOUBLE_EQ(next.previous_stamp_s, 1.0);
  // A duplicated stamp (an image sent twice): skipped, the sequence goes on from the first one, no restart.
  try {
    sequence.add(image(), 1.04);
    ADD_FAILURE() << "a duplicated stamp was registered";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("duplicated stamp"), std::string::npos) << e.what();
  }
  const SequenceStep after = sequence.add(image(), 1.08);
  EXPECT_TRUE(after.has_motion);
  EXPECT_TRUE(after.restart_reason.empty()) << after.restart_reason;
  EXPECT_DOUBLE_EQ(after.previous_stamp_s, 1.04);
}

TEST(SequenceRegistrar, InvalidSettingsAndAMissingRegistrarAreNamed) {
  SequenceRegistrarConfig config;
  config.max_gap_s = 0.0;
  ScriptedRegistrar::Log log;
  try {
    scripted(&log, config);
    FAIL() << "max_gap_s = 0 was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("max_gap_s"), std::string::npos) << e.what();
  }
  config = SequenceRegistrarConfig();
  config.max_prediction_ratio = 0.5;
  EXPECT_NE(config.validate().find("max_prediction_ratio"), std::string::npos);
  EXPECT_THROW(SequenceRegistrar(nullptr, SequenceRegistrarConfig()), std::invalid_argument);
}

TEST(SequenceRegistrar, ACalibrationUndistortsImagesOfItsSizeAndAChangeRestarts) {
  ScriptedRegistrar::Log log;
  SequenceRegistrar sequence = scripted(&log);
  CameraCalibration calibration;
  calibration.size = cv::Size(64, 48);
  calibration.k = {60.0, 0.0, 32.0, 0.0, 60.0, 24.0, 0.0, 0.0, 1.0};
  calibration.d = {-0.2, 0.05, 0.0, 0.0, 0.0};
  calibration.distortion_model = "plumb_bob";
  sequence.setCalibration(calibration);

  const cv::Mat raw = image();
  const SequenceStep first = sequence.add(raw, 1.0);
  EXPECT_TRUE(first.undistorted);
  ASSERT_TRUE(first.camera_matrix.has_value());
  EXPECT_TRUE(first.camera_matrix->isApprox(sequence.undistorter().cameraMatrix()));
  // The registrar saw the undistorted image, not the raw one.
  const cv::Mat expected = sequence.undistorter().apply(raw);
  EXPECT_EQ(cv::norm(log.images.back(), expected, cv::NORM_INF), 0.0);
  EXPECT_TRUE(sequence.add(image(), 1.04).has_motion);

  calibration.d[0] = -0.1;
  sequence.setCalibration(calibration);
  const SequenceStep changed = sequence.add(image(), 1.08);
  EXPECT_FALSE(changed.has_motion);
  EXPECT_EQ(changed.restart_reason, "the camera calibration changed");

  // Another size: registered as it is, with a warning; no camera matrix for it.
  const SequenceStep other = sequence.add(image(80, 60), 1.12);
  EXPECT_FALSE(other.undistorted);
  EXPECT_FALSE(other.camera_matrix.has_value());
  EXPECT_NE(other.calibration_warning.find("differs from the calibration's 64x48"), std::string::npos)
      << other.calibration_warning;

  calibration.distortion_model = "equidistant";
  sequence.setCalibration(calibration);
  const SequenceStep unsupported = sequence.add(image(), 1.16);
  EXPECT_NE(unsupported.calibration_warning.find("'equidistant' is not supported"), std::string::npos)
      << unsupported.calibration_warning;
}

TEST(SequenceRegistrar, WithoutDistortionTheCalibrationGivesItsCameraMatrix) {
  ScriptedRegistrar::Log log;
  SequenceRegistrar sequence = scripted(&log);
  CameraCalibration calibration;
  calibration.size = cv::Size(64, 48);
  calibration.k = {60.0, 0.0, 32.0, 0.0, 61.0, 24.0, 0.0, 0.0, 1.0};
  sequence.setCalibration(calibration);
  sequence.add(image(), 1.0);
  const SequenceStep second = sequence.add(image(), 1.04);
  EXPECT_TRUE(second.has_motion);  // a first calibration without distortion does not restart
  EXPECT_FALSE(second.undistorted);
  ASSERT_TRUE(second.camera_matrix.has_value());
  EXPECT_DOUBLE_EQ((*second.camera_matrix)(1, 1), 61.0);
  EXPECT_DOUBLE_EQ((*second.camera_matrix)(0, 2), 32.0);
}

TEST(SequenceRegistrar, ImagesBeforeTheFirstCalibrationAreHeldForTheWaitOnly) {
  SequenceRegistrarConfig config;
  config.calibration_wait_s = 0.5;
  CameraCalibration calibration;
  calibration.size = cv::Size(64, 48);
  calibration.k = {60.0, 0.0, 32.0, 0.0, 61.0, 24.0, 0.0, 0.0, 1.0};

  // The calibration comes within the wait: nothing is held any more, and the held images, registered then, have
  // their camera matrix.
  ScriptedRegistrar::Log log;
  SequenceRegistrar sequence = scripted(&log, config);
  for (double t : {1.0, 1.04, 1.08}) EXPECT_TRUE(sequence.holdForCalibration(t)) << t;
  EXPECT_FALSE(sequence.hasCalibration());
  sequence.setCalibration(calibration);
  EXPECT_FALSE(sequence.holdForCalibration(1.12));
  sequence.add(image(), 1.0);
  const SequenceStep first_motion = sequence.add(image(), 1.04);
  ASSERT_TRUE(first_motion.has_motion);
  ASSERT_TRUE(first_motion.camera_matrix.has_value());

  // No calibration ever: the wait runs out after calibration_wait_s of image time and does not come back; a stamp
  // that is not finite does not end it.
  ScriptedRegistrar::Log uncalibrated_log;
  SequenceRegistrar uncalibrated = scripted(&uncalibrated_log, config);
  EXPECT_TRUE(uncalibrated.holdForCalibration(2.0));
  EXPECT_FALSE(uncalibrated.holdForCalibration(std::nan("")));
  EXPECT_TRUE(uncalibrated.holdForCalibration(2.49));
  EXPECT_TRUE(uncalibrated.holdForCalibration(1.9));  // stamps went back: the wait counts from there
  EXPECT_TRUE(uncalibrated.holdForCalibration(2.39));
  EXPECT_FALSE(uncalibrated.holdForCalibration(2.4));
  EXPECT_FALSE(uncalibrated.holdForCalibration(2.41));
  EXPECT_FALSE(uncalibrated.holdForCalibration(1.0));

  // The default holds nothing.
  ScriptedRegistrar::Log default_log;
  EXPECT_FALSE(scripted(&default_log).holdForCalibration(1.0));

  config.calibration_wait_s = 61.0;
  EXPECT_NE(config.validate().find("calibration_wait_s"), std::string::npos);
}

TEST(SequenceRegistrar, ReplacingTheRegistrarStartsANewSequence) {
  ScriptedRegistrar::Log log, other_log;
  SequenceRegistrar sequence = scripted(&log);
  sequence.add(image(), 1.0);
  sequence.add(image(), 1.04);
  sequence.replaceRegistrar(std::make_unique<ScriptedRegistrar>(&other_log, Eigen::Vector2d(1.0, 1.0)));
  EXPECT_FALSE(sequence.add(image(), 1.08).has_motion);
  EXPECT_TRUE(sequence.add(image(), 1.12).has_motion);
  EXPECT_EQ(other_log.predictions.size(), 1u);
}

TEST(SequenceRegistrar, DrivesARealRegistrarOnAShiftedPair) {
  cv::Mat texture(240, 320, CV_8UC1);
  cv::randu(texture, 0, 255);
  cv::GaussianBlur(texture, texture, cv::Size(0, 0), 2.0);
  const cv::Mat a = texture(cv::Rect(20, 20, 256, 192)).clone();
  const cv::Mat b = texture(cv::Rect(24, 17, 256, 192)).clone();  // the scene moves by (-4, +3) px
  RegistrationConfig config;
  config.method = RegistrationMethod::kKlt;
  config.model = MotionModel::kTranslation;
  SequenceRegistrar sequence(makeRegistrar(config), SequenceRegistrarConfig());
  sequence.add(a, 100.0);
  const SequenceStep step = sequence.add(b, 100.04);
  ASSERT_TRUE(step.has_motion);
  ASSERT_FALSE(step.motion.failed) << step.motion.failure_detail;
  EXPECT_NEAR(step.motion.pixel_matrix(0, 2), -4.0, 0.1);
  EXPECT_NEAR(step.motion.pixel_matrix(1, 2), 3.0, 0.1);
}

}  // namespace
}  // namespace registration
}  // namespace exocet_mosaic
