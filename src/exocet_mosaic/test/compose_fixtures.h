/**
 * @file compose_fixtures.h
 * @brief Simulated seabed for the composer's tests: a truth ortho-image (multi-scale random texture, checker
 * landmarks) with a known UTM geotransform, a nadir-ish camera flying a line with a slow turn, frames rendered by
 * warping the ortho with the exact ground -> image homography, registrations from the true poses, fused poses = truth
 * + noise.
 */
#pragma once

#include <cmath>
#include <optional>
#include <random>
#include <vector>

#include <Eigen/Geometry>
#include <opencv2/imgproc.hpp>

#include "exocet_mosaic/compose/ground_projection.h"
#include "exocet_mosaic/compose/mosaic_composer.h"

namespace compose_test {

using exocet_mosaic::compose::applyHomography;
using exocet_mosaic::compose::CameraGroundPose;
using exocet_mosaic::compose::ClosedMosaic;
using exocet_mosaic::compose::ComposerFrame;

/// The truth: an ortho-image north-up, pixel (c, r) centred at (E0 + (c + 0.5) gsd, N0 - (r + 0.5) gsd).
struct TruthOrtho {
  cv::Mat image;  // CV_8UC3
  double origin_e_m = 0, origin_n_m = 0, gsd_m = 0;

  /// Multi-scale random texture (band-limited: no aliasing when resampled) plus checker landmarks.
  static TruthOrtho make(double width_m, double height_m, double gsd_m, double origin_e_m, double origin_n_m,
                         unsigned seed = 7) {
    TruthOrtho t;
    t.gsd_m = gsd_m;
    t.origin_e_m = origin_e_m;
    t.origin_n_m = origin_n_m;
    const cv::Size size(static_cast<int>(width_m / gsd_m), static_cast<int>(height_m / gsd_m));
    cv::Mat acc(size, CV_32FC3, cv::Scalar::all(120));
    cv::RNG rng(seed);
    const double scales[] = {4, 12, 40, 150};
    const double amps[] = {18, 22, 18, 10};
    for (int k = 0; k < 4; ++k) {
      const cv::Size small(std::max(2, static_cast<int>(size.width / scales[k]) + 2),
                           std::max(2, static_cast<int>(size.height / scales[k]) + 2));
      cv::Mat noise(small, CV_32FC3);
      rng.fill(noise, cv::RNG::NORMAL, cv::Scalar::all(0), cv::Scalar::all(amps[k]));
      cv::Mat up;
      cv::resize(noise, up, size, 0, 0, cv::INTER_CUBIC);
      acc += up;
    }
    // A few checker landmarks (sharp but smoothed by 1 px so that resampling stays faithful).
    for (int i = 0; i < 6; ++i) {
      const int cx = static_cast<int>(rng.uniform(0.1, 0.9) * size.width);
      const int cy = static_cast<int>(rng.uniform(0.2, 0.8) * size.height);
      const int sq = 10;
      for (int y = -3 * sq; y < 3 * sq; ++y)
        for (int x = -3 * sq; x < 3 * sq; ++x) {
          const int px = cx + x, py = cy + y;
          if (px < 0 || py < 0 || px >= size.width || py >= size.height) continue;
          const bool white = ((x + 3 * sq) / sq + (y + 3 * sq) / sq) % 2 == 0;
          acc.at<cv::Vec3f>(py, px) = white ? cv::Vec3f(220, 215, 210) : cv::Vec3f(40, 45, 50);
        }
    }
    cv::GaussianBlur(acc, acc, cv::Size(0, 0), 0.8);
    acc.convertTo(t.image, CV_8UC3);
    return t;
  }

  /// ground (E - E0, N - N0) <- ortho pixel.
  cv::Matx33d groundFromOrthoPx() const { return cv::Matx33d(gsd_m, 0, 0.5 * gsd_m, 0, -gsd_m, -0.5 * gsd_m, 0, 0, 1); }

  /// Renders the image of a camera pose (exact ground -> image homography, bilinear).
  cv::Mat render(const CameraGroundPose& pose, const cv::Size& size) const {
    cv::Matx33d px_from_ground;
    if (!exocet_mosaic::compose::pixelFromGround(pose, size, Eigen::Vector2d(origin_e_m, origin_n_m), &px_from_ground))
      return cv::Mat();
    cv::Mat out;
    cv::warpPerspective(image, out, px_from_ground * groundFromOrthoPx(), size, cv::INTER_LINEAR, cv::BORDER_REFLECT);
    return out;
  }

  /// The truth resampled on a tile's grid (origin = top-left corner, gsd), CV_8UC3.
  cv::Mat onGrid(double origin_e_m_tile, double origin_n_m_tile, double gsd_tile, const cv::Size& size) const {
    // tile px centre -> UTM -> ortho px: col_o = (E - E0) / g - 0.5.
    const double s = gsd_tile / gsd_m;
    const cv::Matx23d a(s, 0, (origin_e_m_tile + 0.5 * gsd_tile - origin_e_m) / gsd_m - 0.5, 0, s,
                        (origin_n_m - origin_n_m_tile + 0.5 * gsd_tile) / gsd_m - 0.5);
    cv::Mat out;
    cv::warpAffine(image, out, a, size, cv::INTER_LINEAR | cv::WARP_INVERSE_MAP, cv::BORDER_REFLECT);
    return out;
  }
};

/// Camera flight: a line east with a slow heading turn and a few degrees of roll and pitch.
struct Flight {
  Eigen::Vector2d start_en_m = Eigen::Vector2d(500000.0, 4800000.0);
  double step_m = 0.02;            // per frame along the track
  double heading_start_rad = 0.0;  // track direction: east, rotating by turn_rad_per_frame
  double turn_rad_per_frame = 0.0;
  double yaw_offset_rad = 0.3;       // camera yaw relative to north-up at frame 0
  double yaw_rate_rad = 0.003;       // camera yaw change per frame
  double tilt_amplitude_rad = 0.05;  // roll / pitch amplitude
  double height_m = 2.2;
  double height_amplitude_m = 0.1;
  cv::Matx33d k = cv::Matx33d(400, 0, 159.5, 0, 400, 119.5, 0, 0, 1);
  cv::Size image_size = cv::Size(320, 240);

  CameraGroundPose pose(int i) const {
    CameraGroundPose p;
    Eigen::Vector2d pos = start_en_m;
    double track = heading_start_rad;
    for (int j = 0; j < i; ++j) {  // integrated so that a turn is a smooth arc
      pos += step_m * Eigen::Vector2d(std::cos(track), std::sin(track));
      track += turn_rad_per_frame;
    }
    p.camera_en_m = pos;
    p.camera_height_m = height_m + height_amplitude_m * std::sin(0.05 * i);
    const double yaw = yaw_offset_rad + yaw_rate_rad * i;
    const double roll = tilt_amplitude_rad * std::sin(0.07 * i), pitch = tilt_amplitude_rad * std::cos(0.05 * i);
    const Eigen::Matrix3d nadir = Eigen::Vector3d(1, -1, -1).asDiagonal();  // optical z down, image top north
    const Eigen::Matrix3d r = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix() *
                              Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitY()).toRotationMatrix() *
                              Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitX()).toRotationMatrix() * nadir;
    p.world_from_camera = Eigen::Quaterniond(r);
    p.camera_matrix = k;
    p.position_cov_m2 = Eigen::Matrix2d::Identity() * 0.01;
    return p;
  }

  /// Exact registration: previous px -> current px, through the ground.
  cv::Matx33d registration(int i) const {
    cv::Matx33d g_prev, px_cur;
    const Eigen::Vector2d o = start_en_m;
    exocet_mosaic::compose::groundFromPixel(pose(i - 1), image_size, o, &g_prev);
    exocet_mosaic::compose::pixelFromGround(pose(i), image_size, o, &px_cur);
    return exocet_mosaic::compose::normalizeHomography(px_cur * g_prev);
  }

  /// True footprint corners (UTM) of frame i.
  std::array<Eigen::Vector2d, 4> footprint(int i) const {
    cv::Matx33d g;
    exocet_mosaic::compose::groundFromPixel(pose(i), image_size, start_en_m, &g);
    const double w = image_size.width, h = image_size.height;
    const Eigen::Vector2d c[4] = {{-0.5, -0.5}, {w - 0.5, -0.5}, {w - 0.5, h - 0.5}, {-0.5, h - 0.5}};
    std::array<Eigen::Vector2d, 4> out;
    for (int k = 0; k < 4; ++k) out[k] = start_en_m + applyHomography(g, c[k]);
    return out;
  }
};

/// Builds the frames of a flight: exact registration, fused pose = truth + position noise (sigma_m).
struct FrameFactory {
  const TruthOrtho* truth = nullptr;
  Flight flight;
  double position_noise_m = 0.0;
  std::mt19937 rng{42};

  ComposerFrame frame(int i, bool with_registration = true, bool with_pose = true) {
    ComposerFrame f;
    f.index = i;
    f.stamp_s = 0.04 * i;
    const CameraGroundPose truth_pose = flight.pose(i);
    f.image = truth->render(truth_pose, flight.image_size);
    if (with_registration && i > 0) f.current_from_previous_px = flight.registration(i);
    if (with_pose) {
      CameraGroundPose p = truth_pose;
      std::normal_distribution<double> n(0.0, 1.0);
      p.camera_en_m += position_noise_m * Eigen::Vector2d(n(rng), n(rng));
      p.position_cov_m2 = Eigen::Matrix2d::Identity() * std::max(1e-6, position_noise_m * position_noise_m);
      f.pose = p;
    }
    return f;
  }
};

/// Mean footprint displacement (m) of a closed mosaic's composed images vs the truth, matching by frame order:
/// composed frame indices are recovered from the nearest true footprint centre among [first, last].
inline Eigen::Vector2d placementError(const ClosedMosaic& tile, const Flight& flight) {
  Eigen::Vector2d sum = Eigen::Vector2d::Zero();
  int n = 0;
  for (const auto& fp : tile.footprints_en_m) {
    // Nearest true frame (by all four corners).
    double best = 1e300;
    Eigen::Vector2d best_d = Eigen::Vector2d::Zero();
    for (int i = tile.first_frame; i <= tile.last_frame; ++i) {
      const auto t = flight.footprint(i);
      Eigen::Vector2d d = Eigen::Vector2d::Zero();
      double e = 0;
      for (int k = 0; k < 4; ++k) {
        d += (fp[k] - t[k]) / 4.0;
        e += (fp[k] - t[k]).squaredNorm();
      }
      if (e < best) {
        best = e;
        best_d = d;
      }
    }
    sum += best_d;
    ++n;
  }
  return n ? Eigen::Vector2d(sum / n) : Eigen::Vector2d(1e9, 1e9);
}

/// Largest rectangle centred at the mask's centroid that lies fully in the mask (shrinking from the bounding box).
inline cv::Rect innerRect(const cv::Mat& mask, double aspect = 1.0) {
  const cv::Moments mo = cv::moments(mask, true);
  if (mo.m00 <= 0) return cv::Rect();
  const cv::Point c(static_cast<int>(mo.m10 / mo.m00), static_cast<int>(mo.m01 / mo.m00));
  cv::Rect best;
  for (int half = 4; half < std::max(mask.cols, mask.rows); half += 2) {
    const int hw = static_cast<int>(half * aspect), hh = half;
    const cv::Rect r(c.x - hw, c.y - hh, 2 * hw, 2 * hh);
    if ((r & cv::Rect(0, 0, mask.cols, mask.rows)) != r) break;
    if (cv::countNonZero(mask(r)) != r.area()) break;
    best = r;
  }
  return best;
}

/// Sub-pixel shift of b relative to a (phase correlation on grey, Hanning window).
inline cv::Point2d phaseShift(const cv::Mat& a, const cv::Mat& b) {
  cv::Mat ga, gb, fa, fb;
  if (a.channels() == 3)
    cv::cvtColor(a, ga, cv::COLOR_BGR2GRAY);
  else
    ga = a;
  if (b.channels() == 3)
    cv::cvtColor(b, gb, cv::COLOR_BGR2GRAY);
  else
    gb = b;
  ga.convertTo(fa, CV_64F);
  gb.convertTo(fb, CV_64F);
  cv::Mat window;
  cv::createHanningWindow(window, fa.size(), CV_64F);
  return cv::phaseCorrelate(fa, fb, window);
}

/// Mean absolute grey difference over a mask.
inline double meanAbsError(const cv::Mat& a, const cv::Mat& b, const cv::Mat& mask) {
  cv::Mat diff;
  cv::absdiff(a, b, diff);
  const cv::Scalar m = cv::mean(diff, mask);
  return (m[0] + m[1] + m[2]) / a.channels();
}

}  // namespace compose_test
