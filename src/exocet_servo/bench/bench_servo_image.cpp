// Benchmark of the image-level intrinsics-free servo (2D4 report 2.3-2.4): a rendered, textured vent on a seabed; the
// right camera takes the reference image, the left camera (other intrinsics) starts 5-10 cm and 5-10 deg away and
// servoes with SIFT matching, KLT tracking, rendered depths and the invariant law. Then the control rate on 640x480
// images, one core (cv::setNumThreads(1)): tracking + invariant features + law; the report's circular acquisition
// through the arm (its feasibility predicted, the vent placed by a search in the arm's workspace, then run) and
// free-flying (20 servoings = a full circle about the vent's axis, after a check that the renderer shows the vent from
// all sides). Writes servo_image.json.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <random>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "exocet_common/json_file.h"
#include "exocet_common/command_line.h"
#include "exocet_servo/control/image_servo_controller.h"
#include "exocet_servo/control/twist_limit.h"
#include "exocet_servo/sim/arm_rig_simulator.h"
#include "exocet_servo/sim/image_servo_loop.h"
#include "exocet_servo/sim/point_scene.h"
#include "exocet_servo/sim/vent_renderer.h"
#include "exocet_servo/trajectory/acquisition_feasibility.h"
#include "exocet_servo/trajectory/se3.h"

namespace {

using namespace exocet_servo;
using Clock = std::chrono::steady_clock;

/// Start poses 5-10 cm and 5-10 deg from the reference, in random directions (fixed seed).
std::vector<Eigen::Isometry3d> startPoses(const Eigen::Isometry3d& reference, int count) {
  std::vector<Eigen::Isometry3d> out;
  std::mt19937 rng(23);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::normal_distribution<double> g(0.0, 1.0);
  for (int i = 0; i < count; ++i) {
    const Eigen::Vector3d t_dir = Eigen::Vector3d(g(rng), g(rng), g(rng)).normalized();
    const Eigen::Vector3d r_dir = Eigen::Vector3d(g(rng), g(rng), g(rng)).normalized();
    const double t = 0.05 + 0.05 * i / std::max(1, count - 1), r = (5.0 + 5.0 * u(rng)) * M_PI / 180.0;
    trajectory::Twist d;
    d << t * t_dir, r * r_dir;
    out.push_back(reference * trajectory::expSe3(d));
  }
  return out;
}

/// Rotation of angle_rad about the world vertical through `centre_w` (the vent's axis), as a world transform.
Eigen::Isometry3d aboutVertical(const Eigen::Vector3d& centre_w, double angle_rad) {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.linear() = Eigen::AngleAxisd(angle_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  t.translation() = centre_w - t.linear() * centre_w;
  return t;
}

/// What one view of the vent shows, sampled on a grid of pixels (every `step_px`): the fraction of samples on the
/// chimney (side and top), on the seabed and on the water, and the chimney's texture contrast (mean gradient magnitude
/// of the rendered image on chimney samples, gray levels per pixel).
struct ViewContent {
  double chimney_fraction = 0.0, seabed_fraction = 0.0, water_fraction = 0.0, chimney_gradient = 0.0;
};

ViewContent viewContent(const sim::VentRenderer& renderer, const sim::PinholeCamera& camera,
                        const Eigen::Isometry3d& world_T_camera, const cv::Mat& image, int step_px = 8) {
  ViewContent c;
  int n = 0, chimney = 0, seabed = 0;
  double gradient_sum = 0.0;
  for (int v = step_px / 2; v < camera.height_px - 1; v += step_px) {
    for (int u = step_px / 2; u < camera.width_px - 1; u += step_px) {
      sim::SurfaceKind kind = sim::SurfaceKind::kNone;
      renderer.depthAt(camera, world_T_camera, Eigen::Vector2d(u, v), &kind);
      ++n;
      if (kind == sim::SurfaceKind::kSeabed) ++seabed;
      if (kind != sim::SurfaceKind::kChimney && kind != sim::SurfaceKind::kTop) continue;
      ++chimney;
      const double gx = image.at<uchar>(v, u + 1) - image.at<uchar>(v, u - 1);
      const double gy = image.at<uchar>(v + 1, u) - image.at<uchar>(v - 1, u);
      gradient_sum += 0.5 * std::hypot(gx, gy);
    }
  }
  c.chimney_fraction = static_cast<double>(chimney) / n;
  c.seabed_fraction = static_cast<double>(seabed) / n;
  c.water_fraction = 1.0 - c.chimney_fraction - c.seabed_fraction;
  c.chimney_gradient = chimney > 0 ? gradient_sum / chimney : 0.0;
  return c;
}

/// One image-level repeated servoing through the arm (the report's circular acquisition): each servoing brings the
/// left camera to where the right one took the reference image, so the poses follow left_0 (left_T_right)^k; the
/// drift is how far the simulated poses end from that prediction.
struct ArmCircleRun {
  std::vector<double> step_mm, drift_mm, drift_deg, min_sigma;  ///< per completed servoing
  std::vector<int> images_per;
  int images = 0;
  double min_sigma_all = INFINITY;  ///< smallest singular value of the Jacobian met by the resolved rate
  std::string status = "converged";
  double seconds = 0.0;
};

/// One servoing's stop: |e| below convergence_threshold, or max_images images.
struct ArmServoStop {
  double convergence_threshold = 3e-4;
  int max_images = 200;
};

ArmCircleRun runArmCircle(const sim::ArmRigConfig& rig, int servoings, const ArmServoStop& stop) {
  const auto t0 = Clock::now();
  ArmCircleRun run;
  sim::ArmRigSimulator arm(rig);  // supersampling 2, as the node's simulator
  control::ImageServoConfig cc;
  cc.servo.gain = control::AdaptiveGain{2.0, 1.0, 4.0};  // per second at 4 Hz: the node's defaults
  cc.matcher.ratio = 0.6;
  cc.servo.convergence_threshold = stop.convergence_threshold;
  const double dt = 0.25;
  Eigen::Isometry3d predicted = arm.worldFromLeft();
  for (int k = 0; k < servoings; ++k) {
    const sim::StereoViews start = arm.render();
    const Eigen::Isometry3d target = arm.worldFromRight();
    predicted = predicted * arm.leftFromRight();
    control::ImageServoController controller(cc, rig.right_camera.k, rig.left_camera.k, rig.left_camera.width_px,
                                             rig.left_camera.height_px);
    const auto lookup = [&cc](const sim::RenderedView& view) {
      return [&view, &cc](const Eigen::Vector2d& px) {
        double d = 0.0;
        return view.smoothDepthAt(px, cc.depth_check_radius_px, cc.depth_max_relative_step, &d) ? d : NAN;
      };
    };
    controller.setReference(start.right.image, lookup(start.right));
    control::ImageStep step;
    arm::ResolvedRate last_rate;
    double step_min_sigma = INFINITY;
    int images = 0;
    for (int it = 0; it < stop.max_images; ++it) {
      const sim::StereoViews views = arm.render();
      step = controller.step(views.left.image, lookup(views.left));
      ++images;
      if (step.status != control::ImageStepStatus::kRunning) break;
      last_rate = arm.command(control::limitTwist(step.velocity, 0.3, 1.0), dt);
      step_min_sigma = std::min(step_min_sigma, last_rate.min_singular_value);
    }
    run.images += images;
    run.min_sigma_all = std::min(run.min_sigma_all, step_min_sigma);
    if (step.status != control::ImageStepStatus::kConverged) {
      const sim::PoseError e = sim::poseError(arm.worldFromLeft(), target);
      char text[200];
      std::snprintf(text, sizeof(text), " (|e| %.5f, %d points, %.2f mm / %.3f deg from the target)", step.error_norm,
                    step.points, e.position_mm, e.rotation_deg);
      run.status = (step.status == control::ImageStepStatus::kRunning
                        ? "not converged in " + std::to_string(stop.max_images) + " images"
                        : control::toString(step.status)) +
                   " at servoing " + std::to_string(k + 1) + ": " + step.message + text +
                   "; arm: " + arm::toString(last_rate.status) + " " + last_rate.message;
      break;
    }
    run.step_mm.push_back(sim::poseError(arm.worldFromLeft(), target).position_mm);
    const sim::PoseError drift = sim::poseError(arm.worldFromLeft(), predicted);
    run.drift_mm.push_back(drift.position_mm);
    run.drift_deg.push_back(drift.rotation_deg);
    run.min_sigma.push_back(step_min_sigma);
    run.images_per.push_back(images);
  }
  run.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  return run;
}

void printArmCircle(const ArmCircleRun& run) {
  for (size_t k = 0; k < run.step_mm.size(); ++k) {
    printf(
        "servoing %zu: %.3f mm from the right camera's pose; drift from the predicted circle %.3f mm %.4f deg; %d "
        "images; arm's smallest singular value %.3f\n",
        k + 1, run.step_mm[k], run.drift_mm[k], run.drift_deg[k], run.images_per[k], run.min_sigma[k]);
  }
  printf("%s, %d images in all, smallest singular value met %.4f, %.1f s\n", run.status.c_str(), run.images,
         run.min_sigma_all, run.seconds);
}

/// The arm's circle: feasibility predicted at the default start, placement search, both circles run at image level.
struct ArmSection {
  static constexpr int kQuarterServoings = 5;
  trajectory::FeasibilityReport default_check, placed_check;
  trajectory::PlacementResult placement;
  double search_s = 0.0;
  int max_feasible_any_placement = 0;
  ArmCircleRun default_run, run;
};

ArmSection armSection() {
  // ---- Repeated servoing through the arm at image level: the report's circular acquisition ----
  // Placement first (2D4: the arm's simulation tells which trajectories fit its workspace): the feasibility check
  // predicts how many servoings the arm can follow from the default start (the vent at 1.3 m, the rig's screw axis
  // 1.65 m out: the circle runs away from the arm), then the placement search puts the vent on the rig's screw axis
  // where a quarter circle (5 x 18 deg) keeps the arm best conditioned; both circles are then run at image level.
  ArmSection out;
  const int quarter_servoings = ArmSection::kQuarterServoings, long_check_servoings = 20;
  sim::ArmRigConfig default_rig;
  const arm::ArmModel arm_model(default_rig.arm);
  const Eigen::Isometry3d rig_transform = default_rig.rig.leftFromRight();
  out.default_check = trajectory::checkFeasibility(
      arm_model, default_rig.flange_T_left,
      trajectory::repeatedServoingPoses(arm_model.forward(default_rig.q_initial) * default_rig.flange_T_left,
                                        rig_transform, long_check_servoings),
      default_rig.q_initial);
  const auto t_search = Clock::now();
  trajectory::PlacementSearchConfig search;
  search.servoings = quarter_servoings;
  out.placement =
      trajectory::searchPlacement(arm_model, default_rig.flange_T_left, rig_transform, default_rig.q_initial, search);
  out.search_s = std::chrono::duration<double>(Clock::now() - t_search).count();
  // More than a quarter circle: the longest circle any grid placement allows.
  out.max_feasible_any_placement = out.placement.found ? quarter_servoings : 0;
  for (int n = quarter_servoings + 1; out.placement.found && n <= 2 * quarter_servoings; ++n) {
    trajectory::PlacementSearchConfig more = search;
    more.servoings = n;
    if (!trajectory::searchPlacement(arm_model, default_rig.flange_T_left, rig_transform, default_rig.q_initial, more)
             .found) {
      break;
    }
    out.max_feasible_any_placement = n;
  }
  if (out.placement.found) {
    out.placed_check = trajectory::checkFeasibility(
        arm_model, default_rig.flange_T_left,
        trajectory::repeatedServoingPoses(out.placement.base_T_left_start, rig_transform, long_check_servoings),
        out.placement.q_start);
  }
  printf(
      "\n== Feasibility of the repeated servoing through the arm (IK along the screw path, 10 samples per servoing, "
      "smallest singular value >= %.2f, joint margin >= %.2f rad)\n",
      search.feasibility.min_sigma, search.feasibility.min_joint_margin_rad);
  printf(
      "default start (vent at (%.2f, %.2f, %.2f) m): %d feasible servoings predicted, worst smallest singular value "
      "%.4f before: %s\n",
      default_rig.scene.base_m.x(), default_rig.scene.base_m.y(), default_rig.scene.base_m.z(),
      out.default_check.feasible_steps, out.default_check.worst_sigma_min, out.default_check.reason.c_str());
  printf("placement search (%d servoings) in %.1f s: %s\n", quarter_servoings, out.search_s,
         out.placement.message.c_str());
  printf(
      "from that placement: %d feasible servoings predicted (of %d checked)%s%s; longest circle of any grid "
      "placement: %d servoings\n",
      out.placed_check.feasible_steps, long_check_servoings,
      out.placed_check.feasible ? "" : ", then: ", out.placed_check.reason.c_str(), out.max_feasible_any_placement);

  // Default start, as before: 3 servoings.
  out.default_run = runArmCircle(default_rig, 3, ArmServoStop{});
  printf(
      "\n== Repeated servoing through the arm, default start (image level, 0.3 m / 18 deg rig, node's gains at 4 Hz)"
      "\n");
  printArmCircle(out.default_run);
  // Searched placement: the vent where the search put it, the arm at the start pose's IK solution; the quarter circle,
  // then on until the servo fails (up to two servoings beyond the prediction).
  int run_servoings = 0;
  if (out.placement.found) {
    sim::ArmRigConfig placed_rig = default_rig;
    placed_rig.scene.base_m = out.placement.axis_base_m;
    placed_rig.q_initial = out.placement.q_start;
    run_servoings = std::max(quarter_servoings, out.placed_check.feasible_steps) + 2;
    // At the searched placement the camera is 0.96 m from the vent (0.6 m at the default start): the vent fills less
    // of the image (40-85 points) and the re-anchored points' jitter keeps |e| at 1e-3..5e-3 while the pose is already
    // 0.2-4 mm from its target (measured), so |e| < 3e-4 is never met there; 2.5e-3 and 120 images. The drift from
    // the predicted circle measures what the looser stop costs.
    out.run = runArmCircle(placed_rig, run_servoings, ArmServoStop{2.5e-3, 120});
    printf(
        "\n== Repeated servoing through the arm, searched placement: vent at (%.2f, %.2f, %.2f) m, start azimuth "
        "%.0f deg, up to %d servoings (%d predicted feasible)\n",
        out.placement.axis_base_m.x(), out.placement.axis_base_m.y(), out.placement.axis_base_m.z(),
        out.placement.start_azimuth_rad * 180.0 / M_PI, run_servoings, out.placed_check.feasible_steps);
    printArmCircle(out.run);
  } else {
    out.run.status = "no placement found: " + out.placement.message;
  }
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  exocet_common::BenchmarkPaths paths;
  CLI::App app(
      "bench_servo_image: the image-level intrinsics-free servo on a rendered vent (SIFT, KLT, rendered\n"
      "depths), its control rate on one core, and the circular acquisition through the arm and free-flying.\n"
      "Writes OUTPUT_DIR/servo_image.json and fills the image-level figures of OUTPUT_DIR/servo.json.",
      "bench_servo_image");
  exocet_common::addBenchmarkPathOptions(app, &paths, false);
  if (const auto exit_status = exocet_common::parseCommandLine(app, argc, argv)) return *exit_status;
  const std::string& output_dir = paths.output_dir;
  cv::setNumThreads(1);  // the control rate is measured on one core; rendering then also runs on one

  const auto t_scene = Clock::now();
  const sim::VentRenderer renderer{sim::VentSceneConfig()};
  sim::ImageServoSetup setup;
  setup.controlled_camera.k = sim::intrinsics(800.0, 812.0, 322.0, 236.0);      // left
  setup.reference_camera.k = sim::intrinsics(905.0, 880.0, 301.0, 257.0, 1.5);  // right
  setup.world_T_reference = sim::lookAt(Eigen::Vector3d(1.0, 0.0, 0.55), Eigen::Vector3d(0.0, 0.0, 0.12));
  setup.k_estimate_reference = setup.reference_camera.k;
  setup.k_estimate_controlled = setup.controlled_camera.k;
  printf("scene (textures) built in %.2f s\n", std::chrono::duration<double>(Clock::now() - t_scene).count());

  const sim::ImageServoConfig config;  // defaults: |e| < 3e-4, 80 iterations, adaptive gain 0.3 -> 0.7, 300 points

  const auto starts = startPoses(setup.world_T_reference, 4);
  printf("\n== Image servo loop: left camera (K_l) to the right camera's (K_r) reference pose, 640x480 rendered\n");
  printf("%5s %14s %14s %16s %7s %8s %9s %10s %s\n", "start", "initial", "final pos", "final rot", "iters", "remat",
         "points", "cpu ms", "status");
  double pos_sum = 0, rot_sum = 0, pos_max = 0, rot_max = 0, iter_sum = 0;
  int converged = 0;
  std::vector<sim::ImageServoResult> results;
  for (size_t s = 0; s < starts.size(); ++s) {
    setup.world_T_start = starts[s];
    const sim::ImageServoResult r = sim::runImageServo(renderer, setup, config);
    results.push_back(r);
    printf("%5zu %6.1fmm %5.1fd %12.3fmm %14.4fdeg %7d %8d %9d %10.2f %s%s\n", s, r.initial_error.position_mm,
           r.initial_error.rotation_deg, r.final_error.position_mm, r.final_error.rotation_deg, r.iterations,
           r.rematches, r.initial_matches, 1e3 * r.mean_control_cpu_time_s, sim::toString(r.status).c_str(),
           r.status == sim::ImageServoStatus::kConverged ? "" : (" (" + r.message + ")").c_str());
    pos_sum += r.final_error.position_mm;
    rot_sum += r.final_error.rotation_deg;
    pos_max = std::max(pos_max, r.final_error.position_mm);
    rot_max = std::max(rot_max, r.final_error.rotation_deg);
    iter_sum += r.iterations;
    converged += r.status == sim::ImageServoStatus::kConverged;
  }
  const double n = static_cast<double>(starts.size());
  printf("mean final error %.3f mm %.4f deg (max %.3f mm %.4f deg), %.1f iterations, %d of %zu converged\n",
         pos_sum / n, rot_sum / n, pos_max, rot_max, iter_sum / n, converged, starts.size());

  // Without re-anchoring the points on the reference image: the SIFT positions of the two images (and the KLT drift)
  // set the final error.
  sim::ImageServoConfig no_anchor = config;
  no_anchor.anchor_below_error = 0.0;
  double pos_na = 0, rot_na = 0, iter_na = 0;
  int converged_na = 0;
  for (size_t s = 0; s < starts.size(); ++s) {
    setup.world_T_start = starts[s];
    const sim::ImageServoResult r = sim::runImageServo(renderer, setup, no_anchor);
    pos_na += r.final_error.position_mm;
    rot_na += r.final_error.rotation_deg;
    iter_na += r.iterations;
    converged_na += r.status == sim::ImageServoStatus::kConverged;
  }
  printf(
      "without re-anchoring on the reference (SIFT + KLT only): mean final error %.3f mm %.4f deg, %.1f iterations, "
      "%d of %zu converged\n",
      pos_na / n, rot_na / n, iter_na / n, converged_na, starts.size());

  // --- Control rate: tracking + invariant features + law on 640x480 images along a servoing, one core. ---
  double control_sum = 0.0, control_max = 0.0, match_sum = 0.0, cpu_sum = 0.0, cpu_max = 0.0;
  int control_n = 0, match_n = 0, points_sum = 0;
  for (const auto& r : results) {
    for (const auto& it : r.history) {
      if (it.rematched) {  // no tracking on that image (SIFT instead, timed apart): not a control step to average
        match_sum += it.match_time_s;
        ++match_n;
        continue;
      }
      control_sum += it.control_time_s;
      cpu_sum += it.control_cpu_time_s;
      cpu_max = std::max(cpu_max, it.control_cpu_time_s);
      control_max = std::max(control_max, it.control_time_s);
      points_sum += it.points;
      ++control_n;
    }
  }
  const double control_mean = control_n > 0 ? control_sum / control_n : NAN;
  const double cpu_mean = control_n > 0 ? cpu_sum / control_n : NAN;
  // The rate is the thread's CPU time: the machine may be shared, and wall time then measures the other processes.
  const double rate_hz = 1.0 / cpu_mean, wall_rate_hz = 1.0 / control_mean;
  double load[3] = {NAN, NAN, NAN};
  std::ifstream("/proc/loadavg") >> load[0] >> load[1] >> load[2];
  printf("\n== Control step on one core (KLT forward-backward + invariant features + law), %d steps, %.0f points:\n",
         control_n, control_n > 0 ? static_cast<double>(points_sum) / control_n : 0.0);
  printf("CPU time mean %.2f ms (max %.2f ms): %.1f Hz (target >= 30 Hz)\n", 1e3 * cpu_mean, 1e3 * cpu_max, rate_hz);
  printf("wall time mean %.2f ms (max %.2f ms): %.1f Hz, machine load average %.2f\n", 1e3 * control_mean,
         1e3 * control_max, wall_rate_hz, load[0]);
  printf("SIFT matching (start, and when tracking fails; not in the rate): %.0f ms wall (%d runs)\n",
         match_n > 0 ? 1e3 * match_sum / match_n : NAN, match_n);

  std::filesystem::create_directories(output_dir);
  const ArmSection arm = armSection();
  const ArmCircleRun& run = arm.run;
  const int quarter_servoings = ArmSection::kQuarterServoings;
  const double circle_drift_end_mm = run.drift_mm.empty() ? NAN : run.drift_mm.back();
  const double quarter_drift_mm =
      run.drift_mm.size() >= static_cast<size_t>(quarter_servoings) ? run.drift_mm[quarter_servoings - 1] : NAN;
  const double quarter_drift_deg =
      run.drift_deg.size() >= static_cast<size_t>(quarter_servoings) ? run.drift_deg[quarter_servoings - 1] : NAN;

  // ---- Free-flying rig circle at image level (no arm): the left camera's pose is integrated directly ----
  // The rig transform is chosen with its screw axis on the vent's vertical axis: the right camera is the left one
  // rotated by 18 deg about that axis, at the horizontal radius that makes the baseline 0.3 m. Servoing k brings the
  // left camera from where servoing k - 1 ended to where the right camera was then (the reference image, K_r), so
  // 20 servoings close the circle; the drift is how far the simulated poses end from left_0 (left_T_right)^k.
  const int free_circle_servoings = 20;
  const double pan_rad = 18.0 * M_PI / 180.0, baseline_m = 0.3;
  const Eigen::Vector3d vent_base_w = renderer.config().base_m;
  const double circle_radius_m = 0.5 * baseline_m / std::sin(0.5 * pan_rad);  // chord of 18 deg = baseline
  const Eigen::Isometry3d free_left_0 =
      sim::lookAt(vent_base_w + Eigen::Vector3d(circle_radius_m, 0.0, 0.55), vent_base_w + Eigen::Vector3d(0, 0, 0.12));
  const Eigen::Isometry3d pan_w = aboutVertical(vent_base_w, pan_rad);
  const Eigen::Isometry3d left_T_right = free_left_0.inverse() * pan_w * free_left_0;
  printf(
      "\n== Free-flying rig circle (image level, no arm): left_T_right baseline %.4f m, pan %.3f deg, screw axis "
      "on the vent's axis (radius %.4f m), %d servoings\n",
      left_T_right.translation().norm(), Eigen::AngleAxisd(left_T_right.linear()).angle() * 180.0 / M_PI,
      circle_radius_m, free_circle_servoings);

  // Renderer check first: the right camera's views all round the circle must show the textured vent, not hidden by
  // the seabed (the chimney's texture has a seam at azimuth pi; the light makes one side darker).
  double min_chimney_fraction = 1.0, min_chimney_gradient = 1e9, max_chimney_gradient = 0.0;
  int first_bad_view = -1;
  {
    const auto t_check = Clock::now();
    printf("%5s %10s %9s %9s %9s %10s\n", "view", "azimuth", "chimney", "seabed", "water", "chim grad");
    for (int k = 0; k < free_circle_servoings; ++k) {
      Eigen::Isometry3d pose = free_left_0;
      for (int j = 0; j <= k; ++j) pose = pose * left_T_right;
      const sim::RenderedView view = renderer.render(setup.reference_camera, pose);
      const ViewContent c = viewContent(renderer, setup.reference_camera, pose, view.image);
      const Eigen::Vector3d p = pose.translation() - vent_base_w;
      printf("%5d %8.1fdeg %8.1f%% %8.1f%% %8.1f%% %10.2f\n", k + 1, std::atan2(p.y(), p.x()) * 180.0 / M_PI,
             100.0 * c.chimney_fraction, 100.0 * c.seabed_fraction, 100.0 * c.water_fraction, c.chimney_gradient);
      min_chimney_fraction = std::min(min_chimney_fraction, c.chimney_fraction);
      min_chimney_gradient = std::min(min_chimney_gradient, c.chimney_gradient);
      max_chimney_gradient = std::max(max_chimney_gradient, c.chimney_gradient);
      // A view is unusable when the vent is (almost) absent or untextured.
      if (first_bad_view < 0 && (c.chimney_fraction < 0.02 || c.chimney_gradient < 1.0)) first_bad_view = k + 1;
    }
    printf("renderer check: vent on >= %.1f%% of every view, chimney gradient %.2f..%.2f gray/px, %s (%.1f s)\n",
           100.0 * min_chimney_fraction, min_chimney_gradient, max_chimney_gradient,
           first_bad_view < 0 ? "all sides textured and visible"
                              : ("view " + std::to_string(first_bad_view) + " degenerate").c_str(),
           std::chrono::duration<double>(Clock::now() - t_check).count());
  }

  std::vector<double> free_drift_mm, free_drift_deg, free_step_mm, free_step_deg;
  std::vector<int> free_images_per;
  std::vector<std::string> free_status_per;
  int free_images = 0;
  std::string free_status = "converged";
  double free_drift_max_mm = 0.0, free_closure_mm = NAN, free_closure_deg = NAN;
  const auto t_circle = Clock::now();
  {
    sim::ImageServoSetup cs = setup;  // same cameras (left K_l servoed, right K_r takes the references)
    Eigen::Isometry3d left_k = free_left_0, predicted = free_left_0;
    printf("%5s %14s %18s %18s %7s %7s %s\n", "servo", "initial", "to its target", "drift (circle)", "images", "remat",
           "status");
    for (int k = 0; k < free_circle_servoings; ++k) {
      cs.world_T_start = left_k;
      cs.world_T_reference = left_k * left_T_right;
      predicted = predicted * left_T_right;
      const sim::ImageServoResult r = sim::runImageServo(renderer, cs, config);
      free_images += r.iterations;
      left_k = r.final_pose;
      const sim::PoseError drift = sim::poseError(left_k, predicted);
      free_drift_mm.push_back(drift.position_mm);
      free_drift_deg.push_back(drift.rotation_deg);
      free_step_mm.push_back(r.final_error.position_mm);
      free_step_deg.push_back(r.final_error.rotation_deg);
      free_images_per.push_back(r.iterations);
      free_status_per.push_back(sim::toString(r.status));
      free_drift_max_mm = std::max(free_drift_max_mm, drift.position_mm);
      printf("%5d %6.1fmm %5.1fd %9.3fmm %6.4fd %9.3fmm %6.4fd %7d %7d %s%s\n", k + 1, r.initial_error.position_mm,
             r.initial_error.rotation_deg, r.final_error.position_mm, r.final_error.rotation_deg, drift.position_mm,
             drift.rotation_deg, r.iterations, r.rematches, sim::toString(r.status).c_str(),
             r.status == sim::ImageServoStatus::kConverged ? "" : (" (" + r.message + ")").c_str());
      if (r.status != sim::ImageServoStatus::kConverged) {
        free_status = sim::toString(r.status) + " at servoing " + std::to_string(k + 1) + " of " +
                      std::to_string(free_circle_servoings) + ": " + r.message;
        break;
      }
    }
    if (free_drift_mm.size() == static_cast<size_t>(free_circle_servoings)) {
      const sim::PoseError closure = sim::poseError(left_k, free_left_0);
      free_closure_mm = closure.position_mm;
      free_closure_deg = closure.rotation_deg;
    }
  }
  const double free_circle_s = std::chrono::duration<double>(Clock::now() - t_circle).count();
  printf(
      "%s after %zu servoings (%.0f deg round), %d images; drift end %.3f mm %.4f deg (max %.3f mm); closure "
      "%.3f mm %.4f deg; %.1f s\n",
      free_status.c_str(), free_drift_mm.size(), 18.0 * free_drift_mm.size(), free_images,
      free_drift_mm.empty() ? NAN : free_drift_mm.back(), free_drift_deg.empty() ? NAN : free_drift_deg.back(),
      free_drift_max_mm, free_closure_mm, free_closure_deg, free_circle_s);

  const std::string path = output_dir + "/servo_image.json";
  nlohmann::ordered_json json;
  json["image_loop_pos_err_mm"] = pos_sum / n;
  json["image_loop_rot_err_deg"] = rot_sum / n;
  json["image_loop_iterations"] = iter_sum / n;
  json["image_loop_pos_err_mm_max"] = pos_max;
  json["image_loop_rot_err_deg_max"] = rot_max;
  json["image_loop_converged"] = converged;
  json["image_loop_pos_err_mm_without_anchoring"] = pos_na / n;
  json["image_loop_rot_err_deg_without_anchoring"] = rot_na / n;
  json["image_loop_converged_without_anchoring"] = converged_na;
  json["image_loop_runs"] = starts.size();
  json["control_rate_hz"] = rate_hz;
  json["control_cpu_ms_mean"] = 1e3 * cpu_mean;
  json["control_cpu_ms_max"] = 1e3 * cpu_max;
  json["control_rate_hz_wall"] = wall_rate_hz;
  json["control_wall_ms_mean"] = 1e3 * control_mean;
  json["control_wall_ms_max"] = 1e3 * control_max;
  json["load_average"] = load[0];
  json["control_points_mean"] = control_n > 0 ? static_cast<double>(points_sum) / control_n : NAN;
  json["sift_match_ms_mean"] = match_n > 0 ? 1e3 * match_sum / match_n : NAN;
  json["arm_circle_servoings"] = run.drift_mm.size();
  json["arm_circle_status"] = run.status;
  json["arm_circle_images"] = run.images;
  json["arm_circle_drift_end_mm"] = circle_drift_end_mm;
  json["arm_circle_drift_end_deg"] = run.drift_deg.empty() ? NAN : run.drift_deg.back();
  json["arm_circle_placement_m"] = {arm.placement.axis_base_m.x(), arm.placement.axis_base_m.y(),
                                    arm.placement.axis_base_m.z()};
  json["arm_circle_start_azimuth_deg"] = arm.placement.start_azimuth_rad * 180.0 / M_PI;
  json["arm_circle_min_sigma"] = arm.placement.found ? arm.placement.report.worst_sigma_min : NAN;
  json["arm_circle_min_joint_margin_rad"] = arm.placement.found ? arm.placement.report.worst_joint_margin_rad : NAN;
  json["arm_circle_feasible_servoings"] = arm.placed_check.feasible_steps;
  json["arm_circle_min_sigma_run"] = run.min_sigma_all;
  json["arm_circle_quarter_drift_mm"] = quarter_drift_mm;
  json["arm_circle_quarter_drift_deg"] = quarter_drift_deg;
  json["arm_circle_search_s"] = arm.search_s;
  json["arm_circle_max_feasible_servoings_any_placement"] = arm.max_feasible_any_placement;
  json["arm_circle_default_feasible_servoings"] = arm.default_check.feasible_steps;
  json["arm_circle_default_min_sigma"] = arm.default_check.worst_sigma_min;
  json["arm_circle_default_servoings"] = arm.default_run.drift_mm.size();
  json["arm_circle_default_status"] = arm.default_run.status;
  json["arm_circle_default_min_sigma_run"] = arm.default_run.min_sigma_all;
  json["arm_circle_default_drift_end_mm"] = arm.default_run.drift_mm.empty() ? NAN : arm.default_run.drift_mm.back();
  json["circle_servoings"] = free_drift_mm.size();
  json["circle_drift_end_mm"] = free_drift_mm.empty() ? NAN : free_drift_mm.back();
  json["circle_drift_end_deg"] = free_drift_deg.empty() ? NAN : free_drift_deg.back();
  json["circle_drift_max_mm"] = free_drift_max_mm;
  json["circle_closure_mm"] = free_closure_mm;
  json["circle_closure_deg"] = free_closure_deg;
  json["circle_images"] = free_images;
  json["circle_status"] = free_status;
  json["circle_seconds"] = free_circle_s;
  json["circle_renderer_min_chimney_fraction"] = min_chimney_fraction;
  json["circle_renderer_min_chimney_gradient"] = min_chimney_gradient;
  json["circle_per_servoing"] = nlohmann::ordered_json::array();
  for (size_t k = 0; k < free_drift_mm.size(); ++k) {
    json["circle_per_servoing"].push_back({{"servoing", k + 1},
                                           {"drift_mm", free_drift_mm[k]},
                                           {"drift_deg", free_drift_deg[k]},
                                           {"final_pos_err_mm", free_step_mm[k]},
                                           {"final_rot_err_deg", free_step_deg[k]},
                                           {"images", free_images_per[k]},
                                           {"status", free_status_per[k]}});
  }
  json["starts"] = nlohmann::ordered_json::array();
  for (const auto& r : results) {
    json["starts"].push_back({{"initial_pos_mm", r.initial_error.position_mm},
                              {"initial_rot_deg", r.initial_error.rotation_deg},
                              {"final_pos_err_mm", r.final_error.position_mm},
                              {"final_rot_err_deg", r.final_error.rotation_deg},
                              {"iterations", r.iterations},
                              {"rematches", r.rematches},
                              {"initial_matches", r.initial_matches},
                              {"control_cpu_ms_mean", 1e3 * r.mean_control_cpu_time_s},
                              {"status", sim::toString(r.status)}});
  }
  try {
    exocet_common::writeJsonFileAtomically(path, json);
  } catch (const std::exception& e) {
    std::cerr << "bench_servo_image: " << e.what() << "\n";
    return 1;
  }
  printf("\nwrote %s\n", path.c_str());

  // servo.json (bench_servo, which runs first) leaves the image-level figures to this benchmark: fill them in.
  const std::string servo_path = output_dir + "/servo.json";
  if (auto servo = exocet_common::readJsonObjectFile<nlohmann::ordered_json>(servo_path)) {
    for (const char* key : {"image_loop_pos_err_mm", "image_loop_rot_err_deg", "control_rate_hz"})
      if (servo->contains(key) && (*servo)[key].is_null()) (*servo)[key] = json[key];
    try {
      exocet_common::writeJsonFileAtomically(servo_path, *servo);
    } catch (const std::exception& e) {
      std::cerr << "bench_servo_image: " << e.what() << "\n";
      return 1;
    }
    printf("filled the image-level figures of %s\n", servo_path.c_str());
  }
  return 0;
}
