// Loop candidates (gating, ranking, recency), loop verification on rendered revisits against the simulator's true
// poses, planted false loops over a rippled seabed, bad input.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <functional>
#include <iostream>
#include <limits>
#include <memory>
#include <stdexcept>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>

#include "exocet_common/camera_model.h"
#include "exocet_mosaic/graph/loop_candidates.h"
#include "exocet_mosaic/graph/loop_verifier.h"
#include "exocet_mosaic/graph/pose_graph.h"
#include "exocet_mosaic/sim/imaging_config.h"
#include "exocet_mosaic/sim/procedural_seabed.h"
#include "exocet_mosaic/sim/seabed_renderer.h"
#include "exocet_mosaic/sim/seabed_texture.h"
#include "loop_scene.h"

namespace exocet_mosaic {
namespace graph {
namespace {

using namespace testing;

LoopKeyFrame keyFrame(int64_t id, double stamp_s, double e_m, double n_m, double yaw_rad, double sigma_m) {
  LoopKeyFrame k;
  k.id = id;
  k.stamp_s = stamp_s;
  k.pose.position_en_m = Eigen::Vector2d(e_m, n_m);
  k.pose.yaw_rad = yaw_rad;
  k.position_cov_m2 = Eigen::Matrix2d::Identity() * sigma_m * sigma_m;
  k.camera_height_m = 2.5;  // footprint 2.89 m x 2.17 m
  k.camera = smallCamera();
  return k;
}

// ---- Candidates ---------------------------------------------------------------------------------------------

TEST(LoopCandidates, FootprintFollowsTheYawAndTheCameraAxes) {
  // Yaw 0: the key frame's x (image up) points east; the image's top-left corner is ahead and to the left (north).
  const auto c = footprintCorners(smallCamera(), Pose2d{Eigen::Vector2d(10, 20), 0.0}, 2.5);
  EXPECT_NEAR(c[0].x(), 10 + 2.5 * 144 / smallCamera().fy_px, 1e-9);
  EXPECT_NEAR(c[0].y(), 20 + 2.5 * 192 / smallCamera().fx_px, 1e-9);
  // Yaw 90 deg: ahead is north.
  const auto d = footprintCorners(smallCamera(), Pose2d{Eigen::Vector2d(0, 0), M_PI / 2}, 2.5);
  EXPECT_GT(d[0].y(), 0.0);
  EXPECT_LT(d[0].x(), 0.0);
}

TEST(LoopCandidates, GatingRecencyAndRanking) {
  LoopCandidateConfig config;
  config.min_separation_s = 20.0;
  config.min_separation_keyframes = 5;
  config.min_overlap_fraction = 0.3;
  LoopCandidateFinder finder(config);
  // The outbound line: key frames every 1 m eastwards, 1 s apart, accurate to 5 cm (start of the dive).
  for (int i = 0; i < 20; ++i) finder.addKeyFrame(keyFrame(i, i, i * 1.0, 0.0, 0.0, 0.05));
  // Recent key frames (to make the new one "recent" for ids 15..19), then the return.
  // The new key frame truly above x = 7.0 (between ids 6, 7, 8), but its estimate is 2.6 m off across the track
  // (north), with a 1 m 1-sigma: its footprint (2.17 m across) does not overlap at the estimate.
  LoopKeyFrame query = keyFrame(100, 60.0, 7.0, 2.6, M_PI, 1.0);
  std::vector<LoopCandidate> found = finder.candidates(query);
  ASSERT_FALSE(found.empty());
  bool has_truth = false;
  for (const LoopCandidate& c : found) has_truth |= c.id == 7;
  EXPECT_TRUE(has_truth) << "the true neighbour is missed with a matching covariance";
  EXPECT_LE(int(found.size()), config.max_candidates);
  // Same error, claimed accurate to 5 cm: nothing plausible.
  query.position_cov_m2 = Eigen::Matrix2d::Identity() * 0.0025;
  EXPECT_TRUE(finder.candidates(query).empty());

  // Ranking at the estimate: exact position over id 7 -> 7 first, then 6 and 8 (1 m off), then 5, 9.
  query = keyFrame(101, 61.0, 7.0, 0.0, M_PI, 0.05);
  found = finder.candidates(query);
  ASSERT_GE(found.size(), 3u);
  EXPECT_EQ(found[0].id, 7);
  EXPECT_TRUE((found[1].id == 6 && found[2].id == 8) || (found[1].id == 8 && found[2].id == 6));
  for (size_t i = 1; i < found.size(); ++i) EXPECT_GE(found[i - 1].overlap_at_estimate, found[i].overlap_at_estimate);

  // Far: 15 m north with 1 m sigma.
  EXPECT_TRUE(finder.candidates(keyFrame(102, 62.0, 7.0, 15.0, 0.0, 1.0)).empty());

  // Recent: a key frame at 19 s over x = 17 finds no key frame 14..18 (within 20 s and 5 key frames).
  LoopCandidateFinder recent(config);
  for (int i = 0; i < 20; ++i) recent.addKeyFrame(keyFrame(i, i, i * 0.3, 0.0, 0.0, 0.05));
  const std::vector<LoopCandidate> none = recent.candidates(keyFrame(20, 20.0, 19 * 0.3, 0.0, 0.0, 0.05));
  EXPECT_TRUE(none.empty()) << "a recent key frame is a chain neighbour, not a loop";
  // 25 s later: the early key frames within reach are found.
  const std::vector<LoopCandidate> later = recent.candidates(keyFrame(21, 25.0, 0.3, 0.0, 0.0, 0.05));
  ASSERT_FALSE(later.empty());
  for (const LoopCandidate& c : later) EXPECT_LT(c.id, 5);
}

TEST(LoopCandidates, GridStaysFastWithTenThousandKeyFrames) {
  LoopCandidateFinder finder;
  // A lawnmower of 100 lines x 100 key frames, 1 m apart along, 2 m between lines.
  int64_t id = 0;
  for (int line = 0; line < 100; ++line)
    for (int i = 0; i < 100; ++i, ++id)
      finder.addKeyFrame(keyFrame(id, id * 2.0, (line % 2 ? 99 - i : i) * 1.0, line * 2.0, 0.0, 0.5));
  const auto start = std::chrono::steady_clock::now();
  size_t total = 0;
  for (int q = 0; q < 100; ++q) total += finder.candidates(keyFrame(id + q, id * 2.0 + q, q, 50.0, 0.0, 0.5)).size();
  const double per_query_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count() / 100.0;
  std::cout << "10000 key frames: " << per_query_ms << " ms per query, " << total << " candidates\n";
  EXPECT_GT(total, 100u);
  EXPECT_LT(per_query_ms, 20.0);
}

TEST(LoopCandidates, BadInput) {
  LoopCandidateConfig bad;
  bad.gate_chi2 = -1;
  EXPECT_THROW({ LoopCandidateFinder f(bad); }, std::invalid_argument);
  LoopCandidateFinder finder;
  LoopKeyFrame k = keyFrame(1, 1.0, 0, 0, 0, 0.1);
  k.pose.position_en_m.x() = std::nan("");
  EXPECT_THROW(finder.addKeyFrame(k), std::invalid_argument);
  k = keyFrame(1, 1.0, 0, 0, 0, 0.1);
  k.position_cov_m2(0, 1) = std::numeric_limits<double>::infinity();
  EXPECT_THROW(finder.addKeyFrame(k), std::invalid_argument);
  k = keyFrame(1, 1.0, 0, 0, 0, 0.1);
  k.position_cov_m2(0, 0) = -1.0;
  EXPECT_THROW(finder.candidates(k), std::invalid_argument);
  k = keyFrame(1, 1.0, 0, 0, 0, 0.1);
  k.camera_height_m = 0.0;
  try {
    finder.addKeyFrame(k);
    ADD_FAILURE() << "no throw";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("camera_height_m"), std::string::npos) << e.what();
  }
  finder.addKeyFrame(keyFrame(2, 2.0, 0, 0, 0, 0.1));
  EXPECT_THROW(finder.addKeyFrame(keyFrame(2, 3.0, 0, 0, 0, 0.1)), std::invalid_argument);  // id not increasing
}

// ---- Rendered revisits ----------------------------------------------------------------------------------------

TEST(LoopVerifier, SiftKeypointsAreUnbiased) {
  // A pixel (u, v) is (w - 1 - u, h - 1 - v) in the image turned by 180 deg (exactly): a keypoint bias b shows as
  // u + u_turned = w - 1 + 2 b.
  sim::ProceduralSeabedConfig seabed;
  const Scene scene(seabed, murkyLamp());
  const cv::Mat img = scene.render(TruePose{0, 0, 2.5, 0.0}, 0);
  cv::Mat turned;
  cv::rotate(img, turned, cv::ROTATE_180);
  for (double offset : {0.0, LoopVerifierConfig().sift_offset_px}) {
    LoopVerifierConfig config;
    config.sift_offset_px = offset;
    const LoopVerifier verifier(config);
    const LoopFeatures a = verifier.features(img), b = verifier.features(turned);
    std::vector<std::vector<cv::DMatch>> knn;
    cv::BFMatcher(cv::NORM_L2).knnMatch(a.descriptors, b.descriptors, knn, 2);
    Eigen::Vector2d sum = Eigen::Vector2d::Zero();
    int n = 0;
    for (const auto& m : knn) {
      if (m.size() < 2 || m[0].distance > 0.7 * m[1].distance) continue;
      const cv::Point2f p = a.keypoints[m[0].queryIdx].pt, q = b.keypoints[m[0].trainIdx].pt;
      const Eigen::Vector2d d(p.x + q.x - (img.cols - 1), p.y + q.y - (img.rows - 1));
      if (d.norm() > 2.0) continue;
      sum += 0.5 * d;
      ++n;
    }
    ASSERT_GT(n, 100);
    const Eigen::Vector2d bias = sum / n;
    std::cout << "SIFT keypoint bias with offset " << offset << ": " << bias.transpose() << " px (" << n << ")\n";
    if (offset == 0.0) {
      EXPECT_GT(bias.norm(), 0.1) << "OpenCV's SIFT no longer biased: set sift_offset_px to 0";
    } else {
      EXPECT_LT(bias.norm(), 0.05);
    }
  }
}

TEST(LoopVerifier, OutAndBackRevisitsMatchTheTruePoses) {
  const auto start = std::chrono::steady_clock::now();
  sim::ProceduralSeabedConfig seabed;
  seabed.seed = 20260602;
  const Scene scene(seabed, murkyLamp());
  LoopVerifier verifier;
  // An out-and-back line at heading 75 deg (ENU yaw 15 deg): outbound frames every 1.5 m, the return 180 deg later
  // over the same places, 0.1-0.4 m off the line, at other heights, rolls and pitches.
  const double yaw_out = 15.0 * M_PI / 180.0;
  const Eigen::Vector2d along(std::cos(yaw_out), std::sin(yaw_out)), across(-along.y(), along.x());
  int pairs = 0;
  double worst_pos_m = 0.0, worst_yaw_deg = 0.0, worst_sigma = 0.0;
  for (int k = 0; k < 4; ++k) {
    const Eigen::Vector2d p_out = 1.5 * k * along;
    const Eigen::Vector2d p_ret = p_out + (0.3 - 0.1 * k) * along + (0.1 + 0.1 * k) * across;
    const TruePose out{p_out.x(), p_out.y(), 2.5 + 0.05 * k, yaw_out, 0.01 * k, -0.02};
    const TruePose ret{p_ret.x(), p_ret.y(), 2.6 - 0.08 * k, yaw_out + M_PI + 0.05 * (k - 1.5), -0.015, 0.02};
    const cv::Mat g_out = scene.render(out, k), g_ret = scene.render(ret, 100 + k);
    const LoopVerification v = verifier.verify(g_out, out.view(), g_ret, ret.view());
    const RelativePose2d truth = between(out.pose2d(), ret.pose2d());
    const Eigen::Vector3d e(v.new_in_old.translation_m.x() - truth.translation_m.x(),
                            v.new_in_old.translation_m.y() - truth.translation_m.y(),
                            wrapAngle(v.new_in_old.yaw_rad - truth.yaw_rad));
    const double mahalanobis = std::sqrt(e.dot(v.covariance.inverse() * e));
    std::cout << "pair " << k << ": " << (v.accepted ? "accepted" : "REFUSED: " + v.reason) << ", " << v.inliers << "/"
              << v.matches << " inliers, hull " << v.hull_fraction << ", fb " << v.forward_backward_px << " px, rms "
              << v.rms_residual_px << " px, scale " << v.scale << "; error " << 1000 * e.head<2>().norm() << " mm, "
              << e.z() * 180 / M_PI << " deg; sigma " << 1000 * std::sqrt(v.covariance(0, 0)) << " mm, "
              << std::sqrt(v.covariance(2, 2)) * 180 / M_PI << " deg; Mahalanobis " << mahalanobis << "\n";
    EXPECT_TRUE(v.accepted) << v.reason;
    if (!v.accepted) continue;
    ++pairs;
    EXPECT_LT(e.head<2>().norm(), 0.03);
    EXPECT_LT(std::abs(e.z()), 1.0 * M_PI / 180.0);
    EXPECT_LT(mahalanobis, std::sqrt(14.16)) << "beyond the 3-sigma (99.7 %, 3 dof) gate of the covariance";
    worst_pos_m = std::max(worst_pos_m, e.head<2>().norm());
    worst_yaw_deg = std::max(worst_yaw_deg, std::abs(e.z()) * 180 / M_PI);
    worst_sigma = std::max(worst_sigma, mahalanobis);
  }
  EXPECT_EQ(pairs, 4);
  std::cout << "revisits: " << pairs << "/4 accepted, worst error " << 1000 * worst_pos_m << " mm, " << worst_yaw_deg
            << " deg, worst Mahalanobis " << worst_sigma << ", "
            << std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() << " s\n";
}

TEST(LoopVerifier, PlantedFalseLoopsOverRipplesAreRefused) {
  const auto start = std::chrono::steady_clock::now();
  sim::ProceduralSeabedConfig seabed;
  seabed.seed = 77;
  seabed.ripple_coverage = 1.0;
  seabed.ripple_contrast = 1.0;
  seabed.ripple_wavelength_m = 0.12;
  seabed.ripple_direction_deg = 0.0;  // crests along north: across the ripples is east
  seabed.sediment_contrast = 0.1;
  seabed.rock_density_per_m2 = 0.0;
  seabed.shell_density_per_m2 = 0.5;
  seabed.burrow_density_per_m2 = 0.5;
  const Scene scene(seabed, murkyLamp());
  LoopVerifier verifier;
  // Places 1.2 m apart (10 ripple wavelengths: the crests line up), seen from 0.8 m: footprints 0.92 m x 0.69 m,
  // no overlap. Pairs: across and along the ripples, at the same heading and at 180 deg.
  struct Planted {
    TruePose a, b;
  };
  std::vector<Planted> planted;
  for (int k = 0; k < 3; ++k) {
    const double x0 = 3.0 * k, yaw = 0.3 * k;
    planted.push_back({{x0, 0.0, 0.8, yaw}, {x0 + 1.2, 0.0, 0.8, yaw}});          // across, same heading
    planted.push_back({{x0, 0.0, 0.8, yaw}, {x0 + 1.2, 0.0, 0.82, yaw + M_PI}});  // across, revisit
    planted.push_back({{x0, 0.0, 0.8, yaw}, {x0, 1.2, 0.8, yaw}});                // along
    planted.push_back({{x0, 0.0, 0.8, yaw}, {x0 + 0.1, 1.2, 0.78, yaw + M_PI}});  // along, revisit
  }
  // The same seabed is registrable: a true revisit over it is accepted (so the refusals below are not for want of
  // texture).
  {
    const TruePose a{20.0, 0.0, 0.8, 0.2}, b{20.15, 0.1, 0.82, 0.2 + M_PI};
    const LoopVerification v = verifier.verify(scene.render(a, 500), a.view(), scene.render(b, 501), b.view());
    const RelativePose2d truth = between(a.pose2d(), b.pose2d());
    std::cout << "true revisit over ripples: " << (v.accepted ? "accepted" : "REFUSED: " + v.reason) << ", "
              << v.inliers << "/" << v.matches << " inliers, error "
              << 1000 * (v.new_in_old.translation_m - truth.translation_m).norm() << " mm\n";
    EXPECT_TRUE(v.accepted) << v.reason;
    EXPECT_LT((v.new_in_old.translation_m - truth.translation_m).norm(), 0.01);
  }
  // Defence in depth: the same pairs through a verifier without the inlier count and fraction tests, so that the
  // later tests (overlap, spread, similarity, forward-backward, residual) and the pose graph's switch are exercised.
  LoopVerifierConfig lax_config;
  lax_config.min_inliers = 4;
  lax_config.min_inlier_fraction = 0.0;
  const LoopVerifier lax(lax_config);
  int accepted = 0, refused_by_verifier = 0, rejected_by_graph = 0;
  int lax_accepted = 0, lax_refused = 0, lax_rejected_by_graph = 0;
  // Second line of defence: the pose graph's switchable loop, against an accurate chain between the two.
  auto graphAccepts = [](const Planted& p, const LoopVerification& v) {
    PoseGraph graph;
    graph.addKeyFrame(0, 0.0, p.a.pose2d());
    graph.addKeyFrame(1, 1.0, p.b.pose2d());
    graph.addOdometry(0, 1, between(p.a.pose2d(), p.b.pose2d()), Eigen::Vector3d(1e-4, 1e-4, 1e-4).asDiagonal());
    graph.addPositionFix(0.0, p.a.pose2d().position_en_m, Eigen::Matrix2d::Identity() * 1e-4);
    graph.addHeading(0, p.a.yaw_rad, 0.01);
    const int loop = graph.addLoop(0, 1, v.new_in_old, v.covariance);
    graph.solveFull();
    return graph.loopAccepted(loop);
  };
  int frame = 0;
  for (const Planted& p : planted) {
    // The footprints truly do not overlap: no candidate even with a tiny overlap threshold and exact positions.
    LoopCandidateConfig exact;
    exact.min_separation_s = 0.0;
    exact.min_separation_keyframes = 0;
    exact.min_overlap_fraction = 1e-6;
    exact.gate_sigma_yaw = 0.0;
    LoopCandidateFinder finder(exact);
    LoopKeyFrame ka = keyFrame(0, 0.0, 0, 0, 0, 0.0), kb = keyFrame(1, 1.0, 0, 0, 0, 0.0);
    ka.pose = p.a.pose2d();
    kb.pose = p.b.pose2d();
    ka.camera_height_m = p.a.height_m;
    kb.camera_height_m = p.b.height_m;
    finder.addKeyFrame(ka);
    ASSERT_TRUE(finder.candidates(kb).empty()) << "the planted pair's footprints overlap";

    const cv::Mat ga = scene.render(p.a, frame), gb = scene.render(p.b, frame + 1);
    frame += 2;
    const LoopVerification v = verifier.verify(ga, p.a.view(), gb, p.b.view());
    if (!v.accepted) {
      ++refused_by_verifier;
      EXPECT_FALSE(v.reason.empty());
      std::cout << "false loop refused by the verifier: " << v.reason << "\n";
    } else if (graphAccepts(p, v)) {
      ++accepted;
      ADD_FAILURE() << "a false loop got through both defences: " << v.new_in_old.translation_m.transpose();
    } else {
      ++rejected_by_graph;
      std::cout << "false loop accepted by the verifier (" << v.inliers << " inliers), rejected by the pose graph\n";
    }
    const LoopVerification l = lax.verify(ga, p.a.view(), gb, p.b.view());
    if (!l.accepted) {
      ++lax_refused;
      std::cout << "  without the inlier tests: refused: " << l.reason << "\n";
    } else if (!graphAccepts(p, l)) {
      ++lax_rejected_by_graph;
      std::cout << "  without the inlier tests: accepted (" << l.inliers << " inliers), rejected by the pose graph\n";
    } else {
      ++lax_accepted;
      std::cout << "  without the inlier tests: accepted and kept by the pose graph\n";
    }
  }
  std::cout << "planted false loops: " << planted.size() << ", refused by the verifier " << refused_by_verifier
            << ", rejected by the pose graph " << rejected_by_graph << ", accepted " << accepted
            << "; without the inlier tests: refused " << lax_refused << ", rejected by the pose graph "
            << lax_rejected_by_graph << ", accepted " << lax_accepted << "; "
            << std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() << " s\n";
  EXPECT_EQ(accepted, 0);
  EXPECT_EQ(refused_by_verifier + rejected_by_graph, int(planted.size()));
  EXPECT_EQ(lax_accepted, 0) << "the later tests and the pose graph alone let a false loop through";
}

TEST(LoopVerifier, BadInput) {
  LoopVerifierConfig bad;
  bad.ratio = 1.5;
  try {
    LoopVerifier v(bad);
    ADD_FAILURE() << "no throw";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("ratio"), std::string::npos) << e.what();
  }
  LoopVerifier verifier;
  const TruePose p{0, 0, 2.5, 0.0};
  const LoopView view = p.view();
  const cv::Mat good(view.image_size, CV_8UC1, cv::Scalar(100));
  auto expectThrowNaming = [](const std::function<void()>& f, const std::string& word) {
    try {
      f();
      ADD_FAILURE() << "no throw, expected one naming " << word;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(word), std::string::npos) << e.what();
    }
  };
  expectThrowNaming([&] { verifier.verify(cv::Mat(), view, good, view); }, "empty");
  expectThrowNaming([&] { verifier.verify(good, view, cv::Mat(100, 100, CV_8UC1), view); }, "100x100");
  expectThrowNaming([&] { verifier.verify(good, view, cv::Mat(view.image_size, CV_8UC3), view); }, "CV_8UC1");
  LoopView v2 = view;
  v2.camera_height_m = std::nan("");
  expectThrowNaming([&] { verifier.verify(good, view, good, v2); }, "camera_height_m");
  v2 = view;
  v2.camera_matrix(0, 2) = std::numeric_limits<double>::infinity();
  expectThrowNaming([&] { verifier.verify(good, v2, good, view); }, "camera_matrix");
  v2 = view;
  v2.level_from_camera = Eigen::Quaterniond(std::nan(""), 0, 0, 0);
  expectThrowNaming([&] { verifier.verify(good, view, good, v2); }, "level_from_camera");
  v2 = view;
  v2.level_from_camera = Eigen::Quaterniond::Identity();  // looking up
  expectThrowNaming([&] { verifier.verify(good, view, good, v2); }, "does not look down");
  // A featureless pair is refused, not thrown.
  const LoopVerification r = verifier.verify(good, view, good, view);
  EXPECT_FALSE(r.accepted);
  EXPECT_FALSE(r.reason.empty());
}

}  // namespace
}  // namespace graph
}  // namespace exocet_mosaic
