// Evaluator against the published PatchMatch Stereo rates, PFM round trip, evaluate_disparity tool.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "exocet_common/testing/paths.h"
#include "exocet_stereo/dense/evaluation.h"
#include "exocet_stereo/io/pfm.h"

namespace {

using namespace exocet_stereo;

const std::string kData = exocet_common::testing::sharedDataDir() + "/middlebury_stereo/";

// Half a unit of the last printed digit: "2.09" -> 0.005, "15.0" -> 0.05.
double printedTolerance(const std::string& text) {
  const size_t dot = text.find('.');
  const int decimals = dot == std::string::npos ? 0 : static_cast<int>(text.size() - dot - 1);
  return 0.5 * std::pow(10.0, -decimals) + 1e-9;
}

TEST(DenseEvaluation, ReproducesPublishedPatchMatchRates) {
  std::ifstream csv(kData + "reference_patchmatch_badpixels.csv");
  ASSERT_TRUE(csv.good());
  std::string line;
  int rows_checked = 0;
  while (std::getline(csv, line)) {
    if (line.empty() || line[0] == '#' || line.rfind("scene", 0) == 0) continue;
    std::vector<std::string> fields;
    std::stringstream stream(line);
    std::string field;
    while (std::getline(stream, field, ',')) fields.push_back(field);
    ASSERT_EQ(fields.size(), 6u) << line;
    const dense::MiddleburyScene scene = dense::loadMiddleburyScene(kData + fields[0]);
    ASSERT_EQ(scene.scale, std::stoi(fields[1]));
    const cv::Mat patchmatch =
        dense::readScaledDisparityPng(kData + fields[0] + "/alg117_patchmatch_result.png", scene.scale, false);
    const dense::BadPixelRates rates = dense::evaluateDisparity(patchmatch, scene, std::stod(fields[2]));
    EXPECT_NEAR(rates.nonocc, std::stod(fields[3]), printedTolerance(fields[3])) << line;
    EXPECT_NEAR(rates.all, std::stod(fields[4]), printedTolerance(fields[4])) << line;
    EXPECT_NEAR(rates.disc, std::stod(fields[5]), printedTolerance(fields[5])) << line;
    ++rows_checked;
  }
  EXPECT_EQ(rows_checked, 12);
}

TEST(DenseEvaluation, UnknownCountsAsBadAndMaskSelects) {
  cv::Mat gt(4, 5, CV_32F, cv::Scalar(3.0f)), mask(4, 5, CV_8U, cv::Scalar(255));
  cv::Mat estimate = gt.clone();
  estimate.at<float>(0, 0) = std::numeric_limits<float>::quiet_NaN();  // unknown: bad
  estimate.at<float>(1, 1) = 4.0f;                                     // exactly 1 px off: good
  estimate.at<float>(2, 2) = 4.01f;                                    // beyond 1 px: bad
  EXPECT_NEAR(dense::badPixelPercent(estimate, gt, mask), 100.0 * 2 / 20, 1e-9);
  mask.at<uint8_t>(2, 2) = 128;  // not evaluated
  EXPECT_NEAR(dense::badPixelPercent(estimate, gt, mask), 100.0 * 1 / 19, 1e-9);
  EXPECT_THROW(dense::badPixelPercent(estimate, gt, mask(cv::Rect(0, 0, 2, 2))), std::invalid_argument);
}

TEST(Pfm, RoundTripKeepsValuesAndMarksUnknownAsInfinity) {
  cv::Mat image(7, 11, CV_32F);
  cv::randu(image, -50.0f, 50.0f);
  image.at<float>(3, 4) = std::numeric_limits<float>::quiet_NaN();
  const std::string path = testing::TempDir() + "/round_trip.pfm";
  io::writePfm(path, image);
  const cv::Mat back = io::readPfm(path);
  ASSERT_EQ(back.type(), CV_32FC1);
  ASSERT_EQ(back.size(), image.size());
  for (int y = 0; y < image.rows; ++y)
    for (int x = 0; x < image.cols; ++x) {
      if (y == 3 && x == 4) {
        EXPECT_TRUE(std::isinf(back.at<float>(y, x)));
      } else {
        EXPECT_EQ(back.at<float>(y, x), image.at<float>(y, x));
      }
    }
  // Layout: header "Pf", "11 7", negative scale (little-endian), then the BOTTOM row first.
  std::ifstream raw(path, std::ios::binary);
  std::string magic;
  int width, height;
  double scale;
  raw >> magic >> width >> height >> scale;
  raw.get();
  EXPECT_EQ(magic, "Pf");
  EXPECT_EQ(width, 11);
  EXPECT_EQ(height, 7);
  EXPECT_LT(scale, 0.0);
  float first;
  raw.read(reinterpret_cast<char*>(&first), sizeof(first));
  EXPECT_EQ(first, image.at<float>(6, 0));
}

TEST(Pfm, RejectsBadFilesAndTypes) {
  EXPECT_THROW(io::readPfm(testing::TempDir() + "/does_not_exist.pfm"), std::runtime_error);
  const std::string path = testing::TempDir() + "/truncated.pfm";
  std::ofstream(path) << "Pf\n10 10\n-1.0\n"
                      << "abc";
  EXPECT_THROW(io::readPfm(path), std::runtime_error);
  EXPECT_THROW(io::writePfm(path, cv::Mat(3, 3, CV_8U)), std::invalid_argument);
}

TEST(EvaluateDisparityTool, PrintsRatesOfThePatchMatchResult) {
  const std::string command = exocet_common::testing::executableDir() + "/evaluate_disparity --disparity " + kData +
                              "venus/alg117_patchmatch_result.png --scene " + kData + "venus 2>/dev/null";
  FILE* pipe = popen(command.c_str(), "r");
  ASSERT_NE(pipe, nullptr);
  char buffer[512] = {0};
  std::string output;
  while (fgets(buffer, sizeof(buffer), pipe)) output += buffer;
  EXPECT_EQ(pclose(pipe), 0);
  EXPECT_NE(output.find("nonocc 0.21 %"), std::string::npos) << output;
  const std::string bad =
      exocet_common::testing::executableDir() + "/evaluate_disparity --disparity x.pfm >/dev/null 2>&1";
  const int status = std::system(bad.c_str());
  EXPECT_EQ(WEXITSTATUS(status), 2);
}

}  // namespace
