#include "exocet_mosaic/selfcal/self_calibration.h"

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <map>
#include <optional>
#include <random>
#include <set>
#include <sstream>

#include <Eigen/Geometry>

namespace exocet_mosaic {
namespace selfcal {

std::string SelfCalibrationConfig::validate() const {
  std::ostringstream err;
  for (const std::string& part :
       {fundamental.validate(), planarity.validate(), intrinsics.validate(), planar_intrinsics.validate()})
    if (!part.empty()) err << part << "; ";
  if (min_inliers < 8) err << "min_inliers = " << min_inliers << " must be >= 8; ";
  if (min_key_frames < 3) err << "min_key_frames = " << min_key_frames << " must be >= 3; ";
  if (!(planar_majority >= 0.0 && planar_majority < 1.0))
    err << "planar_majority = " << planar_majority << " out of range [0, 1); ";
  if (!(max_relative_sigma > 0.0)) err << "max_relative_sigma = " << max_relative_sigma << " must be > 0; ";
  if (bootstrap_replicates != 0 && (bootstrap_replicates < 20 || bootstrap_replicates > 100000))
    err << "bootstrap_replicates = " << bootstrap_replicates << " must be 0 or in [20, 100000]; ";
  std::string s = err.str();
  if (!s.empty()) s.resize(s.size() - 2);
  return s;
}

const char* toString(PairReport::Status status) {
  switch (status) {
    case PairReport::Status::kTooFewMatches:
      return "too_few_matches";
    case PairReport::Status::kTooFewInliers:
      return "too_few_inliers";
    case PairReport::Status::kPlanar:
      return "planar";
    case PairReport::Status::kGeneral:
      return "general";
  }
  return "unknown";
}

const char* toString(CalibrationMethod method) {
  return method == CalibrationMethod::kMendoncaCipolla ? "mendonca_cipolla" : "planar_homographies";
}

namespace {

std::string fixed(double v, int digits) {
  std::ostringstream s;
  s << std::fixed << std::setprecision(digits) << v;
  return s.str();
}

/// Refuses a result that the motion did not constrain: the user would otherwise trust a number that is noise.
void checkConstrained(const IntrinsicsEstimate& e, double max_relative_sigma) {
  const char* names[4] = {"alpha_u", "alpha_v", "u0", "v0"};
  const double values[4] = {e.value.alpha_u, e.value.alpha_v, e.value.u0, e.value.v0};
  const double sigmas[4] = {e.sigma.alpha_u, e.sigma.alpha_v, e.sigma.u0, e.sigma.v0};
  std::ostringstream bad;
  for (int i = 0; i < 4; ++i) {
    const double relative = sigmas[i] / std::abs(values[i]);
    if (!(relative <= max_relative_sigma))
      bad << (bad.tellp() > 0 ? ", " : "") << names[i] << " = " << fixed(values[i], 1) << " +- " << fixed(sigmas[i], 1)
          << " px";
  }
  if (bad.tellp() == 0) return;
  throw CalibrationImpossible(
      CalibrationImpossible::Reason::kUnconstrained,
      "the images do not constrain the intrinsics (" + bad.str() + ", 1-sigma above " +
          fixed(100.0 * max_relative_sigma, 0) +
          " % of the value): use a stretch where the camera turns about its optical axis and rolls and pitches "
          "between key frames, over relief, or more key frames (--max-frames, --step)");
}

/// The key-frame bootstrap's covariance of (alpha_u, alpha_v, u0, v0) (see SelfCalibrationConfig); empty if fewer
/// than half the replicates converged.
std::optional<Eigen::Matrix4d> keyFrameBootstrapCovariance(const std::vector<PairFundamental>& pairs,
                                                           const Intrinsics& estimate, const cv::Size& image_size,
                                                           const SelfCalibrationConfig& config, int* replicates_used) {
  std::set<int> key_set;
  for (const PairFundamental& p : pairs) {
    key_set.insert(p.key_a);
    key_set.insert(p.key_b);
  }
  const std::vector<int> keys(key_set.begin(), key_set.end());
  MendoncaCipollaConfig start = config.intrinsics;
  // One start, at the estimate's focal length (the calibrator starts at the image centre with square pixels).
  start.initial_hfov_deg = 2.0 * std::atan(0.5 * image_size.width / estimate.alpha_u) * 180.0 / M_PI;
  start.focal_start_factors = {1.0};
  const MendoncaCipollaCalibrator calibrator(start);
  std::mt19937_64 rng(config.bootstrap_seed);
  std::uniform_int_distribution<int> pick(0, static_cast<int>(keys.size()) - 1);
  std::vector<Eigen::Vector4d> samples;
  for (int replicate = 0; replicate < config.bootstrap_replicates; ++replicate) {
    std::map<int, int> multiplicity;
    for (size_t k = 0; k < keys.size(); ++k) ++multiplicity[keys[pick(rng)]];
    std::vector<PairFundamental> drawn;
    for (const PairFundamental& p : pairs) {
      const auto a = multiplicity.find(p.key_a), b = multiplicity.find(p.key_b);
      if (a == multiplicity.end() || b == multiplicity.end()) continue;
      PairFundamental q = p;
      q.weight *= a->second * b->second;
      drawn.push_back(q);
    }
    try {
      const IntrinsicsEstimate e = calibrator.calibrate(drawn, image_size);
      samples.emplace_back(e.value.alpha_u, e.value.alpha_v, e.value.u0, e.value.v0);
    } catch (const std::exception&) {
      // Too few pairs drawn, or no admissible solution: a replicate lost, counted below.
    }
  }
  *replicates_used = static_cast<int>(samples.size());
  if (samples.size() < 10 || 2 * samples.size() < static_cast<size_t>(config.bootstrap_replicates))
    return std::nullopt;
  Eigen::Vector4d mean = Eigen::Vector4d::Zero();
  for (const Eigen::Vector4d& x : samples) mean += x;
  mean /= static_cast<double>(samples.size());
  Eigen::Matrix4d covariance = Eigen::Matrix4d::Zero();
  for (const Eigen::Vector4d& x : samples) covariance += (x - mean) * (x - mean).transpose();
  return Eigen::Matrix4d(covariance / static_cast<double>(samples.size() - 1));
}

}  // namespace

SelfCalibrationResult selfCalibrate(const std::vector<KeyFramePair>& pairs, const cv::Size& image_size,
                                    const SelfCalibrationConfig& config) {
  const std::string problem = config.validate();
  if (!problem.empty()) throw std::invalid_argument("self-calibration: " + problem);
  SelfCalibrationResult result;
  result.image_size = image_size;
  result.pairs.reserve(pairs.size());
  for (const KeyFramePair& pair : pairs) {
    PairReport r;
    r.key_a = pair.key_a;
    r.key_b = pair.key_b;
    r.frame_a = pair.frame_a;
    r.frame_b = pair.frame_b;
    r.matches = static_cast<int>(pair.points_a.size());
    if (r.matches < config.min_inliers) {
      r.status = PairReport::Status::kTooFewMatches;
      result.pairs.push_back(r);
      continue;
    }
    FundamentalConfig fc = config.fundamental;
    fc.seed = config.fundamental.seed * 1000003ULL + static_cast<uint64_t>(pair.key_a) * 7919ULL +
              static_cast<uint64_t>(pair.key_b);
    r.fundamental = FundamentalEstimator(fc).estimate(pair.points_a, pair.points_b);
    if (!r.fundamental.ok || r.fundamental.inlier_count < config.min_inliers) {
      r.status = PairReport::Status::kTooFewInliers;
      result.pairs.push_back(r);
      continue;
    }
    r.planarity = assessPlanarity(pair.points_a, pair.points_b, r.fundamental, config.planarity);
    r.status = r.planarity.planar ? PairReport::Status::kPlanar : PairReport::Status::kGeneral;
    (r.planarity.planar ? result.planar_pairs : result.general_pairs)++;
    result.pairs.push_back(r);
  }
  const int assessed = result.planar_pairs + result.general_pairs;
  if (assessed == 0) {
    std::ostringstream msg;
    msg << "too few tracks: none of the " << pairs.size() << " key-frame pairs sharing tracks has "
        << config.min_inliers
        << " matches consistent with one epipolar geometry; use a smaller --step, more frames (--max-frames) or a "
           "stretch of the dive with more texture";
    throw CalibrationImpossible(CalibrationImpossible::Reason::kTooFewTracks, msg.str());
  }
  result.scene_planar = result.planar_pairs > config.planar_majority * assessed;

  if (result.scene_planar) {
    if (!config.allow_planar) {
      std::ostringstream msg;
      msg << "the seabed is flat: " << result.planar_pairs << " of " << assessed
          << " key-frame pairs are explained by a homography as well as by a fundamental matrix (GRIC), so their "
             "epipolar geometry is degenerate and Mendonca-Cipolla cannot recover the intrinsics from it; fly over "
             "relief (rocks, mounds, slopes) or use --planar to calibrate from the seabed plane's homographies "
             "(which needs the camera to roll and pitch between key frames)";
      throw CalibrationImpossible(CalibrationImpossible::Reason::kFlatSeabed, msg.str());
    }
    std::vector<PairHomography> homographies;
    std::set<int> keys;
    for (PairReport& r : result.pairs) {
      if (r.status != PairReport::Status::kPlanar) continue;
      homographies.push_back(PairHomography{r.key_a, r.key_b, r.planarity.H, double(r.planarity.homography_inliers)});
      r.used = true;
      keys.insert(r.key_a);
      keys.insert(r.key_b);
    }
    result.method = CalibrationMethod::kPlanarHomographies;
    result.pairs_used = static_cast<int>(homographies.size());
    result.key_frames_used = static_cast<int>(keys.size());
    PlanarCalibrationConfig pc = config.planar_intrinsics;
    pc.min_key_frames = std::max(4, config.min_key_frames);
    try {
      result.intrinsics = PlanarSelfCalibrator(pc).calibrate(homographies, image_size);
    } catch (const std::runtime_error& e) {
      throw CalibrationImpossible(CalibrationImpossible::Reason::kUnconstrained, e.what());
    }
    if (result.general_pairs > 0)
      result.notes.push_back(std::to_string(result.general_pairs) +
                             " pairs showed parallax (GRIC) and were left out of the planar calibration");
    result.residual_sigma = result.intrinsics.sigma;
    checkConstrained(result.intrinsics, config.max_relative_sigma);
    return result;
  }

  std::vector<PairFundamental> fundamentals;
  std::set<int> keys;
  for (const PairReport& r : result.pairs) {
    if (r.status != PairReport::Status::kGeneral) continue;
    keys.insert(r.key_a);
    keys.insert(r.key_b);
  }
  if (static_cast<int>(keys.size()) < config.min_key_frames) {
    std::ostringstream msg;
    msg << "too few tracks: the pairs with a usable fundamental matrix involve only " << keys.size()
        << " key frames, at least " << config.min_key_frames
        << " needed; use a smaller --step or more frames (--max-frames)";
    throw CalibrationImpossible(CalibrationImpossible::Reason::kTooFewTracks, msg.str());
  }
  for (PairReport& r : result.pairs) {
    if (r.status != PairReport::Status::kGeneral) continue;
    // Confidence in F: many inliers, small residuals.
    const double rms = std::max(r.fundamental.rms_sampson_px, 0.01);
    fundamentals.push_back(
        PairFundamental{r.key_a, r.key_b, r.fundamental.F, r.fundamental.inlier_count / (rms * rms)});
    r.used = true;
  }
  result.method = CalibrationMethod::kMendoncaCipolla;
  result.pairs_used = static_cast<int>(fundamentals.size());
  result.key_frames_used = static_cast<int>(keys.size());
  if (config.allow_planar)
    result.notes.push_back("--planar was given but the seabed shows relief: calibrated by Mendonca-Cipolla");
  if (result.planar_pairs > 0)
    result.notes.push_back(std::to_string(result.planar_pairs) +
                           " pairs had too little parallax (planar by GRIC) and were left out");
  try {
    result.intrinsics = MendoncaCipollaCalibrator(config.intrinsics).calibrate(fundamentals, image_size);
  } catch (const std::runtime_error& e) {
    throw CalibrationImpossible(CalibrationImpossible::Reason::kUnconstrained, e.what());
  }
  result.residual_sigma = result.intrinsics.sigma;
  if (config.bootstrap_replicates > 0) {
    const std::optional<Eigen::Matrix4d> bootstrap = keyFrameBootstrapCovariance(
        fundamentals, result.intrinsics.value, image_size, config, &result.bootstrap_replicates_used);
    if (bootstrap) {
      // Each parameter's 1-sigma: the larger of the two; the correlations: the bootstrap's.
      IntrinsicsEstimate& e = result.intrinsics;
      Eigen::Vector4d sigma;
      for (int i = 0; i < 4; ++i)
        sigma(i) = std::max(std::sqrt(std::max(0.0, e.covariance(i, i))), std::sqrt(std::max(0.0, (*bootstrap)(i, i))));
      const Eigen::Vector4d boot_sigma = bootstrap->diagonal().cwiseMax(1e-300).cwiseSqrt();
      const Eigen::Matrix4d correlation = boot_sigma.cwiseInverse().asDiagonal() * (*bootstrap) *
                                          boot_sigma.cwiseInverse().asDiagonal();
      e.covariance = sigma.asDiagonal() * correlation * sigma.asDiagonal();
      e.sigma = Intrinsics{sigma(0), sigma(1), sigma(2), sigma(3)};
      result.uncertainty = "key-frame bootstrap";
    } else {
      result.notes.push_back("the key-frame bootstrap did not converge in enough replicates (" +
                             std::to_string(result.bootstrap_replicates_used) + " of " +
                             std::to_string(config.bootstrap_replicates) +
                             "): the 1-sigma is the residual-based one, which takes the pairs as independent");
    }
  }
  checkConstrained(result.intrinsics, config.max_relative_sigma);
  const Eigen::Matrix3d K = result.intrinsics.value.K();
  for (size_t i = 0; i < pairs.size(); ++i) {
    PairReport& r = result.pairs[i];
    if (!r.used) continue;
    r.pose =
        relativePoseFromFundamental(r.fundamental.F, K, pairs[i].points_a, pairs[i].points_b, r.fundamental.inliers);
  }
  return result;
}

std::string summaryText(const SelfCalibrationResult& result) {
  std::ostringstream out;
  const IntrinsicsEstimate& e = result.intrinsics;
  out << "Self-calibration: "
      << (result.method == CalibrationMethod::kMendoncaCipolla ? "Mendonca-Cipolla over the fundamental matrices"
                                                               : "planar (Triggs) over the seabed homographies")
      << " of " << result.pairs_used << " key-frame pairs (" << result.key_frames_used << " key frames), image "
      << result.image_size.width << "x" << result.image_size.height << "\n";
  auto line = [&](const char* name, double v, double s) {
    out << "  " << std::left << std::setw(8) << name << std::right << "= " << std::setw(9) << fixed(v, 2) << " +- "
        << fixed(s, 2) << " px  (1 sigma, " << fixed(100.0 * s / std::abs(v), 2) << " %)\n";
  };
  line("alpha_u", e.value.alpha_u, e.sigma.alpha_u);
  line("alpha_v", e.value.alpha_v, e.sigma.alpha_v);
  line("u0", e.value.u0, e.sigma.u0);
  line("v0", e.value.v0, e.sigma.v0);
  out << "  horizontal field of view "
      << fixed(2.0 * std::atan(0.5 * result.image_size.width / e.value.alpha_u) * 180.0 / M_PI, 2)
      << " deg; residual RMS " << std::setprecision(3) << e.residual_rms << "; " << e.starts_converged << " of "
      << e.starts << " starts converged; 1-sigma from " << result.uncertainty
      << (result.uncertainty == "residuals" ? "" : " (" + std::to_string(result.bootstrap_replicates_used) + " replicates)")
      << "\n";
  const int assessed = result.planar_pairs + result.general_pairs;
  out << "Planarity: " << (result.scene_planar ? "FLAT seabed" : "relief") << " (" << result.general_pairs << " of "
      << assessed << " assessed pairs show parallax, " << result.planar_pairs
      << " are explained by a homography; GRIC)\n";
  out << "Pairs: " << result.pairs.size() << " sharing tracks, " << assessed << " assessed, " << result.pairs_used
      << " used\n";
  for (const std::string& note : result.notes) out << "Note: " << note << "\n";
  if (result.method == CalibrationMethod::kMendoncaCipolla) {
    out << "Extrinsics (x_b = R x_a + t; R as angle about axis, t unit direction in camera b):\n";
    for (const PairReport& r : result.pairs) {
      if (!r.used) continue;
      const Eigen::AngleAxisd aa(r.pose.R_b_a);
      out << "  keys " << r.key_a << "-" << r.key_b << " (frames " << r.frame_a << "-" << r.frame_b << "): R "
          << fixed(aa.angle() * 180.0 / M_PI, 2) << " deg about (" << fixed(aa.axis().x(), 3) << ", "
          << fixed(aa.axis().y(), 3) << ", " << fixed(aa.axis().z(), 3) << "), t (" << fixed(r.pose.t_b_a.x(), 3)
          << ", " << fixed(r.pose.t_b_a.y(), 3) << ", " << fixed(r.pose.t_b_a.z(), 3) << "), " << r.pose.points_in_front
          << "/" << r.pose.points_tested << " points in front, " << r.fundamental.inlier_count << "/" << r.matches
          << " inliers\n";
    }
  }
  return out.str();
}

std::string selfCalibrationYamlBlock(const SelfCalibrationResult& result) {
  const IntrinsicsEstimate& e = result.intrinsics;
  std::ostringstream out;
  out << std::setprecision(10);
  out << "self_calibration:\n"
      << "  method: " << toString(result.method) << "\n"
      << "  alpha_u_sigma_px: " << e.sigma.alpha_u << "\n"
      << "  alpha_v_sigma_px: " << e.sigma.alpha_v << "\n"
      << "  u0_sigma_px: " << e.sigma.u0 << "\n"
      << "  v0_sigma_px: " << e.sigma.v0 << "\n"
      << "  pairs_used: " << result.pairs_used << "\n"
      << "  key_frames_used: " << result.key_frames_used << "\n"
      << "  planar_pairs: " << result.planar_pairs << "\n"
      << "  general_pairs: " << result.general_pairs << "\n"
      << "  seabed_flat: " << (result.scene_planar ? "true" : "false") << "\n"
      << "  residual_rms: " << e.residual_rms << "\n"
      << "  sigma_from: \"" << result.uncertainty << "\"\n";
  return out.str();
}

}  // namespace selfcal
}  // namespace exocet_mosaic
