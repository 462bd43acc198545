// OpenCV StereoSGBM baseline with the common output convention (CV_32F, NaN where unknown).
#include <cmath>
#include <limits>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include "exocet_stereo/dense/methods.h"

namespace exocet_stereo {
namespace dense {
namespace {

cv::Mat sgbmDisparity(const cv::Mat& left, const cv::Mat& right, const DenseStereoConfig& config) {
  // SGBM wants a multiple of 16 disparities; search more and keep the same output convention.
  const int disparities = ((config.labelCount() + 15) / 16) * 16;
  const int block = 3;  // small block: SGBM's smoothness does the rest
  const int channels = left.channels();
  const int p1 = 8 * channels * block * block, p2 = 32 * channels * block * block;
  cv::Ptr<cv::StereoSGBM> sgbm =
      cv::StereoSGBM::create(0, disparities, block, p1, p2, 1, 63, 10, 100, 2, cv::StereoSGBM::MODE_HH);
  cv::Mat fixed_point;
  sgbm->compute(left, right, fixed_point);  // CV_16S, 4 fractional bits, < 0 where invalid
  cv::Mat disparity(left.size(), CV_32F);
  for (int y = 0; y < left.rows; ++y) {
    const int16_t* in = fixed_point.ptr<int16_t>(y);
    float* out = disparity.ptr<float>(y);
    for (int x = 0; x < left.cols; ++x) {
      const float d = in[x] / 16.0f;
      out[x] = (in[x] < 0 || d > config.max_disparity_px) ? std::numeric_limits<float>::quiet_NaN() : d;
    }
  }
  return disparity;
}

}  // namespace

void SgbmStereo::computeRaw(const cv::Mat& left, const cv::Mat& right, cv::Mat* disparity_left,
                            cv::Mat* disparity_right) const {
  *disparity_left = sgbmDisparity(left, right, config_);
  if (!disparity_right) return;
  // Right view: mirror both images and swap them, so the right image becomes a "left" reference.
  cv::Mat left_flipped, right_flipped, flipped;
  cv::flip(left, left_flipped, 1);
  cv::flip(right, right_flipped, 1);
  flipped = sgbmDisparity(right_flipped, left_flipped, config_);
  cv::flip(flipped, *disparity_right, 1);
}

}  // namespace dense
}  // namespace exocet_stereo
