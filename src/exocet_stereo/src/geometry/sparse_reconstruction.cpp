#include "exocet_stereo/geometry/sparse_reconstruction.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <set>
#include <sstream>
#include <stdexcept>

#include "exocet_stereo/geometry/epipolar.h"
#include "exocet_stereo/geometry/triangulation.h"

namespace exocet_stereo {
namespace geometry {

namespace {

double rms(const std::vector<double>& errors) {
  if (errors.empty()) return 0.0;
  double sum = 0.0;
  for (double e : errors) sum += e * e;
  return std::sqrt(sum / errors.size());
}

/// The pairs to match, each once: every image with its `span` nearest initial centres, or its next `span` indices.
std::vector<std::pair<int, int>> neighbourPairs(const std::vector<PinholeView>& views,
                                                const SparseReconstructionConfig& config) {
  const int n = static_cast<int>(views.size());
  std::set<std::pair<int, int>> pairs;
  for (int i = 0; i < n; ++i) {
    std::vector<int> partners;
    if (config.pair_selection == PairSelection::kNearestCentres) {
      std::vector<std::pair<double, int>> by_distance;
      for (int j = 0; j < n; ++j)
        if (j != i) by_distance.emplace_back((views[i].centre() - views[j].centre()).norm(), j);
      std::sort(by_distance.begin(), by_distance.end());
      for (int k = 0; k < config.neighbour_span && k < static_cast<int>(by_distance.size()); ++k)
        partners.push_back(by_distance[k].second);
    } else {
      for (int k = 1; k <= config.neighbour_span; ++k) {
        if (i + k >= n && !config.ring) break;
        partners.push_back((i + k) % n);
      }
    }
    for (int j : partners)
      if (j != i) pairs.insert({std::min(i, j), std::max(i, j)});
  }
  return {pairs.begin(), pairs.end()};
}

/// Keeps the observations whose error is below the gate, then the points still seen at least twice; renumbers.
int pruneObservations(BaProblem& problem, std::vector<std::vector<TrackObservation>>& tracks,
                      const std::vector<double>& errors, double gate_px) {
  std::vector<std::vector<int>> kept_of_point(problem.points.size());
  for (size_t k = 0; k < problem.observations.size(); ++k)
    if (errors[k] <= gate_px) kept_of_point[problem.observations[k].point].push_back(static_cast<int>(k));
  BaProblem pruned;
  pruned.cameras = problem.cameras;
  std::vector<std::vector<TrackObservation>> pruned_tracks;
  int removed = 0;
  for (size_t p = 0; p < problem.points.size(); ++p) {
    const auto& kept = kept_of_point[p];
    const int seen = static_cast<int>(tracks[p].size());
    if (kept.size() < 2) {
      removed += seen;
      continue;
    }
    removed += seen - static_cast<int>(kept.size());
    const int id = static_cast<int>(pruned.points.size());
    pruned.points.push_back(problem.points[p]);
    std::vector<TrackObservation> track;
    for (int k : kept) {
      BaObservation o = problem.observations[k];
      o.point = id;
      pruned.observations.push_back(o);
      // A track holds one keypoint per image, so the camera identifies the track entry.
      for (const auto& t : tracks[p])
        if (t.image == o.camera) track.push_back(t);
    }
    pruned_tracks.push_back(track);
  }
  problem = std::move(pruned);
  tracks = std::move(pruned_tracks);
  return removed;
}

}  // namespace

std::string SparseReconstructionConfig::validate() const {
  std::ostringstream errors;
  auto check = [&errors](bool ok, const char* field, const char* range) {
    if (ok) return;
    if (errors.tellp() > 0) errors << "; ";
    errors << field << " must be in " << range;
  };
  auto nested = [&errors](const std::string& name, const std::string& message) {
    if (message.empty()) return;
    if (errors.tellp() > 0) errors << "; ";
    errors << name << ": " << message;
  };
  check(neighbour_span >= 1 && neighbour_span <= 32, "neighbour_span", "[1, 32]");
  check(pose_epipolar_tolerance_px > 0.0 && pose_epipolar_tolerance_px <= 1000.0, "pose_epipolar_tolerance_px",
        "(0, 1000]");
  check(min_pair_inliers >= 8 && min_pair_inliers <= 100000, "min_pair_inliers", "[8, 100000]");
  check(outlier_threshold_px > 0.0 && outlier_threshold_px <= 100.0, "outlier_threshold_px", "(0, 100]");
  check(min_triangulation_angle_deg >= 0.0 && min_triangulation_angle_deg <= 45.0, "min_triangulation_angle_deg",
        "[0, 45]");
  check(min_observations_per_view >= 1 && min_observations_per_view <= 100000, "min_observations_per_view",
        "[1, 100000]");
  nested("matching", matching.validate());
  nested("ransac", ransac.validate());
  nested("adjustment", adjustment.validate());
  return errors.str();
}

SparseReconstruction reconstructSparse(const std::vector<cv::Mat>& images,
                                       const std::vector<PinholeView>& initial_views,
                                       const SparseReconstructionConfig& config) {
  const std::string error = config.validate();
  if (!error.empty()) throw std::invalid_argument("SparseReconstructionConfig: " + error);
  if (images.size() != initial_views.size() || images.size() < 2)
    throw std::invalid_argument("reconstructSparse: needs as many views as images (>= 2), got " +
                                std::to_string(images.size()) + " images and " + std::to_string(initial_views.size()) +
                                " views");
  const int n = static_cast<int>(images.size());
  SparseReconstruction out;
  out.views = initial_views;
  for (const cv::Mat& image : images) out.features.push_back(detectSift(image, config.matching));

  std::vector<int> counts;
  for (const auto& f : out.features) counts.push_back(static_cast<int>(f.keypoints.size()));
  TrackBuilder builder(counts);
  for (const auto& [i, j] : neighbourPairs(initial_views, config)) {
    PairMatchStats stats;
    stats.image_a = i;
    stats.image_b = j;
    const std::vector<cv::DMatch> matches = matchSift(out.features[i], out.features[j], config.matching);
    stats.putative = static_cast<int>(matches.size());
    // Gate with the approximate poses first: it removes the repeated-texture mismatches far from the epipolar line
    // that could otherwise form a consistent but wrong RANSAC model.
    const Eigen::Matrix3d F0 = fundamentalFromViews(initial_views[i], initial_views[j]);
    std::vector<Eigen::Vector2d> a, b;
    std::vector<cv::DMatch> gated;
    for (const cv::DMatch& m : matches) {
      const Eigen::Vector2d pa = out.features[i].pixel(m.queryIdx), pb = out.features[j].pixel(m.trainIdx);
      if (symmetricEpipolarDistance_px(F0, pa, pb) > config.pose_epipolar_tolerance_px) continue;
      a.push_back(pa);
      b.push_back(pb);
      gated.push_back(m);
    }
    stats.pose_consistent = static_cast<int>(gated.size());
    const FundamentalFit fit = fitFundamentalRansac(a, b, config.ransac);
    if (fit.ok && fit.inlier_count >= config.min_pair_inliers) {
      stats.ransac_inliers = fit.inlier_count;
      for (size_t k = 0; k < gated.size(); ++k)
        if (fit.inliers[k]) builder.addMatch(i, gated[k].queryIdx, j, gated[k].trainIdx);
    }
    out.pairs.push_back(stats);
  }

  // Triangulate every consistent track with the initial poses.
  std::vector<std::vector<TrackObservation>> tracks;
  BaProblem problem;
  problem.cameras = initial_views;
  std::vector<Projection> all_projections;
  for (const auto& v : initial_views) all_projections.push_back(v.projection());
  for (const auto& track : builder.tracks(2)) {
    std::vector<Projection> P;
    std::vector<Eigen::Vector2d> x;
    for (const auto& o : track) {
      P.push_back(all_projections[o.image]);
      x.push_back(out.features[o.image].pixel(o.keypoint));
    }
    Eigen::Vector3d X = triangulateLinear(P, x);
    if (!X.allFinite()) continue;
    X = refineTriangulation(P, x, X, 5).X;
    bool in_front = X.allFinite();
    for (const auto& o : track) in_front = in_front && initial_views[o.image].depth(X) > 0.0;
    if (!in_front) continue;
    const int id = static_cast<int>(problem.points.size());
    problem.points.push_back(X);
    for (size_t k = 0; k < track.size(); ++k) problem.observations.push_back({track[k].image, id, x[k]});
    tracks.push_back(track);
  }
  out.initial_rms_px = rms(reprojectionErrors_px(problem));

  // A view with a handful of observations has a pose the adjustment cannot determine (a singular system): its
  // observations are set aside and its initial pose kept, so it counts as not registered.
  auto dropWeakViews = [&]() {
    std::vector<int> per_view(n, 0);
    for (const auto& o : problem.observations) ++per_view[o.camera];
    std::vector<double> gate(problem.observations.size(), 0.0);
    for (size_t k = 0; k < gate.size(); ++k)
      if (per_view[problem.observations[k].camera] < config.min_observations_per_view)
        gate[k] = std::numeric_limits<double>::infinity();
    pruneObservations(problem, tracks, gate, 1.0);
  };
  // A point whose rays are nearly parallel (views 1 and 11 of the temple ring share a centre) has an undetermined
  // depth: it drifts during the adjustment and slows it down without constraining any pose.
  const double min_angle_rad = config.min_triangulation_angle_deg * M_PI / 180.0;
  auto dropNarrowPoints = [&]() {
    std::vector<double> gate(problem.observations.size(), 0.0);
    std::vector<std::vector<int>> of_point(problem.points.size());
    for (size_t k = 0; k < problem.observations.size(); ++k)
      of_point[problem.observations[k].point].push_back(static_cast<int>(k));
    for (size_t p = 0; p < problem.points.size(); ++p) {
      std::vector<Eigen::Vector3d> rays;
      for (int k : of_point[p])
        rays.push_back((problem.points[p] - problem.cameras[problem.observations[k].camera].centre()).normalized());
      double widest = 0.0;
      for (size_t i = 0; i < rays.size(); ++i)
        for (size_t j = i + 1; j < rays.size(); ++j)
          widest = std::max(widest, std::acos(std::clamp(rays[i].dot(rays[j]), -1.0, 1.0)));
      if (widest < min_angle_rad)
        for (int k : of_point[p]) gate[k] = std::numeric_limits<double>::infinity();
    }
    return pruneObservations(problem, tracks, gate, 1.0);
  };
  dropNarrowPoints();
  dropWeakViews();
  if (!problem.observations.empty()) {
    out.first_adjustment = bundleAdjust(problem, config.adjustment);
    out.removed_observations =
        pruneObservations(problem, tracks, reprojectionErrors_px(problem), config.outlier_threshold_px);
    out.removed_observations += dropNarrowPoints();  // with the adjusted poses the angles are now reliable
    dropWeakViews();
    if (!problem.observations.empty()) out.second_adjustment = bundleAdjust(problem, config.adjustment);
  }
  out.views = problem.cameras;
  out.points = problem.points;
  out.tracks = tracks;
  out.observations = static_cast<int>(problem.observations.size());
  out.final_rms_px = rms(reprojectionErrors_px(problem));
  std::vector<int> per_view(n, 0);
  for (const auto& o : problem.observations) ++per_view[o.camera];
  for (int count : per_view) out.views_registered += count >= config.min_observations_per_view ? 1 : 0;
  return out;
}

}  // namespace geometry
}  // namespace exocet_stereo
