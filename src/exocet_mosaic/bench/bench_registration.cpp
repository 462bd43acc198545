// Benchmark of the frame-to-frame registration (2D3 sections 3.1, 3.2): accuracy against the simulator's ground
// truth over a 2000-frame dive with turbid and dark stretches, agreement with a SIFT + RANSAC reference on the real
// Sparus AUV frames, and speed on one thread, side by side with OpenCV's ECC (affine, pyramid) and a feature
// pipeline (ORB + estimateAffinePartial2D); and the same dive filmed by the PAL, HD and 4K UHD camera presets, each
// registered with its registration preset (errors also in HD pixels). Writes registration.json (and keeps the keys
// another bench added).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <functional>
#include <iomanip>
#include <iostream>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <time.h>

#include <nlohmann/json.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/video.hpp>

#include "exocet_mosaic/registration/normalizing_registrar.h"
#include "exocet_mosaic/registration/registration_config.h"
#include "exocet_mosaic/registration/sequence_evaluation.h"
#include "exocet_mosaic/registration/sift_reference.h"
#include "exocet_mosaic/sim/dive_description.h"
#include "exocet_mosaic/sim/image_motion_truth.h"
#include "exocet_common/json_file.h"
#include "exocet_mosaic/sim/rendered_dive.h"
#include "exocet_mosaic/video/mosaic_presets.h"
#include "exocet_common/command_line.h"
#include "exocet_common/testing/paths.h"
#include "shared_data.h"

namespace {

using namespace exocet_mosaic;
using namespace exocet_mosaic::registration;
using Clock = std::chrono::steady_clock;

double msSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

Eigen::Matrix3d toEigen(const cv::Mat& m) {
  Eigen::Matrix3d e = Eigen::Matrix3d::Identity();
  for (int r = 0; r < m.rows; ++r)
    for (int c = 0; c < 3; ++c) e(r, c) = m.at<double>(r, c);
  return e;
}

// ---- OpenCV peers -------------------------------------------------------------------------------------------------

/// cv::findTransformECC, affine, coarse to fine over a 3-level pyramid (the warp maps A's pixels to B's).
MotionEstimate eccAffine(const cv::Mat& a, const cv::Mat& b) {
  const auto start = Clock::now();
  MotionEstimate e;
  e.model = MotionModel::kAffine;
  const int levels = 3;
  std::vector<cv::Mat> pa{a}, pb{b};
  for (int l = 1; l < levels; ++l) {
    cv::Mat da, db;
    cv::pyrDown(pa.back(), da);
    cv::pyrDown(pb.back(), db);
    pa.push_back(da);
    pb.push_back(db);
  }
  cv::Mat warp = cv::Mat::eye(2, 3, CV_32F);
  warp.at<float>(0, 2) /= float(1 << (levels - 1));
  try {
    for (int l = levels - 1; l >= 0; --l) {
      cv::findTransformECC(pa[l], pb[l], warp, cv::MOTION_AFFINE,
                           cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 50, 1e-5), cv::noArray(),
                           3);
      if (l > 0) {
        warp.at<float>(0, 2) *= 2.f;
        warp.at<float>(1, 2) *= 2.f;
      }
    }
    e.failed = false;
    e.failure = FailureReason::kNone;
    e.pixel_matrix = Eigen::Matrix3d::Identity();
    for (int r = 0; r < 2; ++r)
      for (int c = 0; c < 3; ++c) e.pixel_matrix(r, c) = warp.at<float>(r, c);
  } catch (const cv::Exception&) {
    e.failed = true;
    e.failure = FailureReason::kNotConverged;
  }
  e.elapsed_ms = msSince(start);
  return e;
}

/// ORB features, cross-checked Hamming matches, cv::estimateAffinePartial2D (RANSAC then refinement).
MotionEstimate orbPartialAffine(const cv::Mat& a, const cv::Mat& b, cv::Ptr<cv::ORB>& orb) {
  const auto start = Clock::now();
  MotionEstimate e;
  e.model = MotionModel::kSimilarity;
  std::vector<cv::KeyPoint> ka, kb;
  cv::Mat da, db;
  orb->detectAndCompute(a, cv::noArray(), ka, da);
  orb->detectAndCompute(b, cv::noArray(), kb, db);
  std::vector<cv::DMatch> matches;
  if (!da.empty() && !db.empty()) cv::BFMatcher(cv::NORM_HAMMING, true).match(da, db, matches);
  std::vector<cv::Point2f> pa, pb;
  for (const cv::DMatch& m : matches) {
    pa.push_back(ka[m.queryIdx].pt);
    pb.push_back(kb[m.trainIdx].pt);
  }
  cv::Mat m;
  if (pa.size() >= 10) m = cv::estimateAffinePartial2D(pa, pb, cv::noArray(), cv::RANSAC, 2.0);
  e.failed = m.empty();
  e.failure = e.failed ? FailureReason::kTooFewInliers : FailureReason::kNone;
  if (!e.failed) e.pixel_matrix = toEigen(m);
  e.elapsed_ms = msSince(start);
  return e;
}

// ---- Helpers ------------------------------------------------------------------------------------------------------

RegistrationConfig configFor(RegistrationMethod method, MotionModel model) {
  RegistrationConfig c;
  c.method = method;
  c.model = model;
  return c;
}

/// Per-thread CPU time: the machine is shared, so wall-clock rates are noisy; this one counts our own work only.
double threadCpuSeconds() {
  timespec ts;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

struct Speed {
  double wall_fps = 0.0;
  double cpu_fps = 0.0;  ///< frames per second of this thread's CPU time
  int frames = 0;
  // KLT only: mean wall-clock milliseconds per frame in each stage (KltDiagnostics); `other` is the rest of
  // registerNext (illumination normaliser, input checks).
  bool has_stages = false;
  double pyramid_ms = 0.0, track_ms = 0.0, detect_ms = 0.0, fit_ms = 0.0, other_ms = 0.0;
  double detections_per_frame = 0.0, features_per_frame = 0.0;
};

/// Rate of the registration front-end registration_node runs (SequenceRegistrar: prediction, restart policy,
/// fallback) over `frames` taken at `stamps_s`, the clip repeated until at least `min_seconds` of wall time have
/// passed.
Speed speed(RegistrationMethod method, MotionModel model, const std::vector<cv::Mat>& frames,
            const std::vector<double>& stamps_s, double min_seconds) {
  SequenceRegistrar sequence(makeRegistrar(configFor(method, model)), SequenceRegistrarConfig());
  FrameRegistrar* inner = &sequence.registrar();
  if (auto* normalizing = dynamic_cast<NormalizingRegistrar*>(inner)) inner = &normalizing->inner();
  const auto* klt = dynamic_cast<const KltRegistrar*>(inner);
  Speed s;
  s.has_stages = klt != nullptr;
  double total_ms = 0.0, stages_ms = 0.0;
  int detections = 0, features = 0;
  const auto start = Clock::now();
  const double cpu_start = threadCpuSeconds();
  do {
    sequence.restart();
    for (size_t i = 0; i < frames.size(); ++i) {
      const SequenceStep step = sequence.add(frames[i], stamps_s[i]);
      const MotionEstimate& e = step.motion;
      ++s.frames;
      if (klt) {
        const KltDiagnostics& d = klt->lastDiagnostics();
        s.pyramid_ms += d.pyramid_ms;
        s.track_ms += d.track_ms;
        s.detect_ms += d.detect_ms;
        s.fit_ms += d.fit_ms;
        stages_ms += d.pyramid_ms + d.track_ms + d.detect_ms + d.fit_ms;
        total_ms += e.elapsed_ms;
        detections += d.detected > 0;
        features += d.features;
      }
    }
  } while (msSince(start) < 1000.0 * min_seconds);
  const double cpu_s = threadCpuSeconds() - cpu_start;
  s.wall_fps = 1000.0 * s.frames / msSince(start);
  s.cpu_fps = cpu_s > 0.0 ? s.frames / cpu_s : 0.0;
  if (klt) {
    const double n = s.frames;
    s.pyramid_ms /= n;
    s.track_ms /= n;
    s.detect_ms /= n;
    s.fit_ms /= n;
    s.other_ms = (total_ms - stages_ms) / n;
    s.detections_per_frame = detections / n;
    s.features_per_frame = features / n;
  }
  return s;
}

void printSpeed(const std::string& name, const Speed& s) {
  std::ostringstream line;  // its own stream, so that std::cout's number format stays as it was
  line << std::fixed << std::setprecision(1) << "speed " << std::left << std::setw(20) << name << std::right
       << std::setw(7) << s.wall_fps << " frames/s wall, " << std::setw(7) << s.cpu_fps << " per CPU second ("
       << s.frames << " frames)";
  if (s.has_stages)
    line << std::setprecision(3) << "; ms/frame: pyramid " << s.pyramid_ms << ", track " << s.track_ms << ", detect "
         << s.detect_ms << ", fit " << s.fit_ms << ", normaliser and rest " << s.other_ms << std::setprecision(2)
         << "; detections/frame " << s.detections_per_frame << ", features/frame " << std::setprecision(0)
         << s.features_per_frame;
  std::cout << line.str() << "\n";
}

template <typename Peer>
SequenceScore peerScore(const std::vector<cv::Mat>& frames, const std::vector<Eigen::Matrix3d>& truth, int stride,
                        Peer peer) {
  std::vector<PairScore> pairs;
  for (size_t i = stride; i < frames.size(); i += stride) {
    const MotionEstimate e = peer(frames[i - 1], frames[i]);
    PairScore s;
    s.index = int(i);
    s.failed = e.failed;
    s.elapsed_ms = e.elapsed_ms;
    s.corner_error_px =
        e.failed ? std::nan("") : cornerTransferError_px(e.pixel_matrix, truth[i], frames[i].cols, frames[i].rows);
    s.corner_nees = std::nan("");
    pairs.push_back(s);
  }
  return summarize(pairs);
}

void printRow(const std::string& name, const SequenceScore& s, double fps, double ratio_ecc, double ratio_features) {
  std::cout << std::left << std::setw(30) << name << std::right << std::fixed << std::setprecision(3) << std::setw(9)
            << s.median_px << std::setw(9) << s.p95_px << std::setprecision(2) << std::setw(9) << 100.0 * s.failure_rate
            << std::setw(9) << 100.0 * s.gross_failure_rate << std::setprecision(0) << std::setw(9) << fps;
  if (ratio_ecc > 0) std::cout << std::setprecision(1) << std::setw(9) << ratio_ecc << std::setw(9) << ratio_features;
  std::cout << "\n";
}

/// Score of the pairs of `all` that `select` keeps (the registrar already ran over the whole sequence).
SequenceScore subset(const SequenceScore& all, const std::function<bool(int)>& select) {
  std::vector<PairScore> pairs;
  for (const PairScore& p : all.pairs)
    if (select(p.index)) pairs.push_back(p);
  return summarize(pairs);
}

}  // namespace

int main(int argc, char** argv) {
  exocet_common::BenchmarkPaths paths;
  const std::string config_dir = exocet_common::testing::configDir();
  int frames_limit = 0, wreck_frames_limit = 0;
  int preset_frames = 250;
  std::vector<std::string> part_list = {"accuracy", "peers", "speed", "wreck", "presets"}, method_list;
  CLI::App app(
      "bench_registration: accuracy and speed of the frame-to-frame registration (KLT, RMR, auto) on a\n"
      "simulated dive and the Sparus AUV frames, beside OpenCV's ECC and an ORB feature pipeline.\n"
      "Writes OUTPUT_DIR/registration.json; keys not measured keep their value in that file.",
      "bench_registration");
  exocet_common::addBenchmarkPathOptions(app, &paths);
  app.add_option("--frames", frames_limit, "frames of the simulated dive (0: all)")
      ->type_name("N")
      ->check(exocet_common::atLeast(0))
      ->capture_default_str();
  app.add_option("--wreck-frames", wreck_frames_limit, "frames of the wreck dive (0: all)")
      ->type_name("N")
      ->check(exocet_common::atLeast(0))
      ->capture_default_str();
  app.add_option("--only", part_list,
                 "comma-separated subset of accuracy (simulated dive and Sparus), peers (OpenCV ECC\n"
                 "and ORB), speed (ours, one thread, PAL and HD), wreck (KLT and RMR over strong relief),\n"
                 "presets (the camera presets pal, hd, uhd with their registration presets, errors in HD px);\n"
                 "default all")
      ->type_name("PARTS")
      ->delimiter(',')
      ->check(CLI::IsMember({"accuracy", "peers", "speed", "wreck", "presets"}));
  app.add_option("--preset-frames", preset_frames, "frames of the dive per camera preset (presets part)")
      ->type_name("N")
      ->check(exocet_common::atLeast(10))
      ->capture_default_str();
  app.add_option("--methods", method_list,
                 "comma-separated subset of klt, rmr, auto, klt_similarity, rmr_similarity, klt_affine,\n"
                 "rmr_affine (accuracy), and of klt, rmr, auto (speed); default all")
      ->type_name("KEYS")
      ->delimiter(',');
  if (const auto exit_status = exocet_common::parseCommandLine(app, argc, argv)) return *exit_status;
  const std::string& out_dir = paths.output_dir;
  const std::string& shared = paths.shared_data;
  const std::set<std::string> parts(part_list.begin(), part_list.end());
  std::set<std::string> methods;
  for (const std::string& m : method_list)
    if (!m.empty()) methods.insert(m);
  const bool accuracy = parts.count("accuracy"), peers = parts.count("peers"), timing = parts.count("speed"),
             wreck = parts.count("wreck"), presets = parts.count("presets");
  auto wanted = [&methods](const std::string& key) { return methods.empty() || methods.count(key) > 0; };
  cv::setNumThreads(1);
  std::cout << std::unitbuf;  // progress lines appear as they happen, also when redirected to a file
  std::filesystem::create_directories(out_dir);
  // Keys this run does not measure keep their value (bench_registration_node adds node_peak_rss_mb and node_fps_pal).
  nlohmann::json json = exocet_common::readJsonObjectFile<nlohmann::json>(out_dir + "/registration.json")
                            .value_or(nlohmann::json::object());

  // ---- 1. Accuracy on the simulated dive ----
  std::vector<std::string> overrides;
  if (frames_limit > 0) overrides.push_back("duration_s=" + std::to_string(frames_limit / 25.0 - 0.01));
  const sim::DiveDescription dive = sim::loadDiveDescription(config_dir + "/dives/bench_registration.yaml", overrides);
  auto t0 = Clock::now();
  const sim::RenderedDive pal = sim::renderDiveCached(dive, 2, out_dir + "/cache");
  std::cout << "rendered " << pal.gray.size() << " PAL frames in " << msSince(t0) / 1000.0 << " s\n";
  std::vector<Eigen::Matrix3d> truth(pal.gray.size(), Eigen::Matrix3d::Identity());
  for (size_t i = 1; i < pal.gray.size(); ++i)
    truth[i] = sim::seabedPlaneHomography(pal.camera, pal.local_from_camera[i - 1], pal.local_from_camera[i]);

  struct Candidate {
    std::string key;
    RegistrationMethod method;
    MotionModel model;
  };
  const std::vector<Candidate> candidates = {
      {"klt", RegistrationMethod::kKlt, MotionModel::kHomography},
      {"rmr", RegistrationMethod::kRmr, MotionModel::kHomography},
      {"auto", RegistrationMethod::kAuto, MotionModel::kHomography},
      {"klt_similarity", RegistrationMethod::kKlt, MotionModel::kSimilarity},
      {"rmr_similarity", RegistrationMethod::kRmr, MotionModel::kSimilarity},
      {"klt_affine", RegistrationMethod::kKlt, MotionModel::kAffine},
      {"rmr_affine", RegistrationMethod::kRmr, MotionModel::kAffine},
  };
  std::map<std::string, SequenceScore> scores;
  if (accuracy) {
    for (const Candidate& c : candidates) {
      if (!wanted(c.key)) continue;
      SequenceRegistrar r(makeRegistrar(configFor(c.method, c.model)), SequenceRegistrarConfig());
      t0 = Clock::now();
      const SequenceScore& s = scores[c.key] = evaluateSequence(r, pal.gray, pal.stamps_s, truth);
      const double run_s = msSince(t0) / 1000.0;
      // The segments are scored on the same run: the registrar's state is that of the whole dive.
      const SequenceScore s_dark = subset(s, [&](int i) { return pal.light_gain[i] < 1.0; });
      const SequenceScore s_turbid = subset(s, [&](int i) { return pal.turbidity[i] > 1.0; });
      json[c.key + "_median_px"] = s.median_px;
      json[c.key + "_p95_px"] = s.p95_px;
      json[c.key + "_failure_rate"] = s.failure_rate;
      json[c.key + "_gross_failure_rate"] = s.gross_failure_rate;
      json[c.key + "_nees_ratio"] = s.nees_ratio;
      json[c.key + "_dark_median_px"] = s_dark.median_px;
      json[c.key + "_turbid_median_px"] = s_turbid.median_px;
      std::cout << c.key << ": median " << s.median_px << " px, p95 " << s.p95_px << " px, max " << s.max_px
                << ", failed " << s.failures << ", gross " << s.gross_failures << ", NEES ratio " << s.nees_ratio
                << "; dark median " << s_dark.median_px << " (" << s_dark.failures << " failed), turbid median "
                << s_turbid.median_px << " (" << s_turbid.failures << " failed); " << run_s << " s\n";
    }
    json["dive_pairs"] = double(pal.gray.size() - 1);
    if (scores.count("klt") && scores.count("rmr"))
      json["gross_failure_rate"] = std::max(scores["klt"].gross_failure_rate, scores["rmr"].gross_failure_rate);
    if (scores.count("auto")) json["auto_gross_failure_rate"] = scores["auto"].gross_failure_rate;
  }

  // Peers on every 5th pair (they are slow).
  SequenceScore ecc, features;
  if (peers) {
    cv::Ptr<cv::ORB> orb = cv::ORB::create(1000);
    ecc = peerScore(pal.gray, truth, 5, [](const cv::Mat& a, const cv::Mat& b) { return eccAffine(a, b); });
    features =
        peerScore(pal.gray, truth, 5, [&](const cv::Mat& a, const cv::Mat& b) { return orbPartialAffine(a, b, orb); });
    json["ecc_median_px"] = ecc.median_px;
    json["ecc_p95_px"] = ecc.p95_px;
    json["ecc_failure_rate"] = ecc.failure_rate;
    json["ecc_gross_failure_rate"] = ecc.gross_failure_rate;
    json["features_median_px"] = features.median_px;
    json["features_p95_px"] = features.p95_px;
    json["features_failure_rate"] = features.failure_rate;
    json["features_gross_failure_rate"] = features.gross_failure_rate;
    json["ecc_fps_pal"] = ecc.fps;
    json["features_fps_pal"] = features.fps;
    std::cout << "ECC affine: median " << ecc.median_px << " px, p95 " << ecc.p95_px << ", " << ecc.fps
              << " pairs/s; ORB: median " << features.median_px << " px, p95 " << features.p95_px << ", "
              << features.fps << " pairs/s\n";
  }

  // ---- 2. Speed, one thread: wall-clock and per-thread CPU rates ----
  std::map<std::string, Speed> fps;
  const sim::DiveDescription hd_dive =
      sim::loadDiveDescription(config_dir + "/dives/bench_registration.yaml", {"camera.preset=hd", "duration_s=11.99"});
  if (timing) {
    // 300 frames (12 s) of the dive: long enough that tracking, not the first detection, sets the rate.
    const size_t clip_frames = std::min<size_t>(300, pal.gray.size());
    const std::vector<cv::Mat> pal_clip(pal.gray.begin(), pal.gray.begin() + clip_frames);
    const std::vector<double> pal_clip_stamps_s(pal.stamps_s.begin(), pal.stamps_s.begin() + clip_frames);
    struct Timed {
      std::string key;
      RegistrationMethod method;
      MotionModel model;
      double seconds;
    };
    const std::vector<Timed> timed = {
        {"klt", RegistrationMethod::kKlt, MotionModel::kSimilarity, 3.0},
        {"rmr", RegistrationMethod::kRmr, MotionModel::kSimilarity, 3.0},
        {"klt_homography", RegistrationMethod::kKlt, MotionModel::kHomography, 2.0},
        {"rmr_homography", RegistrationMethod::kRmr, MotionModel::kHomography, 2.0},
        {"auto", RegistrationMethod::kAuto, MotionModel::kSimilarity, 2.0},
    };
    for (const Timed& t : timed) {
      if (!wanted(t.key.substr(0, t.key.find('_')))) continue;
      fps[t.key] = speed(t.method, t.model, pal_clip, pal_clip_stamps_s, t.seconds);
      json[t.key + "_fps_pal"] = fps[t.key].wall_fps;
      json[t.key + "_fps_pal_cpu"] = fps[t.key].cpu_fps;
      printSpeed(t.key + " PAL", fps[t.key]);
    }

    t0 = Clock::now();
    const sim::RenderedDive hd = sim::renderDiveCached(hd_dive, 2, out_dir + "/cache");
    std::cout << "rendered " << hd.gray.size() << " HD frames in " << msSince(t0) / 1000.0 << " s\n";
    for (const Timed& t : timed) {
      if (t.key == "auto" || !wanted(t.key.substr(0, t.key.find('_')))) continue;
      const Speed s = speed(t.method, t.model, hd.gray, hd.stamps_s, 3.0);
      json[t.key + "_fps_hd"] = s.wall_fps;
      json[t.key + "_fps_hd_cpu"] = s.cpu_fps;
      printSpeed(t.key + " HD", s);
    }
  }
  if (peers) {
    const sim::RenderedDive hd = sim::renderDiveCached(hd_dive, 2, out_dir + "/cache");
    std::vector<Eigen::Matrix3d> hd_truth(hd.gray.size(), Eigen::Matrix3d::Identity());
    for (size_t i = 1; i < hd.gray.size(); ++i)
      hd_truth[i] = sim::seabedPlaneHomography(hd.camera, hd.local_from_camera[i - 1], hd.local_from_camera[i]);
    // Every 50th pair of the HD clip: ECC runs about one pair per second there.
    const SequenceScore hd_ecc =
        peerScore(hd.gray, hd_truth, 50, [](const cv::Mat& a, const cv::Mat& b) { return eccAffine(a, b); });
    json["ecc_fps_hd"] = hd_ecc.fps;
    std::cout << "ECC affine HD: " << hd_ecc.fps << " pairs/s\n";
  }

  // ---- 2b. The camera presets: the same dive filmed in PAL, HD and 4K UHD, each registered with its registration
  // preset (config/registration/<camera>_survey.yaml, as registration_node loads it). Errors also in pixels of the
  // HD image (x 1920 / width), so that cameras compare on the ground; CPU per frame of this thread.
  if (presets) {
    const std::string duration = "duration_s=" + std::to_string(preset_frames / 25.0 - 0.01);
    for (const std::string camera : {"pal", "hd", "uhd"}) {
      const sim::DiveDescription d = sim::loadDiveDescription(config_dir + "/dives/bench_registration.yaml",
                                                              {"camera.preset=" + camera, duration});
      t0 = Clock::now();
      const sim::RenderedDive clip = sim::renderDiveCached(d, 2, out_dir + "/cache");
      std::cout << "rendered " << clip.gray.size() << " " << camera << " frames in " << msSince(t0) / 1000.0 << " s\n";
      if (clip.gray.size() < 2) continue;
      std::vector<Eigen::Matrix3d> clip_truth(clip.gray.size(), Eigen::Matrix3d::Identity());
      for (size_t i = 1; i < clip.gray.size(); ++i)
        clip_truth[i] =
            sim::seabedPlaneHomography(clip.camera, clip.local_from_camera[i - 1], clip.local_from_camera[i]);
      const video::RegistrationPreset preset =
          video::loadRegistrationPreset(config_dir + "/registration/" + camera + "_survey.yaml");
      const double to_hd = 1920.0 / clip.gray.front().cols;
      // The preset as it is (its motion model), and with the homography: the camera rolls and pitches, which only
      // the homography holds, so that one shows the registration's precision rather than the model's limit.
      for (const bool homography : {false, true}) {
        registration::RegistrationConfig config = preset.registration;
        if (homography) config.model = MotionModel::kHomography;
        SequenceRegistrar r(makeRegistrar(config), preset.sequence);
        const double cpu0 = threadCpuSeconds();
        const SequenceScore sc = evaluateSequence(r, clip.gray, clip.stamps_s, clip_truth, 2.0 / to_hd);
        const double cpu_ms = 1000.0 * (threadCpuSeconds() - cpu0) / double(clip.gray.size());
        const std::string key = "preset_" + camera + (homography ? "_homography" : "");
        json[key + "_median_px"] = sc.median_px;
        json[key + "_p95_px"] = sc.p95_px;
        json[key + "_median_hd_px"] = sc.median_px * to_hd;
        json[key + "_p95_hd_px"] = sc.p95_px * to_hd;
        json[key + "_failure_rate"] = sc.failure_rate;
        json[key + "_gross_failure_rate"] = sc.gross_failure_rate;
        json[key + "_cpu_ms_per_frame"] = cpu_ms;
        std::cout << key << " (" << clip.gray.front().cols << "x" << clip.gray.front().rows << ", "
                  << clip.gray.size() << " frames): median " << sc.median_px << " px, p95 " << sc.p95_px
                  << " px; in HD px median " << sc.median_px * to_hd << ", p95 " << sc.p95_px * to_hd << "; failed "
                  << sc.failures << ", gross " << sc.gross_failures << "; " << cpu_ms << " ms CPU per frame\n";
      }
    }
  }

  // ---- 3. Real seabed: Sparus AUV frames against SIFT + RANSAC ----
  // Undistorted with the dataset's intrinsics, as registration_node does with a camera_info.
  if (accuracy) {
    const std::vector<cv::Mat> sparus = testing_data::loadSparusFrames(shared, true);
    double sparus_max = 0.0;
    if (sparus.size() >= 2) {
      for (const std::string key : {"klt", "rmr"}) {
        if (!wanted(key)) continue;
        std::unique_ptr<FrameRegistrar> r = makeRegistrar(
            configFor(key == "klt" ? RegistrationMethod::kKlt : RegistrationMethod::kRmr, MotionModel::kHomography));
        std::vector<double> errors;
        int failed = 0;
        for (size_t i = 0; i < sparus.size(); ++i) {
          const MotionEstimate e = r->registerNext(sparus[i]);
          if (i == 0) continue;
          const SiftReference reference = siftReferenceHomography(sparus[i - 1], sparus[i]);
          if (!reference.found) continue;
          if (e.failed) {
            ++failed;
            continue;
          }
          errors.push_back(
              cornerTransferError_px(e.pixel_matrix, reference.pixel_matrix, sparus[i].cols, sparus[i].rows));
        }
        std::sort(errors.begin(), errors.end());
        const double worst = errors.empty() ? std::nan("") : errors.back();
        const double median = errors.empty() ? std::nan("") : errors[errors.size() / 2];
        sparus_max = std::max(sparus_max, worst);
        json["sparus_" + key + "_max_corner_px"] = worst;
        json["sparus_" + key + "_median_corner_px"] = median;
        json["sparus_" + key + "_failures"] = failed;
        std::cout << "sparus " << key << ": " << errors.size() << " pairs, corner difference to SIFT+RANSAC median "
                  << median << " px, max " << worst << " px, " << failed << " failed\n";
      }
      if (wanted("klt") && wanted("rmr")) json["sparus_max_corner_px"] = sparus_max;
    } else {
      std::cout << "sparus: no frames under " << shared << "/sparus_auv/frames\n";
    }
  }

  // ---- Strong relief: the wreck dive (config/dives/wreck.yaml) ----
  if (wreck) {
    std::vector<std::string> wreck_overrides;
    if (wreck_frames_limit > 0) wreck_overrides.push_back("duration_s=" + std::to_string(wreck_frames_limit / 25.0 - 0.01));
    const sim::DiveDescription wreck_dive = sim::loadDiveDescription(config_dir + "/dives/wreck.yaml", wreck_overrides);
    t0 = Clock::now();
    const sim::RenderedDive w = sim::renderDiveCached(wreck_dive, 2, out_dir + "/cache");
    std::cout << "rendered " << w.gray.size() << " PAL frames of the wreck dive in " << msSince(t0) / 1000.0 << " s\n";
    // Truth: the dominant plane's homography (the flat seabed z = 0 under the objects).
    for (const int stride : {1, 4}) {
      std::vector<cv::Mat> frames;
      std::vector<double> stamps;
      std::vector<Eigen::Isometry3d> poses;
      for (size_t i = 0; i < w.gray.size(); i += stride) {
        frames.push_back(w.gray[i]);
        stamps.push_back(w.stamps_s[i]);
        poses.push_back(w.local_from_camera[i]);
      }
      std::vector<Eigen::Matrix3d> wreck_truth(frames.size(), Eigen::Matrix3d::Identity());
      for (size_t i = 1; i < frames.size(); ++i)
        wreck_truth[i] = sim::seabedPlaneHomography(w.camera, poses[i - 1], poses[i]);
      for (const Candidate& c : {candidates[0], candidates[1]}) {
        if (!wanted(c.key)) continue;
        SequenceRegistrar r(makeRegistrar(configFor(c.method, c.model)), SequenceRegistrarConfig());
        t0 = Clock::now();
        const SequenceScore s = evaluateSequence(r, frames, stamps, wreck_truth);
        const std::string key = "wreck_" + c.key;
        json[key + "_failure_rate_s" + std::to_string(stride)] = s.failure_rate;
        if (stride == 1) {
          json[key + "_median_px"] = s.median_px;
          json[key + "_p95_px"] = s.p95_px;
          json[key + "_nees_ratio"] = s.nees_ratio;
          json[key + "_gross_failure_rate"] = s.gross_failure_rate;
          json[key + "_fps"] = 1000.0 * frames.size() / msSince(t0);
        } else {
          json[key + "_median_px_s" + std::to_string(stride)] = s.median_px;
          json[key + "_p95_px_s" + std::to_string(stride)] = s.p95_px;
        }
        std::cout << "wreck " << c.key << " stride " << stride << ": median " << s.median_px << " px, p95 " << s.p95_px
                  << " px, max " << s.max_px << ", failed " << s.failures << " of " << s.pairs.size() << ", gross "
                  << s.gross_failures << ", NEES ratio " << s.nees_ratio << "\n";
        for (const PairScore& p : s.pairs)
          if (p.failed)
            std::cout << "  failed pair " << p.index * stride - stride << "-" << p.index * stride << ": "
                      << toString(p.failure) << "\n";
      }
    }
    json["wreck_pairs"] = double(w.gray.size() - 1);
  }

  // ---- Table (of what this run measured) ----
  if (accuracy && timing && peers && methods.empty()) {
    const double ecc_fps = ecc.fps, features_fps = features.fps;
    std::cout << "\nRegistration, simulated dive of " << pal.gray.size() << " PAL frames (turbid and dark stretches); "
              << "speed on one thread, 720x576 (wall clock; per CPU second above):\n"
              << std::left << std::setw(30) << "method" << std::right << std::setw(9) << "med px" << std::setw(9)
              << "p95 px" << std::setw(9) << "fail %" << std::setw(9) << "gross %" << std::setw(9) << "fps"
              << std::setw(9) << "x ECC" << std::setw(9) << "x ORB"
              << "\n";
    auto row = [&](const std::string& name, const std::string& score_key, const std::string& fps_key) {
      const double f = fps[fps_key].wall_fps;
      printRow(name, scores[score_key], f, f / ecc_fps, f / features_fps);
    };
    row("KLT homography", "klt", "klt_homography");
    row("RMR homography", "rmr", "rmr_homography");
    row("KLT similarity", "klt_similarity", "klt");
    row("RMR similarity", "rmr_similarity", "rmr");
    row("auto (KLT, then RMR) homog.", "auto", "auto");
    printRow("KLT affine", scores["klt_affine"], 0, 0, 0);
    printRow("RMR affine", scores["rmr_affine"], 0, 0, 0);
    printRow("OpenCV ECC affine pyramid", ecc, ecc_fps, 1.0, ecc_fps / features_fps);
    printRow("ORB + estimateAffinePartial2D", features, features_fps, features_fps / ecc_fps, 1.0);
  }

  const std::string path = out_dir + "/registration.json";
  try {
    exocet_common::writeJsonFileAtomically(path, json);
  } catch (const std::exception& e) {
    std::cerr << "bench_registration: " << e.what() << "\n";
    return 1;
  }
  std::cout << "wrote " << path << "\n";
  return 0;
}
