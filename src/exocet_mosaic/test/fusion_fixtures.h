/**
 * @file fusion_fixtures.h
 * @brief Synthetic navigation streams with ground truth for the fusion tests: a camera flown out and back, its image
 * motion (with heading error and pixel-size error), dead reckoning sharing the heading error, and late USBL fixes,
 * generated from the navigation filter's own models so that the filter's consistency can be checked; plus the
 * batch least-squares solution of the linear case.
 */
#pragma once

#include <algorithm>
#include <cmath>
#include <random>
#include <utility>
#include <vector>

#include <Eigen/Dense>

#include "exocet_mosaic/fusion/navigation_filter.h"

namespace exocet_mosaic {
namespace fusion {
namespace testing {

struct NavEvent {
  enum Kind { kImage, kImageFailure, kDeadReckoning, kFix } kind = kImage;
  double stamp_s = 0.0;
  double previous_stamp_s = 0.0;  ///< images
  double arrival_s = 0.0;
  Eigen::Vector2d value = Eigen::Vector2d::Zero();  ///< displacement (images) or position
  Eigen::Matrix2d covariance = Eigen::Matrix2d::Identity();
};

struct SyntheticDiveConfig {
  uint32_t seed = 1;
  double t0_s = 1000.0;
  double duration_s = 120.0;
  double fps = 5.0;
  double speed_mps = 0.4;
  double heading_rad = 0.7;
  bool out_and_back = true;  ///< false: one straight line
  Eigen::Vector2d start_en_m = Eigen::Vector2d(500000.0, 4770000.0);
  // Image motion
  double image_sigma_m = 0.0005;  ///< per image pair, each axis
  // Truth of the model's states (random draws from these sigmas)
  double pixel_size_sigma = 0.01;
  double heading_sigma_rad = 0.01;
  double heading_drift_sigma_rps = 2e-4;
  // Dead reckoning
  bool with_dr = true;
  double dr_rate_hz = 10.0;
  bool dr_shares_heading = true;
  double dr_scale_sigma = 0.0;  ///< 1-sigma of the DR's velocity scale error (drawn only when > 0)
  double dr_scale_error = 0.0;  ///< added to the draw: a known scale error
  // Fixes
  bool with_fixes = true;
  double fix_rate_hz = 1.0;
  double fix_sigma_m = 0.5;
  double fix_latency_s = 1.5;
  double fix_outlier_probability = 0.0;
  double fix_outlier_m = 8.0;
  std::vector<std::pair<double, double>> fix_dropouts_s;  ///< [start, end) from t0
  std::vector<std::pair<double, double>> image_failures_s;  ///< image pairs ending in [start, end) fail
  double image_latency_s = 0.03;
  /// Filter model parameters that the generator follows (noise densities).
  FilterConfig model;
};

struct SyntheticDive {
  std::vector<NavEvent> events;  ///< in arrival order
  std::vector<double> image_stamps_s;
  std::vector<Eigen::Vector2d> truth_at_images;  ///< true camera centre at each image stamp
  Eigen::Vector2d initial_estimate = Eigen::Vector2d::Zero();
  Eigen::Matrix2d initial_covariance = 0.01 * Eigen::Matrix2d::Identity();
  std::vector<int> fix_outlier_indices;  ///< indices in `events` of outlying fixes
};

inline Eigen::Matrix2d rot2(double a) {
  return (Eigen::Matrix2d() << std::cos(a), -std::sin(a), std::sin(a), std::cos(a)).finished();
}

inline bool inIntervals(double t, const std::vector<std::pair<double, double>>& intervals) {
  for (const auto& i : intervals)
    if (t >= i.first && t < i.second) return true;
  return false;
}

/// A dive generated from the filter's models (config.model), so that a correct filter is consistent on it.
inline SyntheticDive makeSyntheticDive(const SyntheticDiveConfig& config) {
  std::mt19937 rng(config.seed);
  std::normal_distribution<double> n01;
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  const auto gauss2 = [&](double sigma) { return Eigen::Vector2d(sigma * n01(rng), sigma * n01(rng)); };
  const FilterConfig& m = config.model;
  SyntheticDive dive;

  // Truth path: out and back along the heading with a lateral wiggle.
  const Eigen::Vector2d along(std::cos(config.heading_rad), std::sin(config.heading_rad));
  const Eigen::Vector2d across(-along.y(), along.x());
  const double half = 0.5 * config.duration_s;
  const auto truth = [&](double t) -> Eigen::Vector2d {
    const double tau = t - config.t0_s;
    const double s = tau < half || !config.out_and_back ? config.speed_mps * tau
                                                         : config.speed_mps * (config.duration_s - tau);
    return config.start_en_m + s * along + 0.3 * std::sin(2.0 * M_PI * tau / 40.0) * across;
  };
  dive.initial_estimate = truth(config.t0_s) + Eigen::Vector2d(0.1 * n01(rng), 0.1 * n01(rng));
  dive.initial_covariance = 0.01 * Eigen::Matrix2d::Identity();

  const int frames = static_cast<int>(std::floor(config.duration_s * config.fps + 1e-9)) + 1;
  const double dt = 1.0 / config.fps;
  double psi = config.heading_sigma_rad * n01(rng);
  double psi_dot = config.heading_drift_sigma_rps * n01(rng);
  double c = config.pixel_size_sigma * n01(rng);
  double dr_scale = config.dr_scale_error + (config.dr_scale_sigma > 0.0 ? config.dr_scale_sigma * n01(rng) : 0.0);
  Eigen::Vector2d d = Eigen::Vector2d(3.0, -2.0);  // DR offset: arbitrary, the filter initialises it from the DR
  std::vector<Eigen::Vector2d> dr_offset_at_images;
  for (int k = 0; k < frames; ++k) {
    // Stamps as t0 + index / rate for every stream, so that equal times are equal doubles.
    const double t = config.t0_s + k / config.fps;
    dive.image_stamps_s.push_back(t);
    dive.truth_at_images.push_back(truth(t));
    if (k > 0) {
      const double tp = config.t0_s + (k - 1) / config.fps;
      const Eigen::Vector2d delta = truth(t) - truth(tp);
      const Eigen::Matrix2d image_cov =
          (std::pow(config.image_sigma_m, 2) + m.position_noise_m2_per_s * dt) * Eigen::Matrix2d::Identity() +
          m.imageStepNoiseCovariance(delta);
      // Measured motion: rotated by the heading error, scaled by the pixel-size error, plus noise (anisotropic when
      // the model's step noise is).
      const Eigen::Matrix2d image_cov_sqrt = image_cov.llt().matrixL();
      const Eigen::Vector2d measured = rot2(psi) * delta / (1.0 + c) + image_cov_sqrt * gauss2(1.0);
      // Dead-reckoning offset: the shared heading error, plus its random walk.
      if (config.dr_shares_heading) d += (rot2(psi) - Eigen::Matrix2d::Identity()) * delta;
      d += dr_scale * delta;  // the DR's velocity scale error
      if (config.dr_scale_sigma > 0.0) dr_scale += m.dr_scale_noise_per_sqrt_s * std::sqrt(dt) * n01(rng);
      d += gauss2(std::sqrt(m.dr_offset_noise_m2_per_m * delta.norm() + m.dr_offset_noise_m2_per_s * dt));
      NavEvent e;
      e.kind = inIntervals(t - config.t0_s, config.image_failures_s) ? NavEvent::kImageFailure : NavEvent::kImage;
      e.stamp_s = t;
      e.previous_stamp_s = tp;
      e.arrival_s = t + config.image_latency_s;
      e.value = measured;
      e.covariance = std::pow(config.image_sigma_m, 2) * Eigen::Matrix2d::Identity();
      dive.events.push_back(e);
      // Heading and pixel size evolve.
      const double q_angle = std::pow(m.heading_noise_rad_per_sqrt_s, 2), q_drift = std::pow(m.heading_drift_noise_rps_per_sqrt_s, 2);
      Eigen::Matrix2d q;
      q << q_angle * dt + q_drift * dt * dt * dt / 3.0, q_drift * dt * dt / 2.0, q_drift * dt * dt / 2.0, q_drift * dt;
      const Eigen::Matrix2d lq = q.llt().matrixL();
      const Eigen::Vector2d w = lq * Eigen::Vector2d(n01(rng), n01(rng));
      psi += psi_dot * dt + w.x();
      psi_dot += w.y();
      c += m.pixel_size_correction_noise_per_sqrt_s * std::sqrt(dt) * n01(rng);
    }
    dr_offset_at_images.push_back(d);
  }
  if (config.with_dr) {
    const int count = static_cast<int>(std::floor(config.duration_s * config.dr_rate_hz + 1e-9)) + 1;
    for (int j = 0; j < count; ++j) {
      const double tau = j / config.dr_rate_hz, t = config.t0_s + tau;
      // Offset between image stamps: linear interpolation.
      const double k_real = tau * config.fps;
      const int k0 = std::min(frames - 1, static_cast<int>(std::floor(k_real + 1e-9)));
      const int k1 = std::min(frames - 1, k0 + 1);
      const double f = std::clamp(k_real - k0, 0.0, 1.0);
      const Eigen::Vector2d offset = (1.0 - f) * dr_offset_at_images[k0] + f * dr_offset_at_images[k1];
      NavEvent e;
      e.kind = NavEvent::kDeadReckoning;
      e.stamp_s = t;
      e.arrival_s = t + 0.001;
      e.value = truth(t) + offset + gauss2(m.dr_measurement_sigma_m);
      e.covariance = 0.04 * Eigen::Matrix2d::Identity();
      dive.events.push_back(e);
    }
  }
  if (config.with_fixes) {
    const int count = static_cast<int>(std::floor(config.duration_s * config.fix_rate_hz + 1e-9)) + 1;
    for (int j = 1; j < count; ++j) {
      const double tau = j / config.fix_rate_hz, t = config.t0_s + tau;
      Eigen::Vector2d noise = gauss2(config.fix_sigma_m);
      const bool outlier = u01(rng) < config.fix_outlier_probability;
      const double angle = 2.0 * M_PI * u01(rng);
      if (outlier) noise += config.fix_outlier_m * Eigen::Vector2d(std::cos(angle), std::sin(angle));
      if (inIntervals(tau, config.fix_dropouts_s)) continue;
      NavEvent e;
      e.kind = NavEvent::kFix;
      e.stamp_s = t;
      e.arrival_s = t + config.fix_latency_s;
      e.value = truth(t) + noise;
      e.covariance = std::pow(config.fix_sigma_m, 2) * Eigen::Matrix2d::Identity();
      if (outlier) dive.fix_outlier_indices.push_back(static_cast<int>(dive.events.size()));
      dive.events.push_back(e);
    }
  }
  // Arrival order (stable: equal arrivals keep generation order).
  std::vector<int> order(dive.events.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = static_cast<int>(i);
  std::stable_sort(order.begin(), order.end(),
                   [&](int a, int b) { return dive.events[a].arrival_s < dive.events[b].arrival_s; });
  std::vector<NavEvent> sorted;
  std::vector<int> new_index(order.size());
  for (size_t i = 0; i < order.size(); ++i) {
    new_index[order[i]] = static_cast<int>(i);
    sorted.push_back(dive.events[order[i]]);
  }
  for (int& i : dive.fix_outlier_indices) i = new_index[i];
  dive.events = sorted;
  return dive;
}

/// Feeds one event to the filter.
inline UpdateResult feed(NavigationFilter& filter, const NavEvent& e) {
  switch (e.kind) {
    case NavEvent::kImage: {
      MetricMotion m;
      m.valid = true;
      m.camera_displacement_en_m = e.value;
      m.covariance_m2 = e.covariance;
      return filter.addImageMotion(e.previous_stamp_s, e.stamp_s, m);
    }
    case NavEvent::kImageFailure:
      return filter.addImageFailure(e.previous_stamp_s, e.stamp_s);
    case NavEvent::kDeadReckoning:
      return filter.addDeadReckoning(e.stamp_s, e.value, e.covariance);
    case NavEvent::kFix:
      return filter.addAbsoluteFix(e.stamp_s, e.value, e.covariance);
  }
  return {};
}

/// Events sorted by stamp (images by their end stamp; DR before fixes at one stamp): in-order processing.
inline std::vector<NavEvent> inStampOrder(std::vector<NavEvent> events) {
  std::stable_sort(events.begin(), events.end(), [](const NavEvent& a, const NavEvent& b) {
    if (a.stamp_s != b.stamp_s) return a.stamp_s < b.stamp_s;
    return static_cast<int>(a.kind) < static_cast<int>(b.kind);
  });
  return events;
}

/// A filter configuration whose heading, drift and pixel-size states are frozen at zero: a linear-Gaussian model
/// (position random walk driven by image motion, DR offset random walk), as in the 2D3 report.
inline FilterConfig linearConfig() {
  FilterConfig c;
  c.initial_pixel_size_correction_sigma = 0.0;
  c.pixel_size_correction_noise_per_sqrt_s = 0.0;
  c.initial_heading_sigma_rad = 0.0;
  c.initial_heading_drift_sigma_rps = 0.0;
  c.heading_noise_rad_per_sqrt_s = 0.0;
  c.heading_drift_noise_rps_per_sqrt_s = 0.0;
  c.initial_dr_scale_sigma = 0.0;
  c.dr_scale_noise_per_sqrt_s = 0.0;
  c.gate_probability = 1.0 - 1e-15;  // nothing gated
  return c;
}

/**
 * @brief Batch least-squares solution of the linear model on a stream where every DR and fix stamp is an image stamp
 * and images chain (no failures): unknowns (p_k, d_k) at the initial stamp and every image stamp. Returns the
 * estimates in stamp order, each a 4-vector (E, N, dE, dN); `with_dr` false drops d.
 */
inline std::vector<Eigen::Vector4d> batchLeastSquares(const FilterConfig& config, double t0_s,
                                                      const Eigen::Vector2d& p0, const Eigen::Matrix2d& P0,
                                                      const std::vector<NavEvent>& events, bool with_dr) {
  std::vector<double> stamps{t0_s};
  for (const NavEvent& e : events)
    if (e.kind == NavEvent::kImage) stamps.push_back(e.stamp_s);
  std::sort(stamps.begin(), stamps.end());
  const int n = static_cast<int>(stamps.size());
  const int dim = with_dr ? 4 : 2;
  const auto index = [&](double t) {
    return static_cast<int>(std::lower_bound(stamps.begin(), stamps.end(), t) - stamps.begin());
  };
  // Positions relative to p0: the normal equations are solved in small numbers.
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(n * dim, n * dim);
  Eigen::VectorXd b = Eigen::VectorXd::Zero(n * dim);
  // Adds (J x - z)^T W (J x - z) for a residual over the blocks listed.
  const auto add = [&](const std::vector<std::pair<int, Eigen::Matrix2d>>& terms, const Eigen::Vector2d& z,
                       const Eigen::Matrix2d& W) {
    for (const auto& [i, Ji] : terms) {
      b.segment<2>(i) += Ji.transpose() * W * z;
      for (const auto& [j, Jj] : terms) A.block<2, 2>(i, j) += Ji.transpose() * W * Jj;
    }
  };
  const Eigen::Matrix2d I = Eigen::Matrix2d::Identity();
  add({{0, I}}, Eigen::Vector2d::Zero(), P0.inverse());
  for (const NavEvent& e : events) {
    const int k = index(e.stamp_s);
    if (e.kind == NavEvent::kImage) {
      const double dt = e.stamp_s - e.previous_stamp_s;
      const Eigen::Matrix2d Qp =
          e.covariance + config.position_noise_m2_per_s * dt * I + config.imageStepNoiseCovariance(e.value);
      add({{k * dim, I}, {(k - 1) * dim, -I}}, e.value, Qp.inverse());
      if (with_dr) {
        const double q = config.dr_offset_noise_m2_per_m * e.value.norm() + config.dr_offset_noise_m2_per_s * dt;
        add({{k * dim + 2, I}, {(k - 1) * dim + 2, -I}}, Eigen::Vector2d::Zero(), (q * I).inverse());
      }
    } else if (e.kind == NavEvent::kDeadReckoning && with_dr) {
      add({{k * dim, I}, {k * dim + 2, I}}, e.value - p0, I / std::pow(config.dr_measurement_sigma_m, 2));
    } else if (e.kind == NavEvent::kFix) {
      add({{k * dim, I}}, e.value - p0, e.covariance.inverse());
    }
  }
  const Eigen::VectorXd x = A.ldlt().solve(b);
  std::vector<Eigen::Vector4d> out;
  for (int k = 0; k < n; ++k) {
    Eigen::Vector4d v = Eigen::Vector4d::Zero();
    v.head(dim) = x.segment(k * dim, dim);
    v.head<2>() += p0;
    out.push_back(v);
  }
  return out;
}

}  // namespace testing
}  // namespace fusion
}  // namespace exocet_mosaic
