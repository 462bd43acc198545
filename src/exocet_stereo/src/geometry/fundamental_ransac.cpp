#include "exocet_stereo/geometry/fundamental_ransac.h"

#include <algorithm>
#include <sstream>
#include <stdexcept>

#include "exocet_common/geometry/fundamental_estimator.h"

namespace exocet_stereo {
namespace geometry {

std::string FundamentalRansacConfig::validate() const {
  std::ostringstream errors;
  auto check = [&errors](bool ok, const char* field, const char* range) {
    if (ok) return;
    if (errors.tellp() > 0) errors << "; ";
    errors << field << " must be in " << range;
  };
  check(threshold_px > 0.0 && threshold_px <= 50.0, "threshold_px", "(0, 50]");
  check(confidence > 0.0 && confidence < 1.0, "confidence", "(0, 1)");
  check(max_samples >= 1 && max_samples <= 100000, "max_samples", "[1, 100000]");
  check(refits >= 0 && refits <= 20, "refits", "[0, 20]");
  return errors.str();
}

FundamentalFit fitFundamentalRansac(const std::vector<Eigen::Vector2d>& a, const std::vector<Eigen::Vector2d>& b,
                                    const FundamentalRansacConfig& config) {
  const std::string error = config.validate();
  if (!error.empty()) throw std::invalid_argument("FundamentalRansacConfig: " + error);
  if (a.size() != b.size())
    throw std::invalid_argument("fitFundamentalRansac: " + std::to_string(a.size()) +
                                " points in the first image but " + std::to_string(b.size()) + " in the second");
  FundamentalFit fit;
  fit.inliers.assign(a.size(), false);
  if (a.size() < 8) {
    fit.failure = "at least 8 matches are needed, got " + std::to_string(a.size());
    return fit;
  }
  // The project's own normalised 8-point inside MSAC (exocet_mosaic's self-calibration core).
  exocet_common::geometry::FundamentalConfig estimator_config;
  estimator_config.threshold_px = config.threshold_px;
  estimator_config.confidence = config.confidence;
  estimator_config.max_iterations = config.max_samples;
  estimator_config.refinement_rounds = std::max(1, config.refits);
  estimator_config.seed = config.seed;
  const exocet_common::geometry::FundamentalResult result =
      exocet_common::geometry::FundamentalEstimator(estimator_config).estimate(a, b);
  fit.samples = result.iterations;
  if (!result.ok) {
    fit.failure = result.failure;
    return fit;
  }
  fit.ok = true;
  fit.F = result.F;
  fit.inliers = result.inliers;
  fit.inlier_count = result.inlier_count;
  fit.rms_sampson_px = result.rms_sampson_px;
  return fit;
}

}  // namespace geometry
}  // namespace exocet_stereo
