#include "exocet_mosaic/registration/rigid_scene_check.h"

#include <algorithm>
#include <sstream>
#include <stdexcept>

#include <Eigen/Core>

#include "exocet_common/geometry/fundamental_estimator.h"

namespace exocet_mosaic {
namespace registration {

double trackingNoiseFromForwardBackward_px(std::vector<float> fb_distances_px, double floor_px) {
  if (fb_distances_px.empty()) return floor_px;
  const size_t middle = fb_distances_px.size() / 2;
  std::nth_element(fb_distances_px.begin(), fb_distances_px.begin() + middle, fb_distances_px.end());
  // |fb| of two independent 2-D errors of sigma per coordinate: Rayleigh of scale sqrt(2) sigma, whose median is
  // sqrt(2) sigma sqrt(2 ln 2) = 1.6651 sigma.
  return std::max(floor_px, fb_distances_px[middle] / 1.6651);
}

std::string RigidSceneConfig::validate() const {
  if (!(k_sigma >= 1.0 && k_sigma <= 20.0)) return "k_sigma must be in [1, 20]";
  return "";
}

RigidSceneCheck checkRigidScene(const std::vector<cv::Point2f>& from_px, const std::vector<cv::Point2f>& to_px,
                                double sigma_px, const RigidSceneConfig& config) {
  const std::string invalid = config.validate();
  if (!invalid.empty()) throw std::invalid_argument("rigid scene check: " + invalid);
  if (from_px.size() != to_px.size()) throw std::invalid_argument("rigid scene check: track lists differ in length");
  if (!(sigma_px > 0.0)) throw std::invalid_argument("rigid scene check: sigma_px must be > 0");
  RigidSceneCheck check;
  check.sigma_px = sigma_px;
  check.threshold_px = config.k_sigma * sigma_px;
  check.consistent.assign(from_px.size(), 0);
  std::vector<Eigen::Vector2d> a, b;
  a.reserve(from_px.size());
  b.reserve(to_px.size());
  for (size_t i = 0; i < from_px.size(); ++i) {
    a.emplace_back(from_px[i].x, from_px[i].y);
    b.emplace_back(to_px[i].x, to_px[i].y);
  }
  if (a.size() < 8) {
    check.detail = std::to_string(a.size()) + " tracks: too few for the epipolar geometry (8)";
    return check;
  }
  exocet_common::geometry::FundamentalConfig fc;
  fc.threshold_px = check.threshold_px;
  fc.seed = config.seed;
  const exocet_common::geometry::FundamentalResult f = exocet_common::geometry::FundamentalEstimator(fc).estimate(a, b);
  if (!f.ok) {
    check.detail = "no epipolar geometry: " + f.failure;
    return check;
  }
  check.estimated = true;
  for (size_t i = 0; i < a.size(); ++i) {
    if (exocet_common::geometry::sampsonDistance_px(f.F, a[i], b[i]) <= check.threshold_px) {
      check.consistent[i] = 1;
      ++check.consistent_count;
    }
  }
  std::ostringstream what;
  what << check.consistent_count << " of " << a.size() << " tracks on one epipolar geometry within "
       << check.threshold_px << " px (" << config.k_sigma << " x the tracking noise " << sigma_px << " px)";
  check.detail = what.str();
  return check;
}

}  // namespace registration
}  // namespace exocet_mosaic
