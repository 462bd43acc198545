// Tests of the intrinsics-free servo core (2D4 report 2.3): invariance of the projective invariant points to the
// intrinsics, the analytic interaction matrix against finite differences, convergence of the servo between two
// different cameras under pixel noise, and the stop criteria.
#include <cmath>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "exocet_servo/control/invariant_features.h"
#include "exocet_servo/control/invariant_interaction.h"
#include "exocet_servo/control/invariant_servo.h"
#include "exocet_servo/sim/point_scene.h"
#include "exocet_servo/sim/pose_bound.h"
#include "exocet_servo/sim/servo_simulation.h"
#include "exocet_servo/trajectory/rig_geometry.h"
#include "exocet_servo/trajectory/se3.h"

namespace {

using namespace exocet_servo;
using control::InvariantPoints;
using control::ServoStatus;

std::vector<Eigen::Vector3d> ventPoints(int n, unsigned seed = 3) {
  sim::VentConfig vent;
  vent.points = n;
  vent.seed = seed;
  return sim::makeVentPoints(vent);
}

// The left camera 1 m from the chimney's axis, looking at its middle.
Eigen::Isometry3d leftPose() { return sim::lookAt(Eigen::Vector3d(1.0, 0.0, 0.15), Eigen::Vector3d(0.0, 0.0, 0.15)); }

sim::PinholeCamera leftCamera() {
  sim::PinholeCamera c;
  c.k = sim::intrinsics(800.0, 812.0, 322.0, 236.0, 0.0);
  return c;
}

sim::PinholeCamera rightCamera() {  // another model: longer focal length, other aspect, principal point and skew
  sim::PinholeCamera c;
  c.k = sim::intrinsics(905.0, 880.0, 301.0, 257.0, 1.5);
  return c;
}

TEST(ServoInvariantFeatures, UpperFactorReproducesMatrix) {
  Eigen::Matrix3d a = Eigen::Matrix3d::Random();
  const Eigen::Matrix3d s = a * a.transpose() + 0.5 * Eigen::Matrix3d::Identity();
  Eigen::Matrix3d u;
  ASSERT_TRUE(control::upperTriangularFactor(s, &u));
  EXPECT_NEAR((u * u.transpose() - s).norm(), 0.0, 1e-12);
  EXPECT_EQ(u(1, 0), 0.0);
  EXPECT_EQ(u(2, 0), 0.0);
  EXPECT_EQ(u(2, 1), 0.0);
  EXPECT_GT(u.diagonal().minCoeff(), 0.0);
  // Collinear points give a singular S: refused.
  std::vector<Eigen::Vector3d> line;
  for (int i = 0; i < 10; ++i) line.emplace_back(10.0 + 3.0 * i, 20.0 + 2.0 * i, 1.0);
  InvariantPoints inv;
  EXPECT_NE(control::computeInvariantPoints(line, &inv), "");
}

TEST(ServoInvariantFeatures, InvariantToIntrinsics) {
  const auto pts = ventPoints(40);
  const Eigen::Isometry3d pose = leftPose();
  // The same view through very different intrinsics: focal lengths, aspect, principal point, skew.
  const std::vector<Eigen::Matrix3d> ks = {
      sim::intrinsics(800, 800, 320, 240), sim::intrinsics(1500, 1320, 100, 700, 0),
      sim::intrinsics(420, 610, -50, 35, 12.5), sim::intrinsics(2500, 2400, 1200, 1100, -40)};
  std::vector<Eigen::VectorXd> q;
  for (const auto& k : ks) {
    sim::PinholeCamera cam;
    cam.k = k;
    const sim::Projection proj = sim::project(cam, pose, pts);
    InvariantPoints inv;
    ASSERT_EQ(control::computeInvariantPoints(control::homogeneous(proj.points_px), &inv), "");
    for (const auto& qi : inv.q) EXPECT_NEAR(qi.z(), 1.0, 1e-12);
    EXPECT_NEAR(inv.t(2, 2), 1.0, 1e-12);
    q.push_back(inv.stacked());
  }
  // Meanwhile the pixels differ by hundreds of pixels.
  for (size_t i = 1; i < q.size(); ++i) EXPECT_LT((q[i] - q[0]).cwiseAbs().maxCoeff(), 1e-10) << "K " << i;
  // And the invariant points are not trivially the same for another pose.
  sim::PinholeCamera cam;
  const sim::Projection other =
      sim::project(cam, pose * trajectory::expSe3((trajectory::Twist() << 0.05, 0, 0, 0, 0.1, 0).finished()), pts);
  InvariantPoints inv;
  ASSERT_EQ(control::computeInvariantPoints(control::homogeneous(other.points_px), &inv), "");
  EXPECT_GT((inv.stacked() - q[0]).cwiseAbs().maxCoeff(), 1e-3);
}

TEST(ServoInteraction, MatchesFiniteDifferences) {
  const auto pts = ventPoints(30);
  sim::PinholeCamera cam = leftCamera();
  // A generic pose (not looking straight at the object) so every term of L matters.
  const Eigen::Isometry3d pose =
      leftPose() * trajectory::expSe3((trajectory::Twist() << 0.04, -0.03, 0.1, 0.05, -0.08, 0.3).finished());
  auto features = [&](const Eigen::Isometry3d& p) {
    const sim::Projection proj = sim::project(cam, p, pts);
    InvariantPoints inv;
    EXPECT_EQ(control::computeInvariantPoints(control::homogeneous(proj.points_px), &inv), "");
    return inv.stacked();
  };
  const sim::Projection proj = sim::project(cam, pose, pts);
  std::vector<Eigen::Vector3d> m;
  for (const auto& p : proj.points_px) m.push_back(cam.k.inverse() * Eigen::Vector3d(p.x(), p.y(), 1.0));
  Eigen::MatrixXd l;
  ASSERT_EQ(control::invariantInteraction(m, proj.depths_m, &l), "");
  ASSERT_EQ(l.rows(), 60);
  ASSERT_EQ(l.cols(), 6);
  const double h = 1e-6;
  for (int j = 0; j < 6; ++j) {
    trajectory::Twist d = trajectory::Twist::Zero();
    d(j) = h;
    const Eigen::VectorXd fd =
        (features(pose * trajectory::expSe3(d)) - features(pose * trajectory::expSe3(-d))) / (2 * h);
    const double scale = l.col(j).cwiseAbs().maxCoeff();
    EXPECT_GT(scale, 1e-3) << "column " << j;
    EXPECT_LT((fd - l.col(j)).cwiseAbs().maxCoeff(), 1e-6 * std::max(1.0, scale)) << "column " << j;
  }
  // Mismatched sizes and bad depths are refused with a message.
  EXPECT_NE(control::invariantInteraction(m, std::vector<double>(3, 1.0), &l), "");
  std::vector<double> bad = proj.depths_m;
  bad[4] = -1.0;
  EXPECT_NE(control::invariantInteraction(m, bad, &l), "");
}

TEST(ServoConfig, ValidateListsEveryBadField) {
  control::ServoConfig c;
  EXPECT_EQ(c.validate(), "");
  c.max_iterations = 0;
  c.convergence_threshold = -1.0;
  c.convergence_window = 0;
  c.gain.gain_at_zero = 0.0;
  const std::string msg = c.validate();
  EXPECT_NE(msg.find("max_iterations"), std::string::npos);
  EXPECT_NE(msg.find("convergence_threshold"), std::string::npos);
  EXPECT_NE(msg.find("convergence_window must be in [1, 1000]"), std::string::npos);
  EXPECT_NE(msg.find("gain_at_zero"), std::string::npos);
  EXPECT_THROW(control::InvariantServo{c}, std::invalid_argument);
}

TEST(ServoAdaptiveGain, FollowsViSPLaw) {
  control::AdaptiveGain g;
  g.gain_at_zero = 4.0;
  g.gain_at_infinity = 0.4;
  g.slope_at_zero = 30.0;
  EXPECT_NEAR(g(0.0), 4.0, 1e-12);
  EXPECT_NEAR(g(1e3), 0.4, 1e-9);
  EXPECT_NEAR((g(1e-7) - g(0.0)) / 1e-7, -30.0, 1e-3);
  EXPECT_NEAR(control::AdaptiveGain::constant(0.7)(5.0), 0.7, 1e-15);
}

// The report's case: reference by the right camera, servo of the left camera (other intrinsics and skew).
struct RigCase {
  std::vector<Eigen::Vector3d> points = ventPoints(100);
  Eigen::Isometry3d start = leftPose();
  Eigen::Isometry3d reference = leftPose() * trajectory::RigGeometry().leftFromRight();  // 0.3 m, 18 deg pan
  sim::PinholeCamera left = leftCamera(), right = rightCamera();
  // Start poses: the rig's own, and three others perturbed by up to 5 cm and 10 deg.
  std::vector<Eigen::Isometry3d> starts() const {
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
};

TEST(ServoSimulation, ConvergesExactlyWithDifferentIntrinsicsWithoutNoise) {
  const RigCase rc;
  control::ServoConfig servo;
  servo.max_iterations = 100;
  servo.convergence_threshold = 1e-7;
  sim::ServoSimConfig simc;
  simc.noise_px = 0.0;
  const auto starts = rc.starts();
  for (size_t s = 0; s < starts.size(); ++s) {
    // The servo believes round-number intrinsics, 10-20 % off: only L_hat is affected, not where it converges.
    const sim::ServoSimResult r =
        sim::simulateServo(rc.points, rc.right, rc.reference, rc.left, starts[s], servo, simc,
                           sim::intrinsics(1000, 1000, 320, 240), sim::intrinsics(700, 700, 320, 240));
    EXPECT_EQ(r.status, ServoStatus::kConverged) << "start " << s << ": " << r.message;
    EXPECT_LE(r.iterations, 100);
    EXPECT_LE(r.final_error.position_mm, 0.5) << "start " << s;
    EXPECT_LE(r.final_error.rotation_deg, 0.05) << "start " << s;
    const sim::PoseError initial = sim::poseError(starts[s], rc.reference);
    printf("start %zu: initial %.1f mm %.2f deg -> %s in %d iterations, final %.5f mm %.6f deg\n", s,
           initial.position_mm, initial.rotation_deg, control::toString(r.status).c_str(), r.iterations,
           r.final_error.position_mm, r.final_error.rotation_deg);
  }
}

TEST(ServoSimulation, EveryInteractionModelAndDepthSourceConverges) {
  // L_hat only shapes the path: at the current, desired or mean points, with exact depths or depths 2 % off, the
  // servo ends at the reference pose.
  const RigCase rc;
  const auto starts = rc.starts();
  for (auto model :
       {control::InteractionModel::kCurrent, control::InteractionModel::kDesired, control::InteractionModel::kMean}) {
    for (auto depth : {sim::DepthSource::kTrue, sim::DepthSource::kNoisy}) {
      control::ServoConfig servo;
      servo.interaction = model;
      servo.max_iterations = 100;
      servo.convergence_threshold = 1e-7;
      sim::ServoSimConfig simc;
      simc.noise_px = 0.0;
      simc.depth_source = depth;
      // 2 % per point (20 mm at 1 m; stereo triangulation gives ~2 mm). 10 % is as large as the depth spread of the
      // chimney, the only thing translations are seen through: the servo then crawls (> 100 iterations).
      simc.depth_noise_fraction = 0.02;
      for (size_t s = 0; s < starts.size(); ++s) {
        const sim::ServoSimResult r = sim::simulateServo(rc.points, rc.right, rc.reference, rc.left, starts[s], servo,
                                                         simc, rc.right.k, rc.left.k);
        const std::string what = "model " + std::to_string(static_cast<int>(model)) + " depth " +
                                 std::to_string(static_cast<int>(depth)) + " start " + std::to_string(s);
        EXPECT_EQ(r.status, ServoStatus::kConverged) << what << ": " << r.message;
        EXPECT_LE(r.final_error.position_mm, 0.5) << what;
        EXPECT_LE(r.final_error.rotation_deg, 0.05) << what;
      }
    }
  }
}

TEST(ServoSimulation, EqualDepthsAreRefusedAsDegenerate) {
  // One depth for every point: translations become indistinguishable from a change of intrinsics.
  const RigCase rc;
  control::ServoConfig servo;
  sim::ServoSimConfig simc;
  simc.depth_source = sim::DepthSource::kConstant;
  const sim::ServoSimResult r =
      sim::simulateServo(rc.points, rc.right, rc.reference, rc.left, rc.start, servo, simc, rc.right.k, rc.left.k);
  EXPECT_EQ(r.status, ServoStatus::kDegenerate);
  EXPECT_NE(r.message.find("depths must vary"), std::string::npos) << r.message;
  EXPECT_EQ(r.iterations, 1);
}

TEST(ServoSimulation, AdaptiveGainShortensTheEnd) {
  // A gain rising to 0.9 near convergence (0.3 far from it) ends in fewer iterations than a constant 0.5.
  const RigCase rc;
  control::ServoConfig constant;
  constant.max_iterations = 100;
  constant.convergence_threshold = 1e-7;
  control::ServoConfig adaptive = constant;
  adaptive.gain.gain_at_zero = 0.9;
  adaptive.gain.gain_at_infinity = 0.3;
  adaptive.gain.slope_at_zero = 20.0;
  ASSERT_EQ(adaptive.validate(), "");
  sim::ServoSimConfig simc;
  simc.noise_px = 0.0;
  const sim::ServoSimResult a =
      sim::simulateServo(rc.points, rc.right, rc.reference, rc.left, rc.start, adaptive, simc, rc.right.k, rc.left.k);
  const sim::ServoSimResult c =
      sim::simulateServo(rc.points, rc.right, rc.reference, rc.left, rc.start, constant, simc, rc.right.k, rc.left.k);
  ASSERT_EQ(a.status, ServoStatus::kConverged) << a.message;
  ASSERT_EQ(c.status, ServoStatus::kConverged) << c.message;
  EXPECT_LT(a.iterations, c.iterations);
  EXPECT_LE(a.final_error.position_mm, 0.5);
  printf("adaptive gain: %d iterations, constant 0.5: %d\n", a.iterations, c.iterations);
}

// With 0.5 px noise the final pose is as good as the noisy reference allows: its spread over seeds stays within twice
// the Cramer-Rao bound of an estimator that does not know the intrinsics (sqrt(2) times the one-image bound, as the
// reference and the last current image are both noisy). That bound is far above 0.5 mm / 0.05 deg here (the
// optical-axis translation trades with the focal length when the object's depth range is small).
TEST(ServoSimulation, NoisyConvergenceReachesTheCramerRaoBound) {
  const RigCase rc;
  control::ServoConfig servo;
  servo.max_iterations = 100;
  servo.convergence_threshold = 0.03;  // just above the noise floor of |e| for this scene
  sim::ServoSimConfig simc;
  simc.noise_px = 0.5;
  const sim::PoseBound bound = sim::poseCramerRao(rc.points, rc.right, rc.reference, 0.5, false);
  const sim::PoseBound calibrated = sim::poseCramerRao(rc.points, rc.right, rc.reference, 0.5, true);
  double sum_pos2 = 0.0, sum_rot2 = 0.0;
  int runs = 0;
  for (const auto& start : rc.starts()) {
    for (unsigned seed = 0; seed < 4; ++seed) {
      simc.seed = 1000 + 17 * seed + runs;
      const sim::ServoSimResult r =
          sim::simulateServo(rc.points, rc.right, rc.reference, rc.left, start, servo, simc, rc.right.k, rc.left.k);
      EXPECT_EQ(r.status, ServoStatus::kConverged) << r.message;
      sum_pos2 += r.final_error.position_mm * r.final_error.position_mm;
      sum_rot2 += r.final_error.rotation_deg * r.final_error.rotation_deg;
      ++runs;
    }
  }
  const double pos_rms = std::sqrt(sum_pos2 / runs), rot_rms = std::sqrt(sum_rot2 / runs);
  printf(
      "noisy: final error RMS %.2f mm %.3f deg over %d runs; one-image bound (intrinsics unknown) %.2f mm %.3f deg, "
      "(known) %.2f mm %.3f deg\n",
      pos_rms, rot_rms, runs, bound.position_rms_mm(), bound.rotation_rms_deg(), calibrated.position_rms_mm(),
      calibrated.rotation_rms_deg());
  EXPECT_LT(pos_rms, 2.0 * std::sqrt(2.0) * bound.position_rms_mm());
  EXPECT_LT(rot_rms, 2.0 * std::sqrt(2.0) * bound.rotation_rms_deg());
}

TEST(ServoStopCriteria, PointsLeavingTheImageStopTheServo) {
  // The object drifts sideways faster than a slow servo follows: the points leave the image.
  const RigCase rc;
  control::ServoConfig servo;
  servo.gain = control::AdaptiveGain::constant(0.2);
  servo.image_margin_px = 10.0;
  sim::ServoSimConfig simc;
  simc.noise_px = 0.5;
  simc.object_drift_m_per_s = Eigen::Vector3d(0.0, 0.08, 0.0);
  const sim::ServoSimResult r =
      sim::simulateServo(rc.points, rc.right, rc.reference, rc.left, rc.start, servo, simc, rc.right.k, rc.left.k);
  EXPECT_EQ(r.status, ServoStatus::kPointsLeftImage) << r.message;
  EXPECT_NE(r.message.find("left the image"), std::string::npos) << r.message;
  // The same servo without drift converges.
  simc.object_drift_m_per_s.setZero();
  servo.convergence_threshold = 0.04;
  const sim::ServoSimResult still =
      sim::simulateServo(rc.points, rc.right, rc.reference, rc.left, rc.start, servo, simc, rc.right.k, rc.left.k);
  EXPECT_EQ(still.status, ServoStatus::kConverged) << still.message;
}

TEST(ServoStopCriteria, GrowingErrorStopsTheServo) {
  // The object recedes along the optical axis faster than a low-gain servo follows: |e| keeps growing.
  const RigCase rc;
  control::ServoConfig servo;
  servo.gain = control::AdaptiveGain::constant(0.05);
  servo.max_iterations = 500;
  sim::ServoSimConfig simc;
  simc.noise_px = 0.0;
  const Eigen::Vector3d optical_axis = rc.reference.linear().col(2);
  simc.object_drift_m_per_s = 0.01 * optical_axis;
  const Eigen::Isometry3d near_start =
      rc.reference * trajectory::expSe3((trajectory::Twist() << 0.005, 0, 0, 0, 0, 0).finished());
  const sim::ServoSimResult r =
      sim::simulateServo(rc.points, rc.right, rc.reference, rc.left, near_start, servo, simc, rc.right.k, rc.left.k);
  EXPECT_EQ(r.status, ServoStatus::kErrorGrowing) << r.message;
  EXPECT_LT(r.iterations, 100);
}

// At the goal, image noise that alternates in sign (+n, -n, +n, ...) keeps every single |e| above the threshold, but
// its mean over an even window is zero: convergence_window 6 converges on the 6th step, a window of 1 never does.
TEST(ServoStopCriteria, TheMeanOfEOverAWindowConvergesThroughNoise) {
  const std::vector<Eigen::Vector3d> points = ventPoints(100);
  const Eigen::Isometry3d pose = leftPose();
  const sim::Projection reference = sim::project(rightCamera(), pose, points);
  const sim::Projection current = sim::project(leftCamera(), pose, points);  // at the goal, other intrinsics
  std::mt19937 rng(5);
  std::normal_distribution<double> gauss(0.0, 0.05);
  std::vector<Eigen::Vector2d> pattern;
  for (size_t i = 0; i < points.size(); ++i) pattern.emplace_back(gauss(rng), gauss(rng));
  for (int window : {1, 6}) {
    control::ServoConfig config;
    config.convergence_threshold = 1e-4;
    config.convergence_window = window;
    control::InvariantServo servo(config);
    ASSERT_EQ(servo.setReference(reference.points_px, rightCamera().k, reference.depths_m), "");
    int converged_at = 0;
    for (int it = 1; it <= 40 && converged_at == 0; ++it) {
      std::vector<Eigen::Vector2d> noisy = current.points_px;
      for (size_t i = 0; i < noisy.size(); ++i) noisy[i] += (it % 2 ? 1.0 : -1.0) * pattern[i];
      const control::ServoStep step = servo.step(noisy, leftCamera().k, current.depths_m);
      if (step.status == ServoStatus::kConverged) {
        converged_at = it;
      } else {
        ASSERT_EQ(step.status, ServoStatus::kRunning) << step.message;
        ASSERT_GT(step.error_norm, 10.0 * config.convergence_threshold);  // one image alone is far from it
      }
    }
    EXPECT_EQ(converged_at, window == 1 ? 0 : 6) << "window " << window;
  }
}

TEST(ServoStopCriteria, BudgetInputsAndStickyStatus) {
  const RigCase rc;
  control::ServoConfig config;
  config.max_iterations = 3;
  control::InvariantServo servo(config);
  const sim::Projection ref = sim::project(rc.right, rc.reference, rc.points);
  const sim::Projection cur = sim::project(rc.left, rc.start, rc.points);
  // No reference yet.
  control::ServoStep s = servo.step(cur.points_px, rc.left.k);
  EXPECT_EQ(s.status, ServoStatus::kInvalidInput);
  ASSERT_EQ(servo.setReference(ref.points_px, rc.right.k, ref.depths_m), "");
  // Wrong number of points.
  std::vector<Eigen::Vector2d> fewer(cur.points_px.begin(), cur.points_px.end() - 1);
  s = servo.step(fewer, rc.left.k);
  EXPECT_EQ(s.status, ServoStatus::kInvalidInput);
  EXPECT_NE(s.message.find("matched one to one"), std::string::npos) << s.message;
  // A terminal status sticks, with a zero velocity, until the next reference.
  s = servo.step(cur.points_px, rc.left.k);
  EXPECT_EQ(s.status, ServoStatus::kInvalidInput);
  EXPECT_TRUE(s.velocity.isZero());
  ASSERT_EQ(servo.setReference(ref.points_px, rc.right.k, ref.depths_m), "");
  for (int i = 0; i < 2; ++i) {
    s = servo.step(cur.points_px, rc.left.k, cur.depths_m);  // the camera does not move: |e| stays
    EXPECT_EQ(s.status, ServoStatus::kRunning) << s.message;
    EXPECT_GT(s.velocity.norm(), 0.0);
  }
  s = servo.step(cur.points_px, rc.left.k, cur.depths_m);
  EXPECT_EQ(s.status, ServoStatus::kMaxIterations) << s.message;
  EXPECT_TRUE(s.velocity.isZero());
  // Collinear reference: refused.
  std::vector<Eigen::Vector2d> line;
  for (int i = 0; i < 10; ++i) line.emplace_back(10.0 + 3.0 * i, 20.0 + 2.0 * i);
  EXPECT_NE(servo.setReference(line, rc.right.k), "");
}

}  // namespace
