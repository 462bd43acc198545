#include "exocet_mosaic/graph/loop_candidates.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <opencv2/imgproc.hpp>

namespace exocet_mosaic {
namespace graph {
namespace {

bool finitePositive(double v) { return std::isfinite(v) && v > 0.0; }

/// Overlap area / smaller area of two convex quadrilaterals.
double overlapFraction(const std::array<Eigen::Vector2d, 4>& a, const std::array<Eigen::Vector2d, 4>& b,
                       const Eigen::Vector2d& origin) {
  std::vector<cv::Point2f> pa, pb, inter;
  for (int i = 0; i < 4; ++i) {
    pa.emplace_back(float(a[i].x() - origin.x()), float(a[i].y() - origin.y()));
    pb.emplace_back(float(b[i].x() - origin.x()), float(b[i].y() - origin.y()));
  }
  const double area_a = std::abs(cv::contourArea(pa)), area_b = std::abs(cv::contourArea(pb));
  const double smaller = std::min(area_a, area_b);
  if (!(smaller > 0.0)) return 0.0;
  const float inter_area = cv::intersectConvexConvex(pa, pb, inter, true);
  return std::max(0.0, double(inter_area)) / smaller;
}

double circumradius_m(const std::array<Eigen::Vector2d, 4>& corners, const Eigen::Vector2d& centre) {
  double r = 0.0;
  for (const Eigen::Vector2d& c : corners) r = std::max(r, (c - centre).norm());
  return r;
}

int64_t cellKey(int64_t ix, int64_t iy) { return (ix << 32) ^ (iy & 0xffffffffLL); }

}  // namespace

std::string FootprintCamera::validate() const {
  std::ostringstream s;
  if (!finitePositive(fx_px)) s << "fx_px = " << fx_px << " must be finite and > 0; ";
  if (!finitePositive(fy_px)) s << "fy_px = " << fy_px << " must be finite and > 0; ";
  if (!std::isfinite(cx_px)) s << "cx_px = " << cx_px << " must be finite; ";
  if (!std::isfinite(cy_px)) s << "cy_px = " << cy_px << " must be finite; ";
  if (width_px < 1) s << "width_px = " << width_px << " must be >= 1; ";
  if (height_px < 1) s << "height_px = " << height_px << " must be >= 1; ";
  return s.str();
}

std::string LoopCandidateConfig::validate() const {
  std::ostringstream s;
  if (!(min_separation_s >= 0.0 && std::isfinite(min_separation_s)))
    s << "min_separation_s = " << min_separation_s << " must be in [0, inf) s; ";
  if (min_separation_keyframes < 0) s << "min_separation_keyframes = " << min_separation_keyframes << " must be >= 0; ";
  if (!(min_overlap_fraction > 0.0 && min_overlap_fraction <= 1.0))
    s << "min_overlap_fraction = " << min_overlap_fraction << " must be in (0, 1]; ";
  if (!finitePositive(gate_chi2)) s << "gate_chi2 = " << gate_chi2 << " must be finite and > 0; ";
  if (!(gate_sigma_yaw >= 0.0 && std::isfinite(gate_sigma_yaw)))
    s << "gate_sigma_yaw = " << gate_sigma_yaw << " must be in [0, inf); ";
  if (max_candidates < 1) s << "max_candidates = " << max_candidates << " must be >= 1; ";
  if (!finitePositive(grid_cell_m)) s << "grid_cell_m = " << grid_cell_m << " must be finite and > 0 m; ";
  return s.str();
}

std::array<Eigen::Vector2d, 4> footprintCorners(const FootprintCamera& camera, const Pose2d& pose,
                                                double camera_height_m) {
  const std::string problem = camera.validate();
  if (!problem.empty()) throw std::invalid_argument("footprint camera: " + problem);
  if (!finitePositive(camera_height_m))
    throw std::invalid_argument("camera_height_m = " + std::to_string(camera_height_m) + " must be finite and > 0");
  const double c = std::cos(pose.yaw_rad), s = std::sin(pose.yaw_rad);
  const double us[4] = {0.0, double(camera.width_px), double(camera.width_px), 0.0};
  const double vs[4] = {0.0, 0.0, double(camera.height_px), double(camera.height_px)};
  std::array<Eigen::Vector2d, 4> corners;
  for (int i = 0; i < 4; ++i) {
    // Nadir camera: image up (-v) is the key frame's x, image left (-u) its y.
    const double x_kf = -(vs[i] - camera.cy_px) / camera.fy_px * camera_height_m;
    const double y_kf = -(us[i] - camera.cx_px) / camera.fx_px * camera_height_m;
    corners[i] = pose.position_en_m + Eigen::Vector2d(c * x_kf - s * y_kf, s * x_kf + c * y_kf);
  }
  return corners;
}

LoopCandidateFinder::LoopCandidateFinder(const LoopCandidateConfig& config) : config_(config) {
  const std::string problem = config.validate();
  if (!problem.empty()) throw std::invalid_argument("LoopCandidateConfig: " + problem);
}

void LoopCandidateFinder::check(const LoopKeyFrame& kf) const {
  const std::string id = "key frame " + std::to_string(kf.id) + ": ";
  if (!std::isfinite(kf.stamp_s)) throw std::invalid_argument(id + "stamp_s is not finite");
  if (!kf.pose.position_en_m.allFinite() || !std::isfinite(kf.pose.yaw_rad))
    throw std::invalid_argument(id + "pose is not finite");
  const Eigen::Matrix2d& p = kf.position_cov_m2;
  if (!p.allFinite()) throw std::invalid_argument(id + "position_cov_m2 is not finite");
  if (std::abs(p(0, 1) - p(1, 0)) > 1e-9 * (1.0 + p.cwiseAbs().maxCoeff()))
    throw std::invalid_argument(id + "position_cov_m2 is not symmetric");
  if (p(0, 0) < 0.0 || p(1, 1) < 0.0 || p.determinant() < -1e-12 * (1.0 + p.squaredNorm()))
    throw std::invalid_argument(id + "position_cov_m2 is not positive semi-definite");
  if (!(kf.yaw_sigma_rad >= 0.0 && std::isfinite(kf.yaw_sigma_rad)))
    throw std::invalid_argument(id + "yaw_sigma_rad must be finite and >= 0");
  if (!finitePositive(kf.camera_height_m)) throw std::invalid_argument(id + "camera_height_m must be finite and > 0");
  const std::string problem = kf.camera.validate();
  if (!problem.empty()) throw std::invalid_argument(id + "camera: " + problem);
}

std::vector<int64_t> LoopCandidateFinder::cellsOf(const LoopKeyFrame& kf) const {
  const auto corners = footprintCorners(kf.camera, kf.pose, kf.camera_height_m);
  const double largest_var =
      std::max(0.0, Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d>(kf.position_cov_m2, Eigen::EigenvaluesOnly)
                        .eigenvalues()
                        .maxCoeff());
  const double r = circumradius_m(corners, kf.pose.position_en_m) + std::sqrt(config_.gate_chi2 * largest_var);
  const Eigen::Vector2d& c = kf.pose.position_en_m;
  const int64_t x0 = int64_t(std::floor((c.x() - r) / config_.grid_cell_m));
  const int64_t x1 = int64_t(std::floor((c.x() + r) / config_.grid_cell_m));
  const int64_t y0 = int64_t(std::floor((c.y() - r) / config_.grid_cell_m));
  const int64_t y1 = int64_t(std::floor((c.y() + r) / config_.grid_cell_m));
  std::vector<int64_t> cells;
  for (int64_t ix = x0; ix <= x1; ++ix)
    for (int64_t iy = y0; iy <= y1; ++iy) cells.push_back(cellKey(ix, iy));
  return cells;
}

void LoopCandidateFinder::insertCells(int index) {
  Stored& s = key_frames_[index];
  s.cells = cellsOf(s.kf);
  for (int64_t cell : s.cells) grid_[cell].push_back(index);
}

void LoopCandidateFinder::removeCells(int index) {
  for (int64_t cell : key_frames_[index].cells) {
    auto it = grid_.find(cell);
    if (it == grid_.end()) continue;
    it->second.erase(std::remove(it->second.begin(), it->second.end(), index), it->second.end());
    if (it->second.empty()) grid_.erase(it);
  }
  key_frames_[index].cells.clear();
}

void LoopCandidateFinder::addKeyFrame(const LoopKeyFrame& key_frame) {
  check(key_frame);
  if (!key_frames_.empty()) {
    const LoopKeyFrame& last = key_frames_.back().kf;
    if (key_frame.id <= last.id)
      throw std::invalid_argument("key frame id " + std::to_string(key_frame.id) + " not greater than the last, " +
                                  std::to_string(last.id));
    if (key_frame.stamp_s <= last.stamp_s)
      throw std::invalid_argument("key frame " + std::to_string(key_frame.id) + ": stamp_s not after the last one");
  }
  const int index = int(key_frames_.size());
  key_frames_.push_back({key_frame, {}});
  index_of_id_[key_frame.id] = index;
  insertCells(index);
  seen_.push_back(0);
}

void LoopCandidateFinder::updatePose(int64_t id, const Pose2d& pose, const Eigen::Matrix2d& position_cov_m2,
                                     double yaw_sigma_rad) {
  auto it = index_of_id_.find(id);
  if (it == index_of_id_.end()) throw std::invalid_argument("unknown key frame id " + std::to_string(id));
  LoopKeyFrame kf = key_frames_[it->second].kf;
  kf.pose = pose;
  kf.position_cov_m2 = position_cov_m2;
  kf.yaw_sigma_rad = yaw_sigma_rad;
  check(kf);
  removeCells(it->second);
  key_frames_[it->second].kf = kf;
  insertCells(it->second);
}

const LoopKeyFrame& LoopCandidateFinder::keyFrame(int64_t id) const {
  auto it = index_of_id_.find(id);
  if (it == index_of_id_.end()) throw std::invalid_argument("unknown key frame id " + std::to_string(id));
  return key_frames_[it->second].kf;
}

std::vector<LoopCandidate> LoopCandidateFinder::candidates(const LoopKeyFrame& key_frame) const {
  check(key_frame);
  std::vector<LoopCandidate> out;
  if (++query_count_ == 0) {  // wrapped: clear the marks
    std::fill(seen_.begin(), seen_.end(), 0u);
    query_count_ = 1;
  }
  // Key frames after the new one in insertion order (a query of a stored key frame) count as recent too.
  const int n = int(key_frames_.size());
  int newer_than = n;
  for (int i = n - 1; i >= 0 && key_frames_[i].kf.stamp_s >= key_frame.stamp_s; --i) newer_than = i;
  const Eigen::Vector2d origin = key_frame.pose.position_en_m;
  const auto new_corners = footprintCorners(key_frame.camera, key_frame.pose, key_frame.camera_height_m);
  constexpr int kBoundaryPoints = 12;
  for (int64_t cell : cellsOf(key_frame)) {
    auto it = grid_.find(cell);
    if (it == grid_.end()) continue;
    for (int index : it->second) {
      if (seen_[index] == query_count_) continue;
      seen_[index] = query_count_;
      const LoopKeyFrame& old = key_frames_[index].kf;
      if (index >= newer_than) continue;
      if (!(key_frame.stamp_s - old.stamp_s > config_.min_separation_s)) continue;
      if (!(newer_than - index > config_.min_separation_keyframes)) continue;
      const Eigen::Matrix2d s = old.position_cov_m2 + key_frame.position_cov_m2;
      // The old key frame's position is shifted by plausible offsets delta (the new one held): d = c_new - c_old.
      const Eigen::Vector2d d = key_frame.pose.position_en_m - old.pose.position_en_m;
      const Eigen::Matrix2d s_reg = s + Eigen::Matrix2d::Identity() * 1e-12;
      const Eigen::Matrix2d s_inv = s_reg.inverse();
      const double m2 = d.dot(s_inv * d);
      std::vector<Eigen::Vector2d> shifts = {Eigen::Vector2d::Zero()};
      if (m2 <= config_.gate_chi2) {
        shifts.push_back(d);  // the centres may coincide
      } else {
        // Closest plausible position to the new centre: delta(lambda) = (I + lambda S^-1)^-1 d on the gate boundary,
        // lambda found by bisection (the Mahalanobis norm of delta decreases with lambda).
        double lo = 0.0, hi = 1.0;
        auto gated = [&](double lambda) -> Eigen::Vector2d {
          return (Eigen::Matrix2d::Identity() + lambda * s_inv).inverse() * d;
        };
        while (gated(hi).dot(s_inv * gated(hi)) > config_.gate_chi2 && hi < 1e12) hi *= 4.0;
        for (int k = 0; k < 60; ++k) {
          const double mid = 0.5 * (lo + hi);
          const Eigen::Vector2d delta = gated(mid);
          (delta.dot(s_inv * delta) > config_.gate_chi2 ? lo : hi) = mid;
        }
        shifts.push_back(gated(hi));
      }
      // A few points on the gate's boundary.
      const Eigen::LLT<Eigen::Matrix2d> llt(s_reg);
      const Eigen::Matrix2d l = llt.matrixL();
      for (int k = 0; k < kBoundaryPoints; ++k) {
        const double a = 2.0 * M_PI * k / kBoundaryPoints;
        const Eigen::Vector2d delta = std::sqrt(config_.gate_chi2) * (l * Eigen::Vector2d(std::cos(a), std::sin(a)));
        shifts.push_back(delta);
      }
      const double yaw_sigma =
          std::sqrt(old.yaw_sigma_rad * old.yaw_sigma_rad + key_frame.yaw_sigma_rad * key_frame.yaw_sigma_rad);
      const double dyaws[3] = {0.0, config_.gate_sigma_yaw * yaw_sigma, -config_.gate_sigma_yaw * yaw_sigma};
      const auto old_corners = footprintCorners(old.camera, old.pose, old.camera_height_m);
      LoopCandidate c;
      c.id = old.id;
      c.mahalanobis2 = m2;
      c.overlap_at_estimate = overlapFraction(new_corners, old_corners, origin);
      c.overlap_gated = c.overlap_at_estimate;
      for (int y = 0; y < (yaw_sigma > 0.0 ? 3 : 1) && c.overlap_gated < 1.0; ++y) {
        Pose2d moved = old.pose;
        moved.yaw_rad += dyaws[y];
        for (const Eigen::Vector2d& delta : shifts) {
          moved.position_en_m = old.pose.position_en_m + delta;
          c.overlap_gated =
              std::max(c.overlap_gated,
                       overlapFraction(new_corners, footprintCorners(old.camera, moved, old.camera_height_m), origin));
        }
      }
      if (c.overlap_gated >= config_.min_overlap_fraction) out.push_back(c);
    }
  }
  std::sort(out.begin(), out.end(), [](const LoopCandidate& a, const LoopCandidate& b) {
    if (a.overlap_at_estimate != b.overlap_at_estimate) return a.overlap_at_estimate > b.overlap_at_estimate;
    if (a.overlap_gated != b.overlap_gated) return a.overlap_gated > b.overlap_gated;
    return a.id < b.id;
  });
  if (int(out.size()) > config_.max_candidates) out.resize(config_.max_candidates);
  return out;
}

}  // namespace graph
}  // namespace exocet_mosaic
