#include "exocet_stereo/geometry/pose_perturbation.h"

#include <cmath>
#include <random>

#include <Eigen/Geometry>

#include "exocet_stereo/geometry/similarity_alignment.h"

namespace exocet_stereo {
namespace geometry {

namespace {

Eigen::Vector3d randomDirection(std::mt19937_64& rng) {
  std::normal_distribution<double> normal(0.0, 1.0);
  Eigen::Vector3d v;
  do {
    v = Eigen::Vector3d(normal(rng), normal(rng), normal(rng));
  } while (v.norm() < 1e-9);
  return v.normalized();
}

}  // namespace

std::vector<PinholeView> perturbPoses(const std::vector<PinholeView>& views, const Eigen::Vector3d& scene_centre,
                                      double centre_fraction, double angle_rad, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<PinholeView> out;
  for (const PinholeView& view : views) {
    PinholeView moved = view;
    const Eigen::Vector3d centre = view.centre();
    const Eigen::Vector3d new_centre = centre + centre_fraction * (centre - scene_centre).norm() * randomDirection(rng);
    moved.R = Eigen::AngleAxisd(angle_rad, randomDirection(rng)).toRotationMatrix() * view.R;
    moved.t = -moved.R * new_centre;
    out.push_back(moved);
  }
  return out;
}

CentreErrors centreErrorsAfterSimilarity(const std::vector<PinholeView>& estimated,
                                         const std::vector<PinholeView>& truth, const Eigen::Vector3d& scene_centre) {
  std::vector<Eigen::Vector3d> source, target;
  for (const auto& v : estimated) source.push_back(v.centre());
  for (const auto& v : truth) target.push_back(v.centre());
  const Similarity S = alignSimilarity(source, target);
  const std::vector<double> errors = alignedErrors(S, source, target);
  CentreErrors out;
  out.scale = S.scale;
  double sum2 = 0.0;
  for (size_t i = 0; i < errors.size(); ++i) {
    const double pct = 100.0 * errors[i] / (target[i] - scene_centre).norm();
    out.max_pct = std::max(out.max_pct, pct);
    sum2 += pct * pct;
  }
  out.rms_pct = std::sqrt(sum2 / errors.size());
  return out;
}

}  // namespace geometry
}  // namespace exocet_stereo
