/**
 * @file registration_fixtures.h
 * @brief Test image pairs with an exactly known motion: both images are sampled from one procedural seabed picture
 * through known pixel matrices, so the motion between them is known to machine precision.
 */
#pragma once

#include <cstdint>
#include <random>

#include <Eigen/Dense>
#include <opencv2/imgproc.hpp>

#include "exocet_mosaic/sim/procedural_seabed.h"

namespace exocet_mosaic {
namespace registration {
namespace testing {

/// A grey picture of a procedural seabed, `size_px` square, at 2 mm per pixel (gamma-encoded like a camera).
inline cv::Mat seabedPicture(int size_px, uint64_t seed = 7) {
  sim::ProceduralSeabedConfig config;
  config.seed = seed;
  sim::ProceduralSeabedTexture texture(config);
  const double texel_m = texture.baseTexelSize_m();
  sim::WorldRect area{0.0, 0.0, size_px * texel_m, size_px * texel_m};
  const sim::TexturePatch<cv::Vec3f> patch = texture.albedoPatch(0, area);
  cv::Mat gray(size_px, size_px, CV_8UC1);
  for (int r = 0; r < size_px; ++r) {
    for (int c = 0; c < size_px; ++c) {
      const cv::Vec3f a = patch.sample((c + 0.5) * texel_m, (r + 0.5) * texel_m);
      const double lum = 0.3 * a[0] + 0.59 * a[1] + 0.11 * a[2];
      gray.at<uint8_t>(r, c) = cv::saturate_cast<uint8_t>(255.0 * std::pow(std::min(1.0, 1.6 * lum), 1.0 / 2.2));
    }
  }
  return gray;
}

/// Samples `picture` through `image_to_picture` (pixel matrix from the image to the picture), bicubic.
inline cv::Mat sampleImage(const cv::Mat& picture, const Eigen::Matrix3d& image_to_picture, int width, int height) {
  cv::Mat m(3, 3, CV_64F);
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) m.at<double>(r, c) = image_to_picture(r, c);
  cv::Mat out;
  cv::warpPerspective(picture, out, m, cv::Size(width, height), cv::INTER_CUBIC | cv::WARP_INVERSE_MAP,
                      cv::BORDER_REFLECT);
  return out;
}

struct WarpedPair {
  cv::Mat a, b;              ///< CV_8UC1
  Eigen::Matrix3d truth_ab;  ///< x_B ~ truth_ab * x_A
};

/**
 * Image A is the centre of a seabed picture; image B is the picture seen through `truth_ab` (x_B ~ truth_ab x_A).
 * Optional Gaussian noise (grey levels, 1 sigma) in both, and `outlier_blobs` bright discs (a fish, particles) pasted
 * in B only.
 */
inline WarpedPair makeWarpedPair(const cv::Mat& picture, const Eigen::Matrix3d& truth_ab, int width, int height,
                                 double noise_sigma = 0.0, int outlier_blobs = 0, uint32_t seed = 3) {
  WarpedPair pair;
  Eigen::Matrix3d a_to_picture = Eigen::Matrix3d::Identity();
  a_to_picture(0, 2) = 0.5 * (picture.cols - width);
  a_to_picture(1, 2) = 0.5 * (picture.rows - height);
  pair.truth_ab = truth_ab / truth_ab(2, 2);
  pair.a = sampleImage(picture, a_to_picture, width, height);
  pair.b = sampleImage(picture, a_to_picture * truth_ab.inverse(), width, height);
  std::mt19937 rng(seed);
  if (noise_sigma > 0.0) {
    for (cv::Mat* img : {&pair.a, &pair.b}) {
      cv::Mat noise(img->size(), CV_32F);
      cv::randn(noise, 0.0, noise_sigma);
      cv::Mat f;
      img->convertTo(f, CV_32F);
      f += noise;
      f.convertTo(*img, CV_8U);
    }
  }
  std::uniform_real_distribution<double> ux(0.0, width), uy(0.0, height), ur(8.0, 30.0);
  for (int i = 0; i < outlier_blobs; ++i)
    cv::circle(pair.b, cv::Point(int(ux(rng)), int(uy(rng))), int(ur(rng)), cv::Scalar(230 - 20 * (i % 3)), cv::FILLED,
               cv::LINE_AA);
  return pair;
}

/// Pixel matrix of a similarity about the image centre: rotation (rad), scale, translation (px).
inline Eigen::Matrix3d similarityAboutCentre(double rotation_rad, double scale, double tx_px, double ty_px, int width,
                                             int height) {
  const double cx = 0.5 * (width - 1), cy = 0.5 * (height - 1);
  Eigen::Matrix3d c = Eigen::Matrix3d::Identity(), m = Eigen::Matrix3d::Identity();
  c(0, 2) = -cx;
  c(1, 2) = -cy;
  m(0, 0) = scale * std::cos(rotation_rad);
  m(0, 1) = -scale * std::sin(rotation_rad);
  m(1, 0) = scale * std::sin(rotation_rad);
  m(1, 1) = scale * std::cos(rotation_rad);
  m(0, 2) = tx_px;
  m(1, 2) = ty_px;
  return c.inverse() * m * c;
}

}  // namespace testing
}  // namespace registration
}  // namespace exocet_mosaic
