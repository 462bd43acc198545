// Benchmark of the intrinsics-free servo at point level (2D4 report 2.4, figures 4 and 5): the reference image is taken
// by the right camera, the left camera (other intrinsics) servoes to it, 0.5 px noise, several seeds and start poses.
// Compared with classical IBVS on raw points with ViSP (vpServo + vpFeaturePoint) fed the same reference image, which
// converges to the pose where the left image looks like the right one: the wrong pose. Also ViSP's 4-point tutorial
// iteration count, the circular acquisition (baseline 0.3 m, pan 18 deg, 20 servoings) against the screw prediction,
// and the rate of one control-law step. Writes servo.json.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <random>
#include <string>
#include <vector>

#include <visp3/core/vpHomogeneousMatrix.h>
#include <visp3/core/vpPoint.h>
#include <visp3/robot/vpSimulatorCamera.h>
#include <visp3/visual_features/vpFeatureBuilder.h>
#include <visp3/visual_features/vpFeaturePoint.h>
#include <visp3/vs/vpServo.h>
#include <nlohmann/json.hpp>

#include "exocet_common/json_file.h"
#include "exocet_common/command_line.h"
#include "exocet_servo/control/invariant_servo.h"
#include "exocet_servo/sim/point_scene.h"
#include "exocet_servo/sim/pose_bound.h"
#include "exocet_servo/sim/servo_simulation.h"
#include "exocet_servo/trajectory/acquisition_planner.h"
#include "exocet_servo/trajectory/rig_geometry.h"
#include "exocet_servo/trajectory/screw_motion.h"
#include "exocet_servo/trajectory/se3.h"

namespace {

using namespace exocet_servo;
using Clock = std::chrono::steady_clock;

struct Scene {
  std::vector<Eigen::Vector3d> points;
  sim::PinholeCamera left, right;
  trajectory::RigGeometry rig;  // 0.3 m, 18 deg
  Eigen::Isometry3d start;      // left camera 1 m from the vent, the screw axis on the vent's axis
  Eigen::Isometry3d reference;  // right camera
};

Scene makeScene(int n_points) {
  Scene s;
  sim::VentConfig vent;
  vent.points = n_points;
  vent.seed = 3;
  s.points = sim::makeVentPoints(vent);
  s.left.k = sim::intrinsics(800.0, 812.0, 322.0, 236.0);
  s.right.k = sim::intrinsics(905.0, 880.0, 301.0, 257.0, 1.5);
  s.start = sim::lookAt(Eigen::Vector3d(1.0, 0.0, 0.15), Eigen::Vector3d(0.0, 0.0, 0.15));
  s.reference = s.start * s.rig.leftFromRight();
  return s;
}

std::vector<Eigen::Isometry3d> startPoses(const Eigen::Isometry3d& start) {
  std::vector<Eigen::Isometry3d> out{start};
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int i = 0; i < 3; ++i) {
    trajectory::Twist d;
    d << 0.05 * u(rng), 0.05 * u(rng), 0.05 * u(rng), 0.17 * u(rng), 0.17 * u(rng), 0.17 * u(rng);
    out.push_back(start * trajectory::expSe3(d));
  }
  return out;
}

/// Classical IBVS (ViSP) on normalised points computed with the LEFT camera's intrinsics from both images, as a user
/// of one calibrated camera would; same integration (exponential map, dt 1 s) and gain as the invariant servo.
sim::ServoSimResult ibvsWithOtherCameraReference(const Scene& s, const Eigen::Isometry3d& start, double noise_px,
                                                 unsigned seed, vpServo::vpServoIteractionMatrixType type,
                                                 int iterations) {
  std::mt19937 rng(seed);
  const Eigen::Matrix3d k_inv = s.left.k.inverse();
  auto normalised = [&](const Eigen::Vector2d& p) {
    const Eigen::Vector3d m = k_inv * Eigen::Vector3d(p.x(), p.y(), 1.0);
    return Eigen::Vector2d(m.x() / m.z(), m.y() / m.z());
  };
  const sim::Projection ref = sim::project(s.right, s.reference, s.points, noise_px, &rng);
  const size_t n = s.points.size();
  std::vector<vpFeaturePoint> p(n), pd(n);
  vpServo task;
  task.setServo(vpServo::EYEINHAND_CAMERA);
  task.setInteractionMatrixType(type);
  task.setLambda(0.5);
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector2d m = normalised(ref.points_px[i]);
    pd[i].buildFrom(m.x(), m.y(), ref.depths_m[i]);
  }
  Eigen::Isometry3d pose = start;
  sim::ServoSimResult r;
  r.status = control::ServoStatus::kMaxIterations;
  for (int it = 0; it < iterations; ++it) {
    const sim::Projection cur = sim::project(s.left, pose, s.points, noise_px, &rng);
    for (size_t i = 0; i < n; ++i) {
      const Eigen::Vector2d m = normalised(cur.points_px[i]);
      p[i].buildFrom(m.x(), m.y(), cur.depths_m[i]);
      if (it == 0) task.addFeature(p[i], pd[i]);
    }
    const vpColVector v = task.computeControlLaw();
    trajectory::Twist t;
    for (int j = 0; j < 6; ++j) t(j) = v[j];
    pose = pose * trajectory::expSe3(t);
    r.iterations = it + 1;
  }
  r.final_pose = pose;
  r.final_error = sim::poseError(pose, s.reference);
  return r;
}

/// ViSP's tutorial-ibvs-4pts, with the loop run until ||e||^2 < 1e-4 (the tutorial runs 150 iterations).
int vispTutorialIterations() {
  vpHomogeneousMatrix cdMo(0, 0, 0.75, 0, 0, 0);
  vpHomogeneousMatrix cMo(0.15, -0.1, 1., vpMath::rad(10), vpMath::rad(-10), vpMath::rad(50));
  vpPoint point[4];
  point[0].setWorldCoordinates(-0.1, -0.1, 0);
  point[1].setWorldCoordinates(0.1, -0.1, 0);
  point[2].setWorldCoordinates(0.1, 0.1, 0);
  point[3].setWorldCoordinates(-0.1, 0.1, 0);
  vpServo task;
  task.setServo(vpServo::EYEINHAND_CAMERA);
  task.setInteractionMatrixType(vpServo::CURRENT);
  task.setLambda(0.5);
  vpFeaturePoint p[4], pd[4];
  for (unsigned int i = 0; i < 4; i++) {
    point[i].track(cdMo);
    vpFeatureBuilder::create(pd[i], point[i]);
    point[i].track(cMo);
    vpFeatureBuilder::create(p[i], point[i]);
    task.addFeature(p[i], pd[i]);
  }
  vpHomogeneousMatrix wMc, wMo;
  vpSimulatorCamera robot;
  robot.setSamplingTime(0.040);
  robot.getPosition(wMc);
  wMo = wMc * cMo;
  for (int iter = 1; iter <= 100000; ++iter) {
    robot.getPosition(wMc);
    cMo = wMc.inverse() * wMo;
    for (unsigned int i = 0; i < 4; i++) {
      point[i].track(cMo);
      vpFeatureBuilder::create(p[i], point[i]);
    }
    const vpColVector v = task.computeControlLaw();
    if (task.getError().sumSquare() < 1e-4) return iter;
    robot.setVelocity(vpRobot::CAMERA_FRAME, v);
  }
  return -1;
}

struct Stats {
  double pos_mean = 0, pos_max = 0, rot_mean = 0, rot_max = 0, iter_mean = 0;
  int runs = 0, converged = 0;
  void add(const sim::ServoSimResult& r) {
    pos_mean += r.final_error.position_mm;
    rot_mean += r.final_error.rotation_deg;
    iter_mean += r.iterations;
    pos_max = std::max(pos_max, r.final_error.position_mm);
    rot_max = std::max(rot_max, r.final_error.rotation_deg);
    converged += r.status == control::ServoStatus::kConverged;
    ++runs;
  }
  void finish() {
    pos_mean /= runs;
    rot_mean /= runs;
    iter_mean /= runs;
  }
};

}  // namespace

int main(int argc, char** argv) {
  exocet_common::BenchmarkPaths paths;
  CLI::App app(
      "bench_servo: the intrinsics-free servo at point level against classical IBVS (ViSP), the circular\n"
      "acquisition against the screw prediction, and the rate of one control-law step.\n"
      "Writes OUTPUT_DIR/servo.json (its image-level figures are null until bench_servo_image fills them).",
      "bench_servo");
  exocet_common::addBenchmarkPathOptions(app, &paths, false);
  if (const auto exit_status = exocet_common::parseCommandLine(app, argc, argv)) return *exit_status;
  const std::string& output_dir = paths.output_dir;
  const Scene scene = makeScene(100);
  const auto starts = startPoses(scene.start);
  const double noise_px = 0.5;

  // --- A. Invariant servo vs classical IBVS, reference from the other camera. ---
  control::ServoConfig servo;
  servo.max_iterations = 100;
  servo.convergence_threshold = 0.025;  // just above the noise floor of |e| at 0.5 px for this scene
  control::ServoConfig servo_exact = servo;
  servo_exact.convergence_threshold = 1e-7;
  Stats inv, inv_exact, ibvs, ibvs_exact, ibvs_desired;
  for (size_t s = 0; s < starts.size(); ++s) {
    for (unsigned seed = 0; seed < 3; ++seed) {
      sim::ServoSimConfig simc;
      simc.noise_px = noise_px;
      simc.seed = 1000 + 17 * seed + s;
      inv.add(sim::simulateServo(scene.points, scene.right, scene.reference, scene.left, starts[s], servo, simc,
                                 scene.right.k, scene.left.k));
      ibvs.add(ibvsWithOtherCameraReference(scene, starts[s], noise_px, simc.seed, vpServo::CURRENT, 100));
      ibvs_desired.add(ibvsWithOtherCameraReference(scene, starts[s], noise_px, simc.seed, vpServo::DESIRED, 100));
    }
    sim::ServoSimConfig clean;
    clean.noise_px = 0.0;
    inv_exact.add(sim::simulateServo(scene.points, scene.right, scene.reference, scene.left, starts[s], servo_exact,
                                     clean, scene.right.k, scene.left.k));
    ibvs_exact.add(ibvsWithOtherCameraReference(scene, starts[s], 0.0, 0, vpServo::CURRENT, 100));
  }
  for (Stats* st : {&inv, &inv_exact, &ibvs, &ibvs_exact, &ibvs_desired}) st->finish();
  const sim::PoseBound bound = sim::poseCramerRao(scene.points, scene.right, scene.reference, noise_px, false);
  const sim::PoseBound bound_cal = sim::poseCramerRao(scene.points, scene.right, scene.reference, noise_px, true);

  printf(
      "== Servo to the right camera's reference pose (left camera servoed, other intrinsics; 100 vent points at "
      "1 m; %zu start poses)\n",
      starts.size());
  printf("%-44s %6s %10s %10s %10s %10s %8s\n", "method", "runs", "pos mean", "pos max", "rot mean", "rot max",
         "iters");
  auto row = [](const char* name, const Stats& st) {
    printf("%-44s %6d %8.3fmm %8.3fmm %8.4fdeg %8.4fdeg %8.1f\n", name, st.runs, st.pos_mean, st.pos_max, st.rot_mean,
           st.rot_max, st.iter_mean);
  };
  row("invariant (Malis), 0.5 px noise", inv);
  row("invariant (Malis), no noise", inv_exact);
  row("ViSP IBVS points (current L), 0.5 px", ibvs);
  row("ViSP IBVS points (desired L), 0.5 px", ibvs_desired);
  row("ViSP IBVS points (current L), no noise", ibvs_exact);
  printf("invariant servo converged in %d of %d noisy runs (|e| < %.3g)\n", inv.converged, inv.runs,
         servo.convergence_threshold);
  printf(
      "Cramer-Rao bound of one image's pose at 0.5 px: intrinsics unknown %.2f mm %.3f deg (t_z alone %.2f mm); "
      "known %.2f mm %.3f deg; servo floor ~ sqrt(2) x bound\n",
      bound.position_rms_mm(), bound.rotation_rms_deg(), bound.translation_mm.z(), bound_cal.position_rms_mm(),
      bound_cal.rotation_rms_deg());

  // The floor is the noisy reference: it shrinks as 1/sqrt(points) (SIFT gives hundreds of points per image).
  printf("\n%6s %12s %12s %16s %16s\n", "points", "pos rms", "rot rms", "bound pos (x1.41)", "bound rot (x1.41)");
  std::vector<std::pair<int, double>> pos_by_points;
  for (int n : {100, 400, 1000}) {
    const Scene sc = makeScene(n);
    control::ServoConfig scaled = servo;  // |e| estimates the remaining displacement: stop at the noise floor
    scaled.convergence_threshold = servo.convergence_threshold * std::sqrt(100.0 / n);
    double s2 = 0.0, r2 = 0.0;
    const int seeds = 10;
    for (int seed = 0; seed < seeds; ++seed) {
      sim::ServoSimConfig simc;
      simc.noise_px = noise_px;
      simc.seed = 5000 + seed;
      const sim::ServoSimResult r =
          sim::simulateServo(sc.points, sc.right, sc.reference, sc.left, sc.start, scaled, simc, sc.right.k, sc.left.k);
      s2 += r.final_error.position_mm * r.final_error.position_mm;
      r2 += r.final_error.rotation_deg * r.final_error.rotation_deg;
    }
    const sim::PoseBound b = sim::poseCramerRao(sc.points, sc.right, sc.reference, noise_px, false);
    printf("%6d %10.2fmm %10.3fdeg %14.2fmm %14.3fdeg\n", n, std::sqrt(s2 / seeds), std::sqrt(r2 / seeds),
           std::sqrt(2.0) * b.position_rms_mm(), std::sqrt(2.0) * b.rotation_rms_deg());
    pos_by_points.emplace_back(n, std::sqrt(s2 / seeds));
  }

  // --- B. ViSP tutorial. ---
  const int tutorial_iterations = vispTutorialIterations();
  printf("\n== ViSP tutorial-ibvs-4pts (lambda 0.5, dt 0.04 s, same K): %d iterations to ||e||^2 < 1e-4\n",
         tutorial_iterations);

  // --- C. Circular acquisition: 20 servoings, baseline 0.3 m, pan 18 deg. ---
  const trajectory::ScrewMotion screw = trajectory::screwFromTransform(scene.rig.leftFromRight());
  const Eigen::Isometry3d circle_start =
      trajectory::alignScrewWithAxis(screw, Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitZ(), 0.0, 0.15);
  sim::ServoSimConfig circle_sim;
  circle_sim.noise_px = noise_px;
  circle_sim.seed = 77;
  std::vector<sim::ServoSimResult> circle_results;
  const auto circle = sim::simulateRepeatedServoing(scene.points, scene.left, scene.right, scene.rig.leftFromRight(),
                                                    circle_start, 20, servo, circle_sim, &circle_results);
  sim::ServoSimConfig circle_clean = circle_sim;
  circle_clean.noise_px = 0.0;
  const auto circle_exact = sim::simulateRepeatedServoing(
      scene.points, scene.left, scene.right, scene.rig.leftFromRight(), circle_start, 20, servo_exact, circle_clean);
  printf("\n== Circular acquisition: radius %.3f m, %.1f deg per servoing, pitch %.4f m\n", screw.radius_m,
         screw.angle_per_step_rad * 180 / M_PI, screw.pitch_per_step_m);
  printf("%4s %12s %12s %12s %14s %8s\n", "k", "pred x", "pred y", "err 0.5px", "err no noise", "iters");
  double pred_err_max = 0.0, pred_err_exact_max = 0.0;
  for (int k = 0; k <= 20; ++k) {
    const Eigen::Isometry3d predicted = circle_start * screw.pose(k);
    const double e = sim::poseError(circle[k], predicted).position_mm;
    const double e0 = sim::poseError(circle_exact[k], predicted).position_mm;
    pred_err_max = std::max(pred_err_max, e);
    pred_err_exact_max = std::max(pred_err_exact_max, e0);
    printf("%4d %11.3fm %11.3fm %10.2fmm %12.5fmm %8d\n", k, predicted.translation().x(), predicted.translation().y(),
           e, e0, k > 0 ? circle_results[k - 1].iterations : 0);
  }
  const double drift = 1000.0 * (circle[20].translation() - circle[0].translation()).norm();
  const double drift_exact = 1000.0 * (circle_exact[20].translation() - circle_exact[0].translation()).norm();
  printf(
      "drift over the circle (start to pose after 20 servoings; prediction: 0): %.2f mm at 0.5 px, %.5f mm "
      "without noise\n",
      drift, drift_exact);

  // With 1000 points instead of 100.
  const Scene dense = makeScene(1000);
  control::ServoConfig servo_dense = servo;
  servo_dense.convergence_threshold = servo.convergence_threshold * std::sqrt(100.0 / 1000.0);
  const auto circle_dense = sim::simulateRepeatedServoing(
      dense.points, dense.left, dense.right, dense.rig.leftFromRight(), circle_start, 20, servo_dense, circle_sim);
  double pred_err_dense_max = 0.0;
  for (int k = 0; k <= 20; ++k)
    pred_err_dense_max =
        std::max(pred_err_dense_max, sim::poseError(circle_dense[k], circle_start * screw.pose(k)).position_mm);
  const double drift_dense = 1000.0 * (circle_dense[20].translation() - circle_dense[0].translation()).norm();
  printf("with 1000 points at 0.5 px: largest prediction error %.2f mm, drift over the circle %.2f mm\n",
         pred_err_dense_max, drift_dense);

  // --- D. Control-law rate. ---
  printf("\n== One control-law step (invariant points + interaction + pseudo-inverse), mean interaction\n");
  double rate_200 = 0.0;
  for (int n : {50, 100, 200}) {
    const Scene sc = makeScene(n);
    const sim::Projection ref = sim::project(sc.right, sc.reference, sc.points);
    const sim::Projection cur = sim::project(sc.left, sc.start, sc.points);
    control::ServoConfig cfg = servo;
    cfg.max_iterations = 1000000;
    control::InvariantServo timed(cfg);
    timed.setReference(ref.points_px, sc.right.k, ref.depths_m);
    const int reps = 2000;
    const auto t0 = Clock::now();
    double sink = 0.0;
    for (int r = 0; r < reps; ++r) sink += timed.step(cur.points_px, sc.left.k, cur.depths_m).velocity(0);
    const double s_per = std::chrono::duration<double>(Clock::now() - t0).count() / reps;
    printf("%4d points: %8.1f us per step, %9.0f Hz%s\n", n, 1e6 * s_per, 1.0 / s_per, sink == 12345.0 ? "!" : "");
    if (n == 200) rate_200 = 1.0 / s_per;
  }

  std::filesystem::create_directories(output_dir);
  const std::string path = output_dir + "/servo.json";
  nlohmann::ordered_json json;
  json["final_pos_err_mm"] = inv.pos_mean;
  json["final_rot_err_deg"] = inv.rot_mean;
  json["iterations"] = inv.iter_mean;
  json["final_pos_err_mm_max"] = inv.pos_max;
  json["final_rot_err_deg_max"] = inv.rot_max;
  json["final_pos_err_mm_noise_free"] = inv_exact.pos_max;
  json["final_rot_err_deg_noise_free"] = inv_exact.rot_max;
  json["iterations_noise_free"] = inv_exact.iter_mean;
  json["pose_bound_intrinsics_unknown_mm"] = bound.position_rms_mm();
  json["pose_bound_intrinsics_unknown_deg"] = bound.rotation_rms_deg();
  json["pose_bound_intrinsics_known_mm"] = bound_cal.position_rms_mm();
  json["pose_bound_intrinsics_known_deg"] = bound_cal.rotation_rms_deg();
  json["ibvs_final_pos_err_mm"] = ibvs.pos_mean;
  json["ibvs_final_rot_err_deg"] = ibvs.rot_mean;
  json["ibvs_desired_final_pos_err_mm"] = ibvs_desired.pos_mean;
  json["ibvs_desired_final_rot_err_deg"] = ibvs_desired.rot_mean;
  json["visp_tutorial_iterations"] = tutorial_iterations;
  json["trajectory_prediction_err_mm"] = pred_err_max;
  json["trajectory_prediction_err_mm_noise_free"] = pred_err_exact_max;
  json["circle_drift_mm"] = drift;
  json["circle_drift_mm_noise_free"] = drift_exact;
  json["trajectory_prediction_err_mm_1000_points"] = pred_err_dense_max;
  json["circle_drift_mm_1000_points"] = drift_dense;
  nlohmann::ordered_json by_points = nlohmann::ordered_json::object();
  for (const auto& [points, rms_mm] : pos_by_points) by_points[std::to_string(points)] = rms_mm;
  json["final_pos_err_mm_rms_by_points"] = by_points;
  json["control_law_rate_hz"] = rate_200;
  json["control_law_points"] = 200;
  // The image-level figures are bench_servo_image's, which fills them in.
  json["image_loop_pos_err_mm"] = nullptr;
  json["image_loop_rot_err_deg"] = nullptr;
  json["control_rate_hz"] = nullptr;
  try {
    exocet_common::writeJsonFileAtomically(path, json);
  } catch (const std::exception& e) {
    std::cerr << "bench_servo: " << e.what() << "\n";
    return 1;
  }
  printf("\nwrote %s\n", path.c_str());
  return 0;
}
