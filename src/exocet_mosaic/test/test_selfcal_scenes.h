/**
 * @file test_selfcal_scenes.h
 * @brief Synthetic self-calibration sequences with exact ground truth, shared by the self-calibration tests and
 * benchmark: a downward camera over a seabed with (or without) relief, key frames with a rotation about the optical
 * axis plus roll and pitch and a translation (the report's "theta_z + (theta_x, theta_y)" experiment), seabed points
 * seen in several key frames with Gaussian image noise and optional gross mismatches.
 */
#pragma once

#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include <Eigen/Dense>
#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "exocet_mosaic/selfcal/feature_track_builder.h"
#include "exocet_mosaic/selfcal/mendonca_cipolla_calibrator.h"

namespace exocet_mosaic {
namespace selfcal {
namespace testing {

struct SyntheticSequenceConfig {
  Intrinsics truth{650.0, 630.0, 372.0, 281.0};  ///< deliberately not square, not centred
  cv::Size image_size{720, 576};
  int key_frames = 8;
  double altitude_m = 3.0;        ///< camera height above the reference plane
  double relief_m = 0.5;          ///< seabed heights within +-relief_m (0: flat)
  double step_m = 0.25;           ///< translation between consecutive key frames
  double yaw_span_deg = 40.0;     ///< rotation about the vertical over the sequence (theta_z)
  double roll_pitch_deg = 8.0;    ///< amplitude of roll and pitch (theta_x, theta_y)
  double noise_px = 0.5;          ///< Gaussian image noise (1 sigma, each coordinate)
  double outlier_fraction = 0.0;  ///< share of observations replaced by a random pixel
  int seabed_points = 3000;
  uint64_t seed = 1;
};

struct SyntheticSequence {
  std::vector<Eigen::Isometry3d> world_from_camera;  ///< camera optical frames (z along the optical axis)
  std::vector<KeyFramePair> pairs;                   ///< noisy matches of every key-frame pair sharing >= 30 points
  std::vector<std::vector<bool>> outliers;           ///< per pair, per match: a gross mismatch
  std::vector<std::vector<Eigen::Vector2d>> exact_a, exact_b;  ///< per pair, per match: the noise-free projections
  std::vector<Eigen::Matrix3d> true_F;                         ///< per pair: the exact F (unit norm)
};

/// Seabed height (m) at (x, y): smooth mounds within +-relief_m.
inline double seabedHeight_m(double relief_m, double x, double y) {
  return relief_m * (0.6 * std::sin(2.0 * M_PI * x / 2.3 + 0.4) * std::sin(2.0 * M_PI * y / 1.9 + 1.1) +
                     0.4 * std::sin(2.0 * M_PI * (x + 0.7 * y) / 1.3));
}

/// Camera pose of key frame k: along x, yawing, rolling and pitching, looking down.
inline Eigen::Isometry3d syntheticCameraPose(const SyntheticSequenceConfig& c, int k) {
  const double s = c.key_frames > 1 ? static_cast<double>(k) / (c.key_frames - 1) : 0.0;
  const double deg = M_PI / 180.0;
  const double yaw = (s - 0.5) * c.yaw_span_deg * deg;
  const double roll = c.roll_pitch_deg * deg * std::sin(2.0 * M_PI * k / 5.0);
  const double pitch = c.roll_pitch_deg * deg * std::cos(2.0 * M_PI * k / 3.7 + 0.3);
  Eigen::Matrix3d down;  // camera x = world x, camera y = -world y, camera z = -world z
  down << 1, 0, 0, 0, -1, 0, 0, 0, -1;
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix() * down *
                  Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitX()).toRotationMatrix() *
                  Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitY()).toRotationMatrix();
  pose.translation() = Eigen::Vector3d(k * c.step_m, 0.15 * std::sin(1.3 * k), c.altitude_m + 0.1 * std::cos(0.9 * k));
  return pose;
}

inline Eigen::Matrix3d skewMatrix(const Eigen::Vector3d& v) {
  Eigen::Matrix3d s;
  s << 0.0, -v.z(), v.y(), v.z(), 0.0, -v.x(), -v.y(), v.x(), 0.0;
  return s;
}

/// The exact F (b^T F a = 0) between two camera poses.
inline Eigen::Matrix3d trueFundamental(const Eigen::Matrix3d& K, const Eigen::Isometry3d& world_from_a,
                                       const Eigen::Isometry3d& world_from_b) {
  const Eigen::Isometry3d b_from_a = world_from_b.inverse() * world_from_a;
  const Eigen::Matrix3d E = skewMatrix(b_from_a.translation()) * b_from_a.linear();
  Eigen::Matrix3d F = K.inverse().transpose() * E * K.inverse();
  return F / F.norm();
}

inline SyntheticSequence makeSyntheticSequence(const SyntheticSequenceConfig& c) {
  std::mt19937_64 rng(c.seed);
  std::normal_distribution<double> noise(0.0, c.noise_px);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  SyntheticSequence seq;
  for (int k = 0; k < c.key_frames; ++k) seq.world_from_camera.push_back(syntheticCameraPose(c, k));
  // Seabed points spread over the area the cameras see.
  const double half_width = c.altitude_m * 0.5 * c.image_size.width / c.truth.alpha_u + 0.5;
  const double x_min = -half_width, x_max = (c.key_frames - 1) * c.step_m + half_width;
  std::vector<Eigen::Vector3d> points(c.seabed_points);
  for (Eigen::Vector3d& p : points) {
    p.x() = x_min + (x_max - x_min) * unit(rng);
    p.y() = -half_width + 2.0 * half_width * unit(rng);
    p.z() = seabedHeight_m(c.relief_m, p.x(), p.y());
  }
  const Eigen::Matrix3d K = c.truth.K();
  // Each point's observation in each key frame (noisy once, as a track would give it), or nothing.
  std::vector<std::vector<Eigen::Vector2d>> seen(c.key_frames, std::vector<Eigen::Vector2d>(points.size()));
  std::vector<std::vector<Eigen::Vector2d>> exact(c.key_frames, std::vector<Eigen::Vector2d>(points.size()));
  std::vector<std::vector<bool>> visible(c.key_frames, std::vector<bool>(points.size(), false));
  std::vector<std::vector<bool>> wrong(c.key_frames, std::vector<bool>(points.size(), false));
  for (int k = 0; k < c.key_frames; ++k) {
    const Eigen::Isometry3d camera_from_world = seq.world_from_camera[k].inverse();
    for (size_t i = 0; i < points.size(); ++i) {
      const Eigen::Vector3d pc = camera_from_world * points[i];
      if (pc.z() <= 0.1) continue;
      const Eigen::Vector2d px = (K * pc).hnormalized();
      if (px.x() < 0.0 || px.y() < 0.0 || px.x() > c.image_size.width - 1 || px.y() > c.image_size.height - 1) continue;
      visible[k][i] = true;
      exact[k][i] = px;
      if (unit(rng) < c.outlier_fraction) {
        wrong[k][i] = true;
        seen[k][i] = Eigen::Vector2d(unit(rng) * (c.image_size.width - 1), unit(rng) * (c.image_size.height - 1));
      } else {
        seen[k][i] = px + Eigen::Vector2d(noise(rng), noise(rng));
      }
    }
  }
  for (int a = 0; a < c.key_frames; ++a) {
    for (int b = a + 1; b < c.key_frames; ++b) {
      KeyFramePair pair;
      pair.key_a = a;
      pair.key_b = b;
      pair.frame_a = a;
      pair.frame_b = b;
      std::vector<bool> outlier;
      std::vector<Eigen::Vector2d> exact_a, exact_b;
      for (size_t i = 0; i < points.size(); ++i) {
        if (!visible[a][i] || !visible[b][i]) continue;
        pair.points_a.push_back(seen[a][i]);
        pair.points_b.push_back(seen[b][i]);
        pair.track_ids.push_back(static_cast<int>(i));
        outlier.push_back(wrong[a][i] || wrong[b][i]);
        exact_a.push_back(exact[a][i]);
        exact_b.push_back(exact[b][i]);
      }
      if (pair.track_ids.size() < 30) continue;
      seq.pairs.push_back(pair);
      seq.outliers.push_back(outlier);
      seq.exact_a.push_back(exact_a);
      seq.exact_b.push_back(exact_b);
      seq.true_F.push_back(trueFundamental(K, seq.world_from_camera[a], seq.world_from_camera[b]));
    }
  }
  return seq;
}

/**
 * @brief The rendered dive of the end-to-end test and benchmark.
 *
 * A 90-degree lens at 4 m: the simulator's relief is gentle (its rocks are a few centimetres high, its mounds smooth
 * over metres), and the deviation of the seabed from a plane grows with the footprint, so a wide footprint (8 x 6 m)
 * is what gives parallax. The start (-15.5, -6) is where a scan of the relief found the most off-plane height over
 * such a footprint. A 1 m leg, then a turn in place (the 0.4 m lever arm moves the camera on a circle) with roll and
 * pitch oscillations: the report's "theta_z + (theta_x, theta_y)" motion. 14 s at 5 fps: 71 frames of 384x288.
 * Key frames every 7 frames (kRenderedDiveStep).
 */
inline constexpr char kRenderedReliefDiveYaml[] = R"(
seed: 20261201
seabed_depth_m: 40.0
seabed: {kind: procedural, relief: true, relief_scale: 2.0}
camera: {width: 384, height: 288, fx: 192.0, fy: 192.0, cx: 191.5, cy: 143.5, fps: 5, encoding: mono8,
         lever_arm_m: [0.4, 0.0, -0.3]}
duration_s: 14
trajectory:
  kind: out_and_back
  start_x_m: -15.5
  start_y_m: -6.0
  heading_deg: 90
  speed_mps: 0.5
  acceleration_mps2: 0.5
  line_length_m: 1.0
  altitude_m: 4.0
  roll_amplitude_deg: 6.0
  roll_period_s: 7
  pitch_amplitude_deg: 6.0
  pitch_period_s: 9
  turn_rate_deg_s: 15
imaging: {noise_sigma_dn: 1.0}
)";
inline constexpr int kRenderedDiveStep = 7;

}  // namespace testing
}  // namespace selfcal
}  // namespace exocet_mosaic
