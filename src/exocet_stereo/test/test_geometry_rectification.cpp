// Rectification of the calibrated chessboard rig (2D4 report section 3.2.4): after cv::stereoRectify and the remap,
// the chessboard corners found again in the rectified images lie on the same row in both (and so do the raw corners
// mapped through the rectification).
#include <cmath>
#include <iostream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "exocet_common/testing/paths.h"
#include "exocet_stereo/geometry/chessboard_detection.h"
#include "exocet_stereo/geometry/rig_calibration.h"
#include "exocet_stereo/geometry/stereo_rectification.h"

namespace {

using namespace exocet_stereo::geometry;

const std::string kDir = exocet_common::testing::sharedDataDir() + "/stereo_chessboard";

std::vector<int> pairNumbers() { return {1, 2, 3, 4, 5, 6, 7, 8, 9, 11, 12, 13, 14}; }

std::string image(const char* side, int i) {
  char name[32];
  std::snprintf(name, sizeof(name), "%s%02d.jpg", side, i);
  return kDir + "/" + name;
}

TEST(Rectification, ChessboardCornersShareRowsAfterRectification) {
  std::vector<std::string> left, right;
  for (int i : pairNumbers()) {
    left.push_back(image("left", i));
    right.push_back(image("right", i));
  }
  const StereoRig rig = calibrateStereoRig(left, right);
  const Rectification rect = computeRectification(rig, 0.0);
  EXPECT_NEAR(rect.baseline(), rig.baseline_m, 1e-6 * rig.baseline_m + 1e-9);
  EXPECT_NEAR(rect.focal_px(), rect.P2.at<double>(0, 0), 1e-9);

  ChessboardPattern pattern;
  double sum2_rect = 0.0, sum2_mapped = 0.0, sum2_raw = 0.0, worst_rect = 0.0;
  int n_rect = 0, n_mapped = 0, pairs_found = 0;
  for (size_t k = 0; k < left.size(); ++k) {
    const cv::Mat l = cv::imread(left[k], cv::IMREAD_GRAYSCALE), r = cv::imread(right[k], cv::IMREAD_GRAYSCALE);
    std::vector<cv::Point2f> cl, cr;
    ASSERT_TRUE(detectChessboard(l, pattern, cl));
    ASSERT_TRUE(detectChessboard(r, pattern, cr));
    const auto ml = rectifyPoints(rig, rect, cl, false), mr = rectifyPoints(rig, rect, cr, true);
    for (size_t i = 0; i < cl.size(); ++i) {
      sum2_mapped += std::pow(ml[i].y - mr[i].y, 2);
      sum2_raw += std::pow(cl[i].y - cr[i].y, 2);
      ++n_mapped;
    }
    cv::Mat lr, rr;
    rectifyPair(rect, l, r, lr, rr);
    std::vector<cv::Point2f> rl, rrc;
    if (!detectChessboard(lr, pattern, rl) || !detectChessboard(rr, pattern, rrc)) continue;
    ++pairs_found;
    for (size_t i = 0; i < rl.size(); ++i) {
      const double dy = rl[i].y - rrc[i].y;
      sum2_rect += dy * dy;
      worst_rect = std::max(worst_rect, std::abs(dy));
      ++n_rect;
    }
  }
  const double rms_rect = std::sqrt(sum2_rect / std::max(n_rect, 1));
  const double rms_mapped = std::sqrt(sum2_mapped / n_mapped);
  const double rms_raw = std::sqrt(sum2_raw / n_mapped);
  std::cout << "row difference: raw " << rms_raw << " px rms; mapped corners " << rms_mapped
            << " px rms; corners re-detected in " << pairs_found << " rectified pairs " << rms_rect << " px rms, worst "
            << worst_rect << " px\n";
  EXPECT_GT(rms_raw, 2.0);  // the raw pair is not rectified
  EXPECT_GE(pairs_found, 10);
  EXPECT_LT(rms_mapped, 0.5);
  EXPECT_LT(rms_rect, 0.5);
}

TEST(Rectification, RejectsRigWithoutExtrinsicsAndBadAlpha) {
  const StereoRig stored = readStereoRig(kDir + "/intrinsics.yml");  // M1..D2 only
  EXPECT_THROW(computeRectification(stored), std::invalid_argument);
  StereoRig rig = stored;
  rig.has_extrinsics = true;
  rig.R = cv::Mat::eye(3, 3, CV_64F);
  rig.T = (cv::Mat_<double>(3, 1) << -0.1, 0, 0);
  rig.image_size = cv::Size(640, 480);
  EXPECT_THROW(computeRectification(rig, 2.0), std::invalid_argument);
  EXPECT_NO_THROW(computeRectification(rig, 1.0));
}

}  // namespace
