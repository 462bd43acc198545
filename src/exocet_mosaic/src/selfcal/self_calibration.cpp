#include "exocet_mosaic/selfcal/self_calibration.h"

#include <algorithm>
#include <cmath>
#include <iomanip>
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
      << e.starts << " starts converged\n";
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
      << "  residual_rms: " << e.residual_rms << "\n";
  return out.str();
}

}  // namespace selfcal
}  // namespace exocet_mosaic
