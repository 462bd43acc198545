// bench_pose_graph: the 2-D pose graph (graph/pose_graph.h) on a simulated one-hour lawnmower survey: CPU time of
// re-solving after one new loop (windowed) as the dive grows, of full solves, peak memory, accuracy against the
// truth with and without loops, and the planted false loops' fate. Writes OUTPUT_DIR/pose_graph.json. It measures
// and prints; it never fails because the machine is slow.
#include <sys/resource.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <random>
#include <string>
#include <vector>

#include <Eigen/Dense>
#include <nlohmann/json.hpp>

#include "exocet_common/command_line.h"
#include "exocet_common/json_file.h"
#include "exocet_mosaic/graph/background_pose_graph.h"
#include "exocet_mosaic/graph/pose_graph.h"

namespace {

using namespace exocet_mosaic::graph;

constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180.0;

double processCpuSeconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_utime.tv_sec + u.ru_stime.tv_sec + 1e-6 * (u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

/// VmHWM of /proc/self/status, MB; NaN when unreadable.
double peakRssMb() {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("VmHWM:", 0) == 0) return std::stod(line.substr(6)) / 1024.0;
  return std::nan("");
}

Pose2d poseOf(double e, double n, double yaw) {
  Pose2d p;
  p.position_en_m = Eigen::Vector2d(e, n);
  p.yaw_rad = yaw;
  return p;
}

Eigen::Matrix3d diag3(double sigma_m, double sigma_rad) {
  return Eigen::Vector3d(sigma_m * sigma_m, sigma_m * sigma_m, sigma_rad * sigma_rad).asDiagonal();
}

struct LoopInput {
  int from, to;  ///< key frame indices, from < to
  RelativePose2d delta;
  Eigen::Matrix3d covariance;
  bool is_false;
};

/// The survey and its measurements.
struct Survey {
  // Models (1-sigma).
  static constexpr double kStepM = 0.2;  // 0.5 m/s at 2.5 key frames/s
  static constexpr double kKeyFramePeriodS = 0.4;
  static constexpr double kLineSpacingM = 2.0;
  static constexpr double kOdometryFraction = 0.01;  // of the distance travelled, per axis
  static constexpr double kOdometryYawRad = 0.2 * kDeg;
  static constexpr double kHeadingRad = 1.0 * kDeg;
  static constexpr double kFixM = 0.5;
  static constexpr double kFixPeriodS = 1.0;
  static constexpr double kFixOutlierRate = 0.01;  // USBL multipath: 5 to 15 m off
  static constexpr double kLoopM = 0.05, kLoopRad = 0.5 * kDeg;
  static constexpr double kFalseLoopM = 0.02, kFalseLoopRad = 0.2 * kDeg;  // confident, and 1 m wrong
  // Dead reckoning between consecutive key frames as the fusion models it (KeyFrameFeeder: 1 cm white noise at
  // both ends, 1e-3 m^2 per metre), and its start, the graph's anchor.
  static constexpr double kDeadReckoningVarianceM2 = 2 * 0.01 * 0.01 + 1e-3 * kStepM;
  static constexpr double kDeadReckoningStartM = 0.01;

  std::vector<Pose2d> truth, initial;
  std::vector<double> stamps_s, headings_rad;
  std::vector<RelativePose2d> odometry;  ///< k -> k + 1
  std::vector<Eigen::Vector2d> dead_reckoning;  ///< k -> k + 1, in k's axes
  Eigen::Vector2d dead_reckoning_start = Eigen::Vector2d::Zero();
  Eigen::Matrix3d odometry_covariance;
  std::vector<std::pair<double, Eigen::Vector2d>> fixes;
  std::vector<LoopInput> loops;     ///< true and false, in the order a live chain finds them (by `to`)
  std::vector<LoopInput> held_out;  ///< true loops kept for the re-solve measurements

  Survey(int keyframes, int lines, int true_loops, int false_loops, unsigned seed) {
    std::mt19937 rng(seed);
    std::normal_distribution<double> normal;
    std::uniform_real_distribution<double> uniform;
    const int per_line = (keyframes + lines - 1) / lines;
    const int turn = 10;  // key frames crossing to the next line
    const int along = per_line - turn;
    for (int i = 0; i < keyframes; ++i) {
      const int line = i / per_line, k = i % per_line;
      const bool east = line % 2 == 0;
      const double end_e = kStepM * (along - 1);
      if (k < along) {
        truth.push_back(poseOf(east ? kStepM * k : end_e - kStepM * k, kLineSpacingM * line, east ? 0.0 : kPi));
      } else {
        truth.push_back(
            poseOf(east ? end_e : 0.0, kLineSpacingM * (line + (k - along + 1) / double(turn + 1)), kPi / 2));
      }
      stamps_s.push_back(kKeyFramePeriodS * i);
      headings_rad.push_back(wrapAngle(truth.back().yaw_rad + kHeadingRad * normal(rng)));
    }
    const double sigma_t = kOdometryFraction * kStepM;
    odometry_covariance = diag3(sigma_t, kOdometryYawRad);
    for (int i = 0; i + 1 < keyframes; ++i) {
      RelativePose2d d = between(truth[i], truth[i + 1]);
      d.translation_m += sigma_t * Eigen::Vector2d(normal(rng), normal(rng));
      d.yaw_rad += kOdometryYawRad * normal(rng);
      odometry.push_back(d);
    }
    std::mt19937 dr_rng(seed + 1);  // its own stream: the other measurements as without it
    const double dr_sigma_m = std::sqrt(kDeadReckoningVarianceM2);
    dead_reckoning_start = truth[0].position_en_m + kDeadReckoningStartM * Eigen::Vector2d(normal(dr_rng), normal(dr_rng));
    for (int i = 0; i + 1 < keyframes; ++i)
      dead_reckoning.push_back(between(truth[i], truth[i + 1]).translation_m +
                               dr_sigma_m * Eigen::Vector2d(normal(dr_rng), normal(dr_rng)));
    // The chain's estimate: odometry steps turned by the measured heading (compass-aided dead reckoning).
    initial.push_back(truth[0]);
    for (int i = 1; i < keyframes; ++i) {
      Pose2d aided = initial.back();
      aided.yaw_rad = headings_rad[i - 1];
      Pose2d next = compose(aided, odometry[i - 1]);
      next.yaw_rad = headings_rad[i];
      initial.push_back(next);
    }
    for (double t = 0.5 * kFixPeriodS; t < stamps_s.back(); t += kFixPeriodS) {
      const int a = static_cast<int>(t / kKeyFramePeriodS);
      const double w = (t - stamps_s[a]) / kKeyFramePeriodS;
      Eigen::Vector2d p = (1 - w) * truth[a].position_en_m + w * truth[a + 1].position_en_m;
      p += kFixM * Eigen::Vector2d(normal(rng), normal(rng));
      if (uniform(rng) < kFixOutlierRate) {
        const double angle = 2 * kPi * uniform(rng);
        p += (5.0 + 10.0 * uniform(rng)) * Eigen::Vector2d(std::cos(angle), std::sin(angle));
      }
      fixes.push_back({t, p});
    }
    // Loops between adjacent lines, over the same spot (partner key frame at the same east).
    const auto make_loop = [&](bool is_false) {
      const int line = std::uniform_int_distribution<int>(0, std::max(0, (keyframes - 1) / per_line - 1))(rng);
      const int k = std::uniform_int_distribution<int>(0, along - 1)(rng);
      const int from = line * per_line + k, to = (line + 1) * per_line + (along - 1 - k);
      LoopInput loop{from, std::min(to, keyframes - 1), between(truth[from], truth[std::min(to, keyframes - 1)]),
                     Eigen::Matrix3d::Identity(), is_false};
      if (is_false) {
        const double angle = 2 * kPi * uniform(rng);
        loop.delta.translation_m += Eigen::Vector2d(std::cos(angle), std::sin(angle));
        loop.covariance = diag3(kFalseLoopM, kFalseLoopRad);
      } else {
        loop.delta.translation_m += kLoopM * Eigen::Vector2d(normal(rng), normal(rng));
        loop.delta.yaw_rad += kLoopRad * normal(rng);
        loop.covariance = diag3(kLoopM, kLoopRad);
      }
      return loop;
    };
    for (int l = 0; l < true_loops; ++l) loops.push_back(make_loop(false));
    for (int l = 0; l < false_loops; ++l) loops.push_back(make_loop(true));
    std::stable_sort(loops.begin(), loops.end(), [](const LoopInput& a, const LoopInput& b) { return a.to < b.to; });
    // Held-out loops: from the line before the last one of each prefix length, to the last line.
    for (const int n : {1000, 3000, keyframes}) {
      const int last = std::min(n, keyframes) - 1, line = last / per_line;
      if (line < 1) continue;
      const int k = std::min(along / 2, last % per_line);
      const int to = line * per_line + k, from = (line - 1) * per_line + (along - 1 - k);
      LoopInput loop{from, to, between(truth[from], truth[to]), diag3(kLoopM, kLoopRad), false};
      loop.delta.translation_m += kLoopM * Eigen::Vector2d(normal(rng), normal(rng));
      held_out.push_back(loop);
      const int to2 = std::max(to - 30, line * per_line),
                from2 = (line - 1) * per_line + (along - 1 - (to2 - line * per_line));
      LoopInput second{from2, to2, between(truth[from2], truth[to2]), diag3(kLoopM, kLoopRad), false};
      held_out.push_back(second);
    }
  }

  /// A graph of the first `n` key frames and every measurement among them, loops or not.
  void fill(PoseGraph* g, int n, bool with_loops, std::vector<int>* loop_of_input = nullptr) const {
    for (int i = 0; i < n; ++i) {
      g->addKeyFrame(i, stamps_s[i], initial[i]);
      if (i > 0) g->addOdometry(i - 1, i, odometry[i - 1], odometry_covariance);
      if (i > 0)
        g->addRelativePosition(i - 1, i, dead_reckoning[i - 1], Eigen::Matrix2d::Identity() * kDeadReckoningVarianceM2);
      g->addHeading(i, headings_rad[i], kHeadingRad);
    }
    g->addPositionFix(stamps_s[0], dead_reckoning_start,
                      Eigen::Matrix2d::Identity() * kDeadReckoningStartM * kDeadReckoningStartM, false);
    const Eigen::Matrix2d fix_covariance = Eigen::Matrix2d::Identity() * kFixM * kFixM;
    for (const auto& [t, p] : fixes)
      if (t < stamps_s[n - 1]) g->addPositionFix(t, p, fix_covariance);
    if (!with_loops) return;
    for (const LoopInput& l : loops) {
      if (l.to >= n) {
        if (loop_of_input) loop_of_input->push_back(-1);
        continue;
      }
      const int index = g->addLoop(l.from, l.to, l.delta, l.covariance);
      if (loop_of_input) loop_of_input->push_back(index);
    }
  }

  double rmsError(const PoseGraph& g, int n) const {
    double sum = 0.0;
    for (int i = 0; i < n; ++i) sum += (g.pose(i).position_en_m - truth[i].position_en_m).squaredNorm();
    return std::sqrt(sum / n);
  }
};

struct GrowthRow {
  int keyframes = 0;
  int loops = 0;
  double build_cpu_s = 0.0;
  double full_solve_cpu_s = 0.0;
  int full_solve_iterations = 0;
  double resolve_cpu_s = 0.0;
  int resolve_keyframes_optimized = 0;
  int resolve_iterations = 0;
  double full_resolve_cpu_s = 0.0;
  double marginals_cpu_s = 0.0;  ///< every key frame's position marginals after the full re-solve
};

}  // namespace

int main(int argc, char** argv) {
  exocet_common::BenchmarkPaths paths;
  int keyframes = 9000, lines = 30, true_loops = 500, false_loops = 20;
  unsigned seed = 1;
  CLI::App app(
      "bench_pose_graph: the 2-D pose graph on a simulated one-hour lawnmower survey (key frames at 2.5 Hz, odometry\n"
      "1 % of distance and 0.2 deg per key frame, USBL every 1 s at 0.5 m with 1 % outliers, heading 1 deg per key\n"
      "frame, true loops between adjacent lines and planted false loops 1 m off). Writes OUTPUT_DIR/pose_graph.json.",
      "bench_pose_graph");
  exocet_common::addBenchmarkPathOptions(app, &paths, false);  // the survey is simulated
  app.add_option("--keyframes", keyframes, "key frames of the dive")
      ->check(exocet_common::atLeast(100))
      ->capture_default_str();
  app.add_option("--lines", lines, "survey lines")->check(exocet_common::atLeast(2))->capture_default_str();
  app.add_option("--true-loops", true_loops, "true loop closures")
      ->check(exocet_common::atLeast(0))
      ->capture_default_str();
  app.add_option("--false-loops", false_loops, "planted false loop closures")
      ->check(exocet_common::atLeast(0))
      ->capture_default_str();
  app.add_option("--seed", seed, "random seed")->capture_default_str();
  if (const auto exit_status = exocet_common::parseCommandLine(app, argc, argv)) return *exit_status;
  std::error_code ignored;
  std::filesystem::create_directories(paths.output_dir, ignored);
  std::cout << std::unitbuf;

  const Survey survey(keyframes, lines, true_loops, false_loops, seed);
  nlohmann::json json;
  PoseGraphConfig config;  // the defaults: windowed solve() after the first full one

  // ---- Growth: full solve of the first N key frames, then one new loop re-solved in its window, then a full
  // re-solve after another one. ----
  std::vector<int> sizes;
  for (const int n : {1000, 3000, keyframes})
    if (n <= keyframes && (sizes.empty() || n > sizes.back())) sizes.push_back(n);
  std::vector<GrowthRow> rows;
  double rms_with_loops = 0.0;
  std::vector<double> sigma_radial_m;
  double within_1sigma = -1.0, mahalanobis_median = -1.0, sigma_radial_median_m = -1.0;
  double every_marginal_cpu_s = 0.0, interpolation_error_max = 0.0;
  const int marginals_cap = BackgroundPoseGraphConfig().marginals_max_key_frames;
  int false_accepted = 0, true_accepted = 0, true_in_graph = 0, false_in_graph = 0, loops_in_graph = 0;
  for (const int n : sizes) {
    GrowthRow row;
    row.keyframes = n;
    PoseGraph g(config);
    std::vector<int> loop_of_input;
    double t0 = processCpuSeconds();
    survey.fill(&g, n, true, &loop_of_input);
    row.build_cpu_s = processCpuSeconds() - t0;
    row.loops = static_cast<int>(g.numLoops());
    const SolveReport full = g.solveFull();
    row.full_solve_cpu_s = full.cpu_s;
    row.full_solve_iterations = full.iterations;
    const LoopInput* one = nullptr;
    const LoopInput* two = nullptr;
    for (size_t h = 0; h + 1 < survey.held_out.size(); h += 2)
      if (survey.held_out[h].to < n && survey.held_out[h + 1].to < n) {
        one = &survey.held_out[h];
        two = &survey.held_out[h + 1];
      }
    if (one) {
      g.addLoop(one->from, one->to, one->delta, one->covariance);
      const SolveReport resolve = g.solve();
      row.resolve_cpu_s = resolve.cpu_s;
      row.resolve_keyframes_optimized = resolve.keyframes_optimized;
      row.resolve_iterations = resolve.iterations;
      g.addLoop(two->from, two->to, two->delta, two->covariance);
      row.full_resolve_cpu_s = g.solveFull().cpu_s;
    }
    // The marginals as the node computes them (BackgroundPoseGraph's cap on the key frames computed).
    t0 = processCpuSeconds();
    const std::vector<Eigen::Matrix2d> capped = g.positionCovariances(marginals_cap);
    row.marginals_cpu_s = processCpuSeconds() - t0;
    rows.push_back(row);
    if (n == sizes.back()) {
      rms_with_loops = survey.rmsError(g, n);
      t0 = processCpuSeconds();
      const std::vector<Eigen::Matrix2d> marginals = g.positionCovariances();  // every key frame
      every_marginal_cpu_s = processCpuSeconds() - t0;
      for (size_t i = 0; i < marginals.size() && capped.size() == marginals.size(); ++i) {
        const double exact = std::sqrt(marginals[i].trace());
        interpolation_error_max = std::max(interpolation_error_max, std::abs(std::sqrt(capped[i].trace()) - exact) / exact);
      }
      // The graph's own 1-sigma against its true error (simulated factors: the truth is known).
      std::vector<double> mahalanobis;
      for (int i = 0; i < n && marginals.size() == static_cast<size_t>(n); ++i) {
        const Eigen::Vector2d e = g.pose(i).position_en_m - survey.truth[i].position_en_m;
        mahalanobis.push_back(std::sqrt(e.dot(marginals[i].ldlt().solve(e))));
        sigma_radial_m.push_back(std::sqrt(marginals[i].trace()));
      }
      if (!mahalanobis.empty()) {
        within_1sigma = std::count_if(mahalanobis.begin(), mahalanobis.end(), [](double d) { return d <= 1.0; }) /
                        static_cast<double>(mahalanobis.size());
        std::nth_element(mahalanobis.begin(), mahalanobis.begin() + mahalanobis.size() / 2, mahalanobis.end());
        mahalanobis_median = mahalanobis[mahalanobis.size() / 2];
        std::nth_element(sigma_radial_m.begin(), sigma_radial_m.begin() + sigma_radial_m.size() / 2,
                         sigma_radial_m.end());
        sigma_radial_median_m = sigma_radial_m[sigma_radial_m.size() / 2];
      }
      for (size_t i = 0; i < survey.loops.size(); ++i) {
        if (loop_of_input[i] < 0) continue;
        const bool accepted = g.loopAccepted(loop_of_input[i]);
        ++loops_in_graph;
        if (survey.loops[i].is_false) {
          ++false_in_graph;
          false_accepted += accepted;
        } else {
          ++true_in_graph;
          true_accepted += accepted;
        }
      }
    }
  }
  double rms_without_loops = 0.0, rms_initial = 0.0;
  {
    PoseGraph g(config);
    survey.fill(&g, keyframes, false);
    for (int i = 0; i < keyframes; ++i)
      rms_initial += (survey.initial[i].position_en_m - survey.truth[i].position_en_m).squaredNorm();
    rms_initial = std::sqrt(rms_initial / keyframes);
    g.solveFull();
    rms_without_loops = survey.rmsError(g, keyframes);
  }
  const double peak_mb = peakRssMb();

  std::cout << "\nPose graph, simulated survey: " << keyframes << " key frames on " << lines << " lines, "
            << survey.fixes.size() << " USBL fixes, " << loops_in_graph << " loops (" << true_in_graph << " true, "
            << false_in_graph << " false, 1 m off at 2 cm), plus the loops of the re-solves\n";
  std::cout << std::setw(10) << "keyframes" << std::setw(8) << "loops" << std::setw(12) << "build s" << std::setw(14)
            << "full solve s" << std::setw(8) << "iters" << std::setw(12) << "resolve s" << std::setw(14)
            << "window (kf)" << std::setw(8) << "iters" << std::setw(16) << "full resolve s"
            << std::setw(14) << "marginals s" << "   (CPU seconds)\n";
  nlohmann::json growth = nlohmann::json::array();
  for (const GrowthRow& r : rows) {
    std::cout << std::fixed << std::setw(10) << r.keyframes << std::setw(8) << r.loops << std::setprecision(3)
              << std::setw(12) << r.build_cpu_s << std::setw(14) << r.full_solve_cpu_s << std::setw(8)
              << r.full_solve_iterations << std::setw(12) << r.resolve_cpu_s << std::setw(14)
              << r.resolve_keyframes_optimized << std::setw(8) << r.resolve_iterations << std::setw(16)
              << r.full_resolve_cpu_s << std::setw(14) << r.marginals_cpu_s << "\n";
    growth.push_back({{"keyframes", r.keyframes},
                      {"loops", r.loops},
                      {"full_solve_cpu_s", r.full_solve_cpu_s},
                      {"resolve_cpu_s", r.resolve_cpu_s},
                      {"resolve_keyframes_optimized", r.resolve_keyframes_optimized},
                      {"full_resolve_cpu_s", r.full_resolve_cpu_s},
                      {"marginals_cpu_s", r.marginals_cpu_s}});
  }
  const GrowthRow& last = rows.back();
  std::cout << std::setprecision(3) << "position RMS error vs truth: initial (compass-aided dead reckoning) "
            << rms_initial << " m, graph without loops " << rms_without_loops << " m, with loops " << rms_with_loops
            << " m\n"
            << "loops accepted: true " << true_accepted << "/" << true_in_graph << ", false " << false_accepted << "/"
            << false_in_graph << "\n"
            << "targets: resolve " << last.resolve_cpu_s << " s CPU (<= 1 s), peak RSS " << std::setprecision(1)
            << peak_mb << " MB (< 500 MB), false loops accepted " << false_accepted << " (0)\n"
 << "the graph's own 1-sigma: " << marginals_cap << " key frames' marginals computed and the others interpolated "
            << std::setprecision(3) << last.marginals_cpu_s << " s CPU (every key frame's " << every_marginal_cpu_s
            << " s; radial 1-sigma interpolated within " << 100.0 * interpolation_error_max
            << " %); radial median " << sigma_radial_median_m << " m; key frames within it (Mahalanobis <= 1) "
            << within_1sigma << " (0.39 if calibrated), Mahalanobis median " << mahalanobis_median << " (1.18)\n";

  json["keyframes"] = keyframes;
  json["marginals_cpu_s"] = last.marginals_cpu_s;
  json["marginals_key_frames_computed"] = marginals_cap;
  json["marginals_every_key_frame_cpu_s"] = every_marginal_cpu_s;
  json["marginals_interpolation_error_max"] = interpolation_error_max;
  json["marginals_sigma_radial_median_m"] = sigma_radial_median_m;
  // For errors drawn from the graph's own covariance: 0.39 and 1.18.
  json["marginals_within_1sigma_fraction"] = within_1sigma;
  json["marginals_mahalanobis_median"] = mahalanobis_median;
  json["loops"] = loops_in_graph;
  json["resolve_cpu_s"] = last.resolve_cpu_s;
  json["resolve_keyframes_optimized"] = last.resolve_keyframes_optimized;
  json["peak_rss_mb"] = peak_mb;
  json["false_loops_planted"] = false_in_graph;
  json["false_loops_accepted"] = false_accepted;
  json["true_loops"] = true_in_graph;
  json["true_loops_accepted"] = true_accepted;
  json["full_solve_cpu_s"] = last.full_solve_cpu_s;
  json["full_resolve_cpu_s"] = last.full_resolve_cpu_s;
  json["build_cpu_s"] = last.build_cpu_s;
  json["position_fixes"] = survey.fixes.size();
  json["rms_error_initial_m"] = rms_initial;
  json["rms_error_without_loops_m"] = rms_without_loops;
  json["rms_error_with_loops_m"] = rms_with_loops;
  json["growth"] = growth;
  const std::string path = paths.output_dir + "/pose_graph.json";
  try {
    exocet_common::writeJsonFileAtomically(path, json);
  } catch (const std::exception& e) {
    std::cerr << "bench_pose_graph: " << e.what() << "\n";
    return 1;
  }
  std::cout << "wrote " << path << "\n";
  return 0;
}
