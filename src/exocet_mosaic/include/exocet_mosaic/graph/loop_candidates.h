/**
 * @file loop_candidates.h
 * @brief Which earlier key frames a new key frame may close a loop with: those whose image footprints on the seabed
 * could overlap it, given the uncertainty of both positions. No ROS in it.
 *
 * Conventions (as pose_graph.h): the seabed plane is (east, north) in metres; a key frame's Pose2d is its camera
 * centre and the yaw of its x axis (ENU, counter-clockwise from east). For the downward camera the key frame's x axis
 * is the image's "up" (-v) direction and its y axis the image's "left" (-u) direction, projected on the seabed: for
 * a camera mounted with its image top forward (image x to starboard, the simulator's camera) these are base_link's
 * x (forward) and y (port), so the key frame's yaw is the vehicle's heading.
 *
 * Gating: the offset between two key frames' centres is uncertain with covariance S = P_old + P_new (the sum of
 * their 2x2 position covariances, errors taken as independent). Offsets within the chi-square gate
 * (d^T S^-1 d <= gate_chi2, 2 degrees of freedom) are plausible; a pair is a candidate when SOME plausible offset
 * makes the footprints overlap by min_overlap_fraction (of the smaller footprint), also trying the yaw difference
 * at +-gate_sigma_yaw sigmas. Two centrally symmetric convex footprints overlap most when concentric (their
 * overlap area's square root is concave in the offset, Brunn-Minkowski), so the offset tried first is the plausible
 * one that brings the centres closest; a few others on the gate's boundary guard the non-symmetric cases.
 * Candidates are ranked by their overlap at the estimate (then by the gated overlap).
 *
 * A key frame is inserted in the cells of a grid hash covered by its footprint's circumscribed circle widened by
 * its own gate radius (sqrt(gate_chi2 * largest eigenvalue of its covariance)); since the gate radius of S is at
 * most the sum of the two own radii, a query of the cells covered by the new key frame's widened circle misses no
 * candidate.
 */
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <unordered_map>
#include <vector>

#include <Eigen/Core>

#include "exocet_mosaic/graph/pose_graph.h"

namespace exocet_mosaic {
namespace graph {

/// A downward camera's intrinsics for the footprint: K of the undistorted image and its size.
struct FootprintCamera {
  double fx_px = 0.0, fy_px = 0.0, cx_px = 0.0, cy_px = 0.0;
  int width_px = 0, height_px = 0;
  std::string validate() const;  ///< "" or each bad field with its allowed range
};

/// What the candidate finder keeps of a key frame.
struct LoopKeyFrame {
  int64_t id = 0;
  double stamp_s = 0.0;
  Pose2d pose;                                                           ///< camera centre (E, N) and yaw
  Eigen::Matrix2d position_cov_m2 = Eigen::Matrix2d::Identity() * 0.01;  ///< of pose.position_en_m, m^2
  double yaw_sigma_rad = 0.02;                                           ///< 1-sigma of pose.yaw_rad, >= 0
  double camera_height_m = 2.5;                                          ///< above the seabed, > 0
  FootprintCamera camera;
};

/// The image footprint on the seabed (E, N) of a nadir camera at `pose` and height: the image corners (0,0),
/// (w,0), (w,h), (0,h) in that order. @throws std::invalid_argument on a bad camera or height
std::array<Eigen::Vector2d, 4> footprintCorners(const FootprintCamera& camera, const Pose2d& pose,
                                                double camera_height_m);

struct LoopCandidateConfig {
  double min_separation_s = 30.0;     ///< a candidate is older than the new key frame by more, seconds, >= 0
  int min_separation_keyframes = 10;  ///< ... AND by more key frames than this (insertion order), >= 0
  double min_overlap_fraction = 0.3;  ///< of the smaller footprint, for some plausible offset, (0, 1]
  double gate_chi2 = 9.21;            ///< offset gate, chi-square 2 dof (9.21: 99 %), > 0
  double gate_sigma_yaw = 3.0;        ///< yaw differences tried: estimate and +-this many sigmas, >= 0
  int max_candidates = 5;             ///< per query, >= 1
  double grid_cell_m = 2.0;           ///< cell side of the spatial hash, metres, > 0
  std::string validate() const;       ///< "" or each bad field with its allowed range
};

/// A loop candidate: an earlier key frame that may overlap the new one.
struct LoopCandidate {
  int64_t id = 0;                  ///< the earlier key frame
  double overlap_at_estimate = 0;  ///< overlap fraction (of the smaller footprint) at the estimated poses
  double overlap_gated = 0;        ///< the largest overlap fraction found within the gate
  double mahalanobis2 = 0;         ///< d^T S^-1 d of the estimated centre offset
};

/**
 * @brief Keeps a dive's key frames and finds the loop candidates of a new one. Not thread-safe.
 *
 * Every key frame is checked (finite pose, covariance symmetric positive semi-definite and finite, height > 0,
 * camera) and a bad one throws std::invalid_argument naming the problem.
 */
class LoopCandidateFinder {
 public:
  /// @throws std::invalid_argument when config.validate() is not empty
  explicit LoopCandidateFinder(const LoopCandidateConfig& config = LoopCandidateConfig());

  /// Adds a key frame (ids and stamps increasing). @throws std::invalid_argument on bad input or order
  void addKeyFrame(const LoopKeyFrame& key_frame);

  /// The loop candidates of `key_frame` (not added) among the stored ones, best first, at most max_candidates.
  std::vector<LoopCandidate> candidates(const LoopKeyFrame& key_frame) const;

  /// Replaces the pose and covariance of a stored key frame (after a graph solve). @throws on an unknown id
  void updatePose(int64_t id, const Pose2d& pose, const Eigen::Matrix2d& position_cov_m2, double yaw_sigma_rad);

  size_t size() const { return key_frames_.size(); }
  const LoopKeyFrame& keyFrame(int64_t id) const;  ///< @throws std::invalid_argument on an unknown id
  const LoopCandidateConfig& config() const { return config_; }

 private:
  struct Stored {
    LoopKeyFrame kf;
    std::vector<int64_t> cells;  ///< grid cells it is listed in
  };
  void check(const LoopKeyFrame& kf) const;
  std::vector<int64_t> cellsOf(const LoopKeyFrame& kf) const;
  void insertCells(int index);
  void removeCells(int index);

  LoopCandidateConfig config_;
  std::vector<Stored> key_frames_;
  std::unordered_map<int64_t, int> index_of_id_;
  std::unordered_map<int64_t, std::vector<int>> grid_;  ///< cell key -> key frame indices
  mutable std::vector<unsigned> seen_;                  ///< scratch: query that last saw each key frame
  mutable unsigned query_count_ = 0;
};

}  // namespace graph
}  // namespace exocet_mosaic
