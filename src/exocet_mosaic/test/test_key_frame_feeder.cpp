// KeyFrameFeeder: key frames and odometry factors from the fusion's image motions into the pose graph.
#include <cmath>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "exocet_mosaic/graph/key_frame_feeder.h"

namespace {

using namespace exocet_mosaic::graph;

/// A camera track: position and ENU yaw at 10 images/s.
struct Track {
  std::vector<double> stamps_s;
  std::vector<Eigen::Vector2d> positions_en_m;
  std::vector<double> yaws_rad;
};

/// Out along a line at `heading_rad` (ENU), a U-turn on a half circle of `turn_radius_m`, and back.
Track outAndBack(double length_m, double heading_rad, double turn_radius_m, double speed_mps) {
  Track t;
  const double dt = 0.1;
  const Eigen::Vector2d along(std::cos(heading_rad), std::sin(heading_rad));
  const Eigen::Vector2d left(-along.y(), along.x());
  const double turn_length = M_PI * turn_radius_m;
  const double total = 2.0 * length_m + turn_length;
  for (double s = 0.0, time = 1000.0; s <= total; s += speed_mps * dt, time += dt) {
    Eigen::Vector2d p;
    double yaw;
    if (s <= length_m) {
      p = along * s;
      yaw = heading_rad;
    } else if (s <= length_m + turn_length) {
      const double a = (s - length_m) / turn_radius_m;  // counter-clockwise about the turn's centre
      const Eigen::Vector2d centre = along * length_m + left * turn_radius_m;
      p = centre - left * turn_radius_m * std::cos(a) + along * turn_radius_m * std::sin(a);
      yaw = heading_rad + a;
    } else {
      p = along * (length_m - (s - length_m - turn_length)) + left * 2.0 * turn_radius_m;
      yaw = heading_rad + M_PI;
    }
    t.stamps_s.push_back(time);
    t.positions_en_m.push_back(p);
    t.yaws_rad.push_back(wrapAngle(yaw));
  }
  return t;
}

double rms(const std::vector<double>& errors) {
  double s = 0.0;
  for (double e : errors) s += e * e;
  return std::sqrt(s / std::max<size_t>(1, errors.size()));
}

BackgroundPoseGraphConfig quietGraph() {
  BackgroundPoseGraphConfig c;
  c.graph.max_solver_time_s = 5.0;
  return c;
}

TEST(KeyFrameFeeder, NoiseFreeMotionsGiveTheTrackAtTheKeyFrames) {
  const Track t = outAndBack(6.0, 0.5, 1.0, 0.4);
  BackgroundPoseGraph graph(quietGraph());
  KeyFrameFeeder feeder(KeyFrameFeederConfig(), &graph);
  feeder.start(t.stamps_s[0], t.positions_en_m[0], t.yaws_rad[0]);
  std::vector<size_t> key_image{0};
  for (size_t i = 1; i < t.stamps_s.size(); ++i) {
    const auto id = feeder.addImageMotion(t.stamps_s[i], t.positions_en_m[i] - t.positions_en_m[i - 1],
                                          Eigen::Matrix2d::Identity() * 1e-6,
                                          wrapAngle(t.yaws_rad[i] - t.yaws_rad[i - 1]));
    if (id) key_image.push_back(i);
  }
  ASSERT_TRUE(graph.waitIdle(30.0));
  const auto snapshot = graph.snapshot();
  ASSERT_EQ(snapshot->key_frames.size(), key_image.size());
  // About one key frame per keyframe_distance_m of track.
  EXPECT_NEAR(double(key_image.size()), (12.0 + M_PI) / 0.3, 5.0);
  for (size_t k = 0; k < key_image.size(); ++k) {
    const KeyFramePose* p = snapshot->find(static_cast<int64_t>(k));
    ASSERT_NE(p, nullptr);
    EXPECT_LT((p->pose.position_en_m - t.positions_en_m[key_image[k]]).norm(), 1e-6) << "key frame " << k;
    EXPECT_LT(std::abs(wrapAngle(p->pose.yaw_rad - t.yaws_rad[key_image[k]])), 1e-6) << "key frame " << k;
  }
}

TEST(KeyFrameFeeder, FixesBoundTheChainsDriftAndLoopsAlignThePasses) {
  // The image chain's random walk (1.5 cm per image, as its covariance says) drifts by decimetres over the dive;
  // 0.5 m USBL fixes at 1 Hz bound it; loops between the passes (the cross-pass registrations, 1 cm) make the two
  // passes agree.
  const Track t = outAndBack(12.0, 0.3, 0.5, 0.5);  // passes 1 m apart: the footprints overlap
  std::mt19937 rng(3);
  std::normal_distribution<double> unit(0.0, 1.0);
  auto run = [&](bool with_fixes, bool with_loops, double* pass_error_m) {
    BackgroundPoseGraph graph(quietGraph());
    KeyFrameFeeder feeder(KeyFrameFeederConfig(), &graph);
    rng.seed(3);
    feeder.start(t.stamps_s[0], t.positions_en_m[0], t.yaws_rad[0]);
    std::vector<size_t> key_image{0};
    const double step_sigma_m = 0.015;
    for (size_t i = 1; i < t.stamps_s.size(); ++i) {
      const Eigen::Vector2d d = (t.positions_en_m[i] - t.positions_en_m[i - 1]) +
                                Eigen::Vector2d(unit(rng), unit(rng)) * step_sigma_m;
      const auto id = feeder.addImageMotion(t.stamps_s[i], d, Eigen::Matrix2d::Identity() * step_sigma_m * step_sigma_m,
                                            wrapAngle(t.yaws_rad[i] - t.yaws_rad[i - 1]) + 0.002 * unit(rng),
                                            t.yaws_rad[i] + 0.01 * unit(rng), 0.01);
      if (id) key_image.push_back(i);
      if (with_fixes && i % 10 == 0)
        feeder.addPositionFix(t.stamps_s[i], t.positions_en_m[i] + Eigen::Vector2d(unit(rng), unit(rng)) * 0.5,
                              Eigen::Matrix2d::Identity() * 0.25);
    }
    // Loops: each return key frame to the outbound key frame nearest to it in truth (within 1.2 m).
    std::vector<std::pair<size_t, size_t>> loops;  // (outbound key index, return key index)
    const size_t half = key_image.size() / 2;
    for (size_t b = half; b < key_image.size(); ++b) {
      size_t best = 0;
      double best_d = 1e300;
      for (size_t a = 0; a + 10 < b && a < half; ++a) {
        const double dist = (t.positions_en_m[key_image[a]] - t.positions_en_m[key_image[b]]).norm();
        if (dist < best_d) best_d = dist, best = a;
      }
      if (best_d < 1.2) loops.emplace_back(best, b);
    }
    if (with_loops) {
      for (const auto& [a, b] : loops) {
        Pose2d pa{t.positions_en_m[key_image[a]], t.yaws_rad[key_image[a]]};
        Pose2d pb{t.positions_en_m[key_image[b]], t.yaws_rad[key_image[b]]};
        RelativePose2d delta = between(pa, pb);
        delta.translation_m += Eigen::Vector2d(unit(rng), unit(rng)) * 0.01;
        delta.yaw_rad += 0.002 * unit(rng);
        graph.addLoop(int64_t(a), int64_t(b), delta, Eigen::Vector3d(1e-4, 1e-4, 4e-6).asDiagonal());
      }
    }
    EXPECT_TRUE(graph.waitIdle(60.0));
    const auto snapshot = graph.snapshot();
    int accepted = 0;
    for (char a : snapshot->loop_accepted) accepted += a;
    std::cout << "fixes " << with_fixes << " loops " << with_loops << ": " << accepted << "/"
              << snapshot->loop_accepted.size() << " loops accepted\n";
    // True loops: about 1 % fall outside the 99 % gate.
    if (with_loops) EXPECT_GE(accepted, int(0.9 * loops.size()));
    std::vector<double> errors, pass_errors;
    for (size_t k = 0; k < key_image.size(); ++k)
      errors.push_back((snapshot->find(int64_t(k))->pose.position_en_m - t.positions_en_m[key_image[k]]).norm());
    for (const auto& [a, b] : loops) {
      // How far the two passes disagree: the error of the graph's relative position against the truth.
      const Eigen::Vector2d found =
          snapshot->find(int64_t(b))->pose.position_en_m - snapshot->find(int64_t(a))->pose.position_en_m;
      const Eigen::Vector2d truth = t.positions_en_m[key_image[b]] - t.positions_en_m[key_image[a]];
      pass_errors.push_back((found - truth).norm());
    }
    EXPECT_GT(loops.size(), 20u);
    *pass_error_m = rms(pass_errors);
    return rms(errors);
  };
  double pass_chain = 0, pass_fixes = 0, pass_loops = 0;
  const double chain_only = run(false, false, &pass_chain);
  const double with_fixes = run(true, false, &pass_fixes);
  const double with_loops = run(true, true, &pass_loops);
  std::cout << "RMS position error: chain only " << chain_only << " m, with fixes " << with_fixes << " m, with loops "
            << with_loops << " m; passes disagree by " << pass_chain << ", " << pass_fixes << ", " << pass_loops
            << " m\n";
  EXPECT_GT(chain_only, 0.1);
  EXPECT_LT(with_fixes, 0.7 * chain_only);
  EXPECT_LT(with_loops, with_fixes);
  EXPECT_LT(pass_loops, 0.04);
  EXPECT_LT(pass_loops, 0.25 * pass_fixes);
}

TEST(KeyFrameFeeder, ARegistrationFailureMakesAKeyFrameTiedLoosely) {
  BackgroundPoseGraph graph(quietGraph());
  KeyFrameFeeder feeder(KeyFrameFeederConfig(), &graph);
  feeder.start(10.0, Eigen::Vector2d(0, 0), 0.0);
  for (int i = 1; i <= 5; ++i)
    feeder.addImageMotion(10.0 + 0.1 * i, Eigen::Vector2d(0.1, 0), Eigen::Matrix2d::Identity() * 1e-6, 0.0);
  const size_t before = feeder.keyFrames().size();
  // Fused displacement since the last key frame (at 0.3 m, made at 10.3 s).
  const Eigen::Vector2d last = feeder.keyFrames().back().initial.position_en_m;
  const int64_t id = feeder.addImageFailure(11.0, Eigen::Vector2d(0.9, 0.1) - last, 0.05);
  EXPECT_EQ(feeder.keyFrames().size(), before + 1);
  EXPECT_EQ(feeder.keyFrames().back().id, id);
  EXPECT_NEAR(feeder.keyFrames().back().initial.position_en_m.x(), 0.9, 1e-12);
  feeder.addImageMotion(11.1, Eigen::Vector2d(0.1, 0), Eigen::Matrix2d::Identity() * 1e-6, 0.0);
  ASSERT_TRUE(graph.waitIdle(30.0));
  EXPECT_TRUE(graph.snapshot()->last_error.empty()) << graph.snapshot()->last_error;
  EXPECT_NE(graph.snapshot()->find(id), nullptr);
}

TEST(KeyFrameFeeder, AOneSecondGapDoesNotLetTheRestFloatOnTheFixes) {
  // A straight track: exact image motions, then one second the fusion could not convert (no attitude), tied by the
  // fused displacement; the start known to 1 cm, noisy 0.5 m fixes at 1 Hz throughout. The part after the gap stays
  // on the track (a 1 m tie let it float with the fixes: 0.2 m off on the tiles benchmark dive).
  BackgroundPoseGraph graph(quietGraph());
  KeyFrameFeeder feeder(KeyFrameFeederConfig(), &graph);
  const Eigen::Vector2d velocity(0.5, 0.0);
  feeder.start(0.0, Eigen::Vector2d::Zero(), 0.0);
  feeder.addPositionFix(0.0, Eigen::Vector2d::Zero(), Eigen::Matrix2d::Identity() * 1e-4);
  std::mt19937 rng(4);
  std::normal_distribution<double> unit(0.0, 1.0);
  int64_t after_gap = -1;
  for (int i = 1; i <= 600; ++i) {  // 60 s at 10 images/s
    const double t = 0.1 * i;
    if (i % 10 == 0)
      feeder.addPositionFix(t, velocity * t + Eigen::Vector2d(unit(rng), unit(rng)) * 0.5,
                            Eigen::Matrix2d::Identity() * 0.25);
    if (i > 200 && i <= 210) continue;  // the gap: no image motion from 20.0 to 21.0 s
    if (i == 211) {
      const Eigen::Vector2d last = feeder.keyFrames().back().initial.position_en_m;
      after_gap = feeder.addImageFailure(t, velocity * t - last, 0.0);  // the fused displacement, exact here
      continue;
    }
    feeder.addImageMotion(t, velocity * 0.1, Eigen::Matrix2d::Identity() * 1e-8, 0.0, 0.0, 0.01);
  }
  ASSERT_TRUE(graph.waitIdle(60.0));
  const auto snapshot = graph.snapshot();
  ASSERT_TRUE(snapshot->last_error.empty()) << snapshot->last_error;
  double worst_m = 0, worst_before_m = 0;
  for (const KeyFramePose& k : snapshot->key_frames) {
    const double e = (k.pose.position_en_m - velocity * k.stamp_s).norm();
    double& worst = k.id >= after_gap ? worst_m : worst_before_m;
    worst = std::max(worst, e);
  }
  std::printf("graph off the track: %.4f m before the gap, %.4f m after\n", worst_before_m, worst_m);
  EXPECT_LT(worst_before_m, 0.01);
  // The tie (1 cm + 1 cm/s over the ~1.2 s since the last key frame) against 40 s of 0.5 m fixes (8 cm together):
  // the part after the gap is held to about 2 cm, 3 sigma 6 cm; the 5 cm + 5 cm/s tie left it 9.5 cm off here.
  EXPECT_LT(worst_m, 0.06);
}

TEST(KeyFrameFeeder, KeyFramesStopWaitingForADeadReckoningThatStopped) {
  // The dead reckoning stops after 5 s; the images go on for 10 minutes. The key frames waiting for a sample after
  // their stamp are those of the last 10 s only, not every key frame since it stopped.
  BackgroundPoseGraph graph(quietGraph());
  KeyFrameFeeder feeder(KeyFrameFeederConfig(), &graph);
  const Eigen::Vector2d velocity(0.0, 0.5);
  feeder.addDeadReckoning(-0.1, Eigen::Vector2d::Zero(), Eigen::Matrix2d::Identity() * 1e-4);
  feeder.start(0.0, Eigen::Vector2d::Zero(), M_PI / 2);
  size_t most_waiting = 0;
  for (int i = 1; i <= 6000; ++i) {
    const double t = 0.1 * i;
    if (t <= 5.0) feeder.addDeadReckoning(t, velocity * t, Eigen::Matrix2d::Identity() * 1e-4);
    feeder.addImageMotion(t, velocity * 0.1, Eigen::Matrix2d::Identity() * 1e-8, 0.0, M_PI / 2, 0.01);
    most_waiting = std::max(most_waiting, feeder.keyFramesAwaitingDeadReckoning());
  }
  ASSERT_GT(feeder.keyFrames().size(), 500u);
  // 0.5 m/s, a key frame every ~0.3 m (0.6 s): about 17 in 10 s.
  EXPECT_LE(most_waiting, 25u);
  EXPECT_GE(most_waiting, 10u) << "the key frames of the last 10 s still wait (a late dead reckoning places them)";
  EXPECT_TRUE(graph.waitIdle(60.0));
}

TEST(KeyFrameFeeder, TheDeadReckoningAnchorsTheGraphAndTiesItsKeyFrames) {
  // A straight track at 0.5 m/s heading north; exact image motions; USBL fixes 0.3 m east of the track all dive (the
  // average of a minute of 0.5 m fixes is off by about that much over short stretches); the dead reckoning at 5 Hz,
  // 1 cm east of the truth (its launch error), half a second behind the images, with a 3 s gap. The graph takes
  // the dead reckoning's start; the key frames in the gap have no tie. Without the dead reckoning the fixes alone
  // place it.
  for (const bool with_dr : {true, false}) {
  BackgroundPoseGraph graph(quietGraph());
  KeyFrameFeeder feeder(KeyFrameFeederConfig(), &graph);
  const Eigen::Vector2d velocity(0.0, 0.5), launch_error(0.01, 0.0), usbl_bias(0.3, 0.0);
  const double yaw = M_PI / 2;
  const auto dr = [&](double t) {
    if (with_dr && (t < 30.0 || t > 33.0)) feeder.addDeadReckoning(t, velocity * t + launch_error, Eigen::Matrix2d::Identity() * 1e-4);
  };
  for (int j = -5; j <= 0; ++j) dr(0.2 * j);
  feeder.start(0.0, Eigen::Vector2d(0.05, -0.05), yaw);
  int next_dr = 1;
  for (int i = 1; i <= 600; ++i) {
    const double t = 0.1 * i;
    if (i % 10 == 0)
      feeder.addPositionFix(t, velocity * t + usbl_bias, Eigen::Matrix2d::Identity() * 0.25);
    feeder.addImageMotion(t, velocity * 0.1, Eigen::Matrix2d::Identity() * 1e-8, 0.0, yaw, 0.01);
    for (; 0.2 * next_dr <= t - 0.5; ++next_dr) dr(0.2 * next_dr);
  }
  for (; 0.2 * next_dr <= 61.0; ++next_dr) dr(0.2 * next_dr);
  ASSERT_TRUE(graph.waitIdle(60.0));
  const auto snapshot = graph.snapshot();
  ASSERT_TRUE(snapshot->last_error.empty()) << snapshot->last_error;
  const double start_error_m = (snapshot->key_frames.front().pose.position_en_m - Eigen::Vector2d::Zero()).norm();
  double worst_m = 0;
  for (const KeyFramePose& k : snapshot->key_frames)
    worst_m = std::max(worst_m, (k.pose.position_en_m - velocity * k.stamp_s).norm());
  std::printf("%s the dead reckoning: graph off the track by %.4f m at the start, %.4f m at most\n",
              with_dr ? "with" : "without", start_error_m, worst_m);
  if (!with_dr) {
    EXPECT_FALSE(feeder.deadReckoningAnchored());
    EXPECT_EQ(feeder.deadReckoningFactors(), 0);
    EXPECT_GT(start_error_m, 0.2) << "the fixes' bias";
    continue;
  }
  // The anchor's own error (the launch, 1 cm east) plus the fixes' pull on it (0.3 m with the weight of 60 fixes of
  // 0.5 m, 240 m^-2, against the anchor's 10000 m^-2: 7 mm): 1.7 cm; the fixes alone: 0.3 m.
  EXPECT_LT(start_error_m, 0.02);
  // Further on, the image odometry's floor (2 mm per key frame) lets the track lean towards the fixes.
  EXPECT_LT(worst_m, 0.08);
  EXPECT_TRUE(feeder.deadReckoningAnchored());
  int64_t with_position = 0, in_gap = 0;
  for (const FeederKeyFrame& k : feeder.keyFrames()) {
    const bool gap = k.stamp_s > 29.8 && k.stamp_s < 33.2;
    if (gap) {
      ++in_gap;
      EXPECT_FALSE(k.dead_reckoning_en_m) << "key frame at " << k.stamp_s << " s";
    } else {
      ASSERT_TRUE(k.dead_reckoning_en_m) << "key frame at " << k.stamp_s << " s";
      EXPECT_LT((*k.dead_reckoning_en_m - velocity * k.stamp_s - launch_error).norm(), 1e-9);
      ++with_position;
    }
  }
  EXPECT_GT(in_gap, 0);
  // Every key frame with a position is tied to the one before it, except the first and the first after the gap.
  EXPECT_EQ(feeder.deadReckoningFactors(), with_position - 2);
  }
}

TEST(KeyFrameFeeder, BadInputIsRefusedWithItsName) {
  BackgroundPoseGraph graph(quietGraph());
  KeyFrameFeederConfig bad;
  bad.keyframe_distance_m = 0.0;
  bad.gap_sigma_m = -1.0;
  EXPECT_NE(bad.validate().find("keyframe_distance_m"), std::string::npos);
  EXPECT_NE(bad.validate().find("gap_sigma_m"), std::string::npos);
  EXPECT_THROW(KeyFrameFeeder(bad, &graph), std::invalid_argument);
  EXPECT_THROW(KeyFrameFeeder(KeyFrameFeederConfig(), nullptr), std::invalid_argument);
  KeyFrameFeeder feeder(KeyFrameFeederConfig(), &graph);
  EXPECT_THROW(feeder.addImageMotion(1.0, Eigen::Vector2d(0.1, 0), Eigen::Matrix2d::Identity(), 0.0),
               std::invalid_argument);  // before start()
  feeder.start(1.0, Eigen::Vector2d(0, 0), 0.0);
  EXPECT_THROW(feeder.start(1.0, Eigen::Vector2d(0, 0), 0.0), std::invalid_argument);
  EXPECT_THROW(feeder.addImageMotion(1.1, Eigen::Vector2d(std::nan(""), 0), Eigen::Matrix2d::Identity(), 0.0),
               std::invalid_argument);
  Eigen::Matrix2d negative = Eigen::Matrix2d::Identity();
  negative(1, 1) = -1.0;
  try {
    feeder.addImageMotion(1.1, Eigen::Vector2d(0.1, 0), negative, 0.0);
    FAIL() << "a covariance that is not positive semi-definite must be refused";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("covariance"), std::string::npos) << e.what();
  }
  EXPECT_THROW(feeder.addPositionFix(2.0, Eigen::Vector2d(0, std::nan("")), Eigen::Matrix2d::Identity()),
               std::invalid_argument);
  EXPECT_THROW(feeder.addDeadReckoning(2.0, Eigen::Vector2d(0, std::nan("")), Eigen::Matrix2d::Identity()),
               std::invalid_argument);
  EXPECT_THROW(feeder.addDeadReckoning(2.0, Eigen::Vector2d(0, 0), Eigen::Matrix2d::Zero()), std::invalid_argument);
  KeyFrameFeederConfig bad_dr;
  bad_dr.dr_max_gap_s = 0.0;
  bad_dr.dr_noise_m2_per_m = -1.0;
  EXPECT_NE(bad_dr.validate().find("dr_max_gap_s"), std::string::npos);
  EXPECT_NE(bad_dr.validate().find("dr_noise_m2_per_m"), std::string::npos);
}

}  // namespace
