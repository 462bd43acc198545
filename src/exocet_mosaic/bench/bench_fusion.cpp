// Benchmark of the navigation fusion (2D3 sections 3.3 and 3.5): the report's out-and-back experiment (figure 5) on
// a simulated dive with ground truth. The simulator runs in-process (frames, navigation and truth captured from its
// sink, cached on disk under --output-dir/cache); consecutive frames are registered through registration_node's
// front-end (SequenceRegistrar: homography, method auto), and every sensor's records are fed, in arrival order, to
// fusion_node's front-end (FusionFrontEnd: attitude and altimeter histories, roll, pitch and range fitted over +-1 s
// at each image, metric conversion with the rig's camera, lever arms) and its navigation filter; the RTS smoother
// runs over the whole dive. Every track is scored against the true camera centre. Writes fusion.json.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <map>
#include <memory>
#include <optional>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include <boost/math/distributions/chi_squared.hpp>
#include <nlohmann/json.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>

#include "exocet_common/atomic_file.h"
#include "exocet_common/binary_cache.h"
#include "exocet_common/command_line.h"
#include "exocet_common/json_file.h"
#include "exocet_common/testing/paths.h"
#include "exocet_common/utm_grid.h"
#include "exocet_mosaic/fusion/cross_pass_smoother.h"
#include "exocet_mosaic/fusion/fusion_front_end.h"
#include "exocet_mosaic/fusion/metric_motion.h"
#include "exocet_mosaic/fusion/navigation_filter.h"
#include "exocet_mosaic/fusion/rts_smoother.h"
#include "exocet_mosaic/registration/motion_model.h"
#include "exocet_mosaic/registration/registration_config.h"
#include "exocet_mosaic/registration/sequence_registrar.h"
#include "exocet_mosaic/sim/dive_description.h"
#include "exocet_mosaic/sim/dive_synthesizer.h"
#include "exocet_mosaic/sim/navigation_sensors.h"
#include "exocet_mosaic/sim/vehicle_trajectory.h"

namespace {

using exocet_common::fnv1a;
using exocet_common::getValue;
using exocet_common::getVector;
using exocet_common::putValue;
using exocet_common::putVector;

using namespace exocet_mosaic;
using Clock = std::chrono::steady_clock;

double secondsSince(Clock::time_point start) { return std::chrono::duration<double>(Clock::now() - start).count(); }

// ---- The simulated dive, captured from the synthesizer's sink, and its cache ------------------------------------

struct CapturedDive {
  std::vector<cv::Mat> gray;  ///< CV_8UC1, one per frame (dropped frames left out)
  std::vector<double> frame_stamps_s;
  std::vector<Eigen::Isometry3d> world_from_camera;  ///< truth, UTM frame
  std::vector<double> gsd_m;                         ///< truth: ground sample distance
  std::vector<double> vehicle_yaw_rad;               ///< truth: ENU yaw of the vehicle
  std::vector<dive::ImuRecord> imu;
  std::vector<dive::AltitudeRecord> altitude;
  std::vector<dive::PoseRecord> dead_reckoning;
  std::vector<dive::FixRecord> usbl;
};

constexpr uint64_t kCacheMagic = 0x3245564944535546ULL;  // "FUSDIVE2" (DR carried with the accelerometers)

/// Plain-old-data copies of the records (Eigen members are trivially copyable; the rest are doubles).
void writeCache(const std::string& path, const CapturedDive& d) {
  // A cache is an optimisation: when it cannot be written the next run renders again.
  const std::string temporary = exocet_common::temporaryPathFor(path);
  {
    std::ofstream out(temporary, std::ios::binary | std::ios::trunc);
    putValue(out, kCacheMagic);
    putVector(out, d.frame_stamps_s);
    putVector(out, d.gsd_m);
    putVector(out, d.vehicle_yaw_rad);
    std::vector<Eigen::Matrix4d> poses;
    for (const auto& p : d.world_from_camera) poses.push_back(p.matrix());
    putVector(out, poses);
    putVector(out, d.imu);
    putVector(out, d.altitude);
    putVector(out, d.dead_reckoning);
    putVector(out, d.usbl);
    putValue(out, int32_t(d.gray.empty() ? 0 : d.gray[0].cols));
    putValue(out, int32_t(d.gray.empty() ? 0 : d.gray[0].rows));
    for (const cv::Mat& g : d.gray) {
      const cv::Mat c = g.isContinuous() ? g : g.clone();
      out.write(reinterpret_cast<const char*>(c.data), std::streamsize(c.total()));
    }
    if (!out) {
      std::error_code ignored;
      std::filesystem::remove(temporary, ignored);
      return;
    }
  }
  try {
    exocet_common::commitTemporaryFile(temporary, path);
  } catch (const std::runtime_error&) {
    std::error_code ignored;
    std::filesystem::remove(temporary, ignored);
  }
}

bool readCache(const std::string& path, CapturedDive* d) {
  std::ifstream in(path, std::ios::binary);
  uint64_t magic = 0;
  if (!getValue(in, &magic) || magic != kCacheMagic) return false;
  std::vector<Eigen::Matrix4d> poses;
  if (!getVector(in, &d->frame_stamps_s) || !getVector(in, &d->gsd_m) || !getVector(in, &d->vehicle_yaw_rad) ||
      !getVector(in, &poses) || !getVector(in, &d->imu) || !getVector(in, &d->altitude) ||
      !getVector(in, &d->dead_reckoning) || !getVector(in, &d->usbl))
    return false;
  for (const auto& m : poses) d->world_from_camera.emplace_back(m);
  int32_t width = 0, height = 0;
  if (!getValue(in, &width) || !getValue(in, &height)) return false;
  for (size_t i = 0; i < d->frame_stamps_s.size(); ++i) {
    cv::Mat g(height, width, CV_8UC1);
    if (!in.read(reinterpret_cast<char*>(g.data), std::streamsize(g.total()))) return false;
    d->gray.push_back(g);
  }
  return !d->gray.empty();
}

CapturedDive simulate(const sim::DiveDescription& dive, const std::string& cache_dir, int threads) {
  char name[64];
  std::snprintf(name, sizeof(name), "fusion_dive_%016llx.bin", static_cast<unsigned long long>(fnv1a(toYaml(dive))));
  const std::string path = cache_dir + "/" + name;
  CapturedDive d;
  if (readCache(path, &d)) {
    std::cout << "dive: " << d.gray.size() << " frames and navigation from the cache " << path << "\n";
    return d;
  }
  d = CapturedDive();
  sim::DiveSynthesisConfig config = dive.synthesis;
  config.threads = threads;
  sim::Seabed seabed = sim::makeSeabed(dive.seabed, config.seed);
  sim::DiveSynthesizer synth(config, seabed.texture.get(), seabed.relief.get());
  sim::DiveSink sink;
  sink.navigation.imu = [&](const dive::ImuRecord& r) { d.imu.push_back(r); };
  sink.navigation.altitude = [&](const dive::AltitudeRecord& r) { d.altitude.push_back(r); };
  sink.navigation.dead_reckoning = [&](const dive::PoseRecord& r) { d.dead_reckoning.push_back(r); };
  sink.navigation.usbl = [&](const dive::FixRecord& r) { d.usbl.push_back(r); };
  sink.frame = [&](const sim::FrameTruth& t) {
    if (t.dropped) return;
    cv::Mat gray;
    if (t.frame.image.channels() == 1 && t.frame.image.depth() == CV_8U)
      gray = t.frame.image.clone();
    else if (t.frame.image.channels() == 3)
      cv::cvtColor(t.frame.image, gray, t.frame.encoding == "rgb8" ? cv::COLOR_RGB2GRAY : cv::COLOR_BGR2GRAY);
    else
      t.frame.image.convertTo(gray, CV_8U, t.frame.image.depth() == CV_16U ? 1.0 / 256.0 : 1.0);
    d.gray.push_back(gray);
    d.frame_stamps_s.push_back(t.frame.stamp_s);
    d.world_from_camera.push_back(t.world_from_camera);
    d.gsd_m.push_back(t.ground_sample_distance_m);
    d.vehicle_yaw_rad.push_back(t.vehicle.yaw_rad);
  };
  const auto start = Clock::now();
  sink.progress = [&](int done, int total) {
    if (done % 200 == 0 || done == total)
      std::cout << "  rendered " << done << "/" << total << " frames, " << secondsSince(start) << " s\n";
  };
  synth.run(sink);
  const double seconds = secondsSince(start);
  std::cout << "dive: simulated " << d.gray.size() << " frames in " << seconds << " s\n";
  std::error_code error;
  std::filesystem::create_directories(cache_dir, error);
  if (!error) writeCache(path, d);
  return d;
}

// ---- Navigation records at a stamp --------------------------------------------------------------------------------

Eigen::Quaterniond attitudeAt(const std::vector<dive::ImuRecord>& imu, double stamp_s) {
  auto it = std::lower_bound(imu.begin(), imu.end(), stamp_s,
                             [](const dive::ImuRecord& r, double t) { return r.stamp_s < t; });
  if (it == imu.end()) return imu.back().orientation;
  if (it == imu.begin() || it->stamp_s == stamp_s) return it->orientation;
  const auto prev = it - 1;
  const double f = (stamp_s - prev->stamp_s) / (it->stamp_s - prev->stamp_s);
  return prev->orientation.slerp(f, it->orientation);
}

// ---- Scores -------------------------------------------------------------------------------------------------------

double rmse(const std::vector<Eigen::Vector2d>& estimate, const std::vector<Eigen::Vector2d>& truth,
            const std::vector<bool>* use = nullptr) {
  double sum = 0.0;
  int n = 0;
  for (size_t i = 0; i < estimate.size(); ++i) {
    if (use && !(*use)[i]) continue;
    if (!estimate[i].allFinite()) continue;
    sum += (estimate[i] - truth[i]).squaredNorm();
    ++n;
  }
  return n ? std::sqrt(sum / n) : std::nan("");
}

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return std::nan("");
  std::sort(v.begin(), v.end());
  const size_t i = std::min(v.size() - 1, static_cast<size_t>(std::floor(p * (v.size() - 1) + 0.5)));
  return v[i];
}

struct Misalignment {
  double median_gsd = std::nan(""), p95_gsd = std::nan("");
};

/// Return pass against the outbound pass: for each (return, nearest outbound) frame pair, the error of the estimated
/// relative position, in ground sample distances.
Misalignment misalignment(const std::vector<std::pair<int, int>>& pairs, const std::vector<Eigen::Vector2d>& estimate,
                          const std::vector<Eigen::Vector2d>& truth, const std::vector<double>& gsd_m) {
  std::vector<double> values;
  for (const auto& [ret, out] : pairs) {
    const Eigen::Vector2d e = (estimate[ret] - estimate[out]) - (truth[ret] - truth[out]);
    if (e.allFinite()) values.push_back(e.norm() / gsd_m[ret]);
  }
  return {percentile(values, 0.5), percentile(values, 0.95)};
}

// ---- Cross-pass registration: SIFT + RANSAC homography with its covariance ----------------------------------------

/// A return frame registered to an outbound frame (the vehicle heads the other way: the images are turned by about
/// 180 degrees, beyond the frame-to-frame registrars' range): SIFT features, ratio test, MAGSAC++ homography, and
/// the parameter covariance of a Gauss-Newton fit on the inliers (residual variance times (J^T J)^-1).
struct CrossRegistration {
  bool found = false;
  Eigen::VectorXd parameters;  ///< homography, centred on `centre_px` (motion_model.h)
  Eigen::MatrixXd covariance;
  Eigen::Vector2d centre_px = Eigen::Vector2d::Zero();
  int matches = 0, inliers = 0;
  double residual_px = 0.0;
};

struct SiftFeatures {
  std::vector<cv::KeyPoint> keypoints;
  cv::Mat descriptors;
};

SiftFeatures siftFeatures(const cv::Mat& gray) {
  static cv::Ptr<cv::SIFT> sift = cv::SIFT::create(2500);
  SiftFeatures f;
  sift->detectAndCompute(gray, cv::noArray(), f.keypoints, f.descriptors);
  return f;
}

CrossRegistration registerAcrossPasses(const SiftFeatures& a, const SiftFeatures& b, int width, int height) {
  CrossRegistration r;
  if (a.descriptors.empty() || b.descriptors.empty()) return r;
  std::vector<std::vector<cv::DMatch>> knn;
  cv::BFMatcher(cv::NORM_L2).knnMatch(a.descriptors, b.descriptors, knn, 2);
  std::vector<cv::Point2f> pa, pb;
  for (const auto& m : knn)
    if (m.size() == 2 && m[0].distance < 0.8f * m[1].distance) {
      pa.push_back(a.keypoints[m[0].queryIdx].pt);
      pb.push_back(b.keypoints[m[0].trainIdx].pt);
    }
  r.matches = static_cast<int>(pa.size());
  if (pa.size() < 30) return r;
  cv::Mat mask;
  const cv::Mat h = cv::findHomography(pa, pb, cv::USAC_MAGSAC, 1.0, mask, 10000, 0.9999);
  if (h.empty()) return r;
  Eigen::Matrix3d H;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) H(i, j) = h.at<double>(i, j);
  r.centre_px = Eigen::Vector2d(0.5 * (width - 1), 0.5 * (height - 1));
  const registration::MotionModel model = registration::MotionModel::kHomography;
  r.parameters = registration::parametersFromPixelMatrix(model, H, r.centre_px, width, height);
  Eigen::MatrixXd jtj = Eigen::MatrixXd::Zero(8, 8);
  double sum_sq = 0.0;
  for (size_t i = 0; i < pa.size(); ++i) {
    if (!mask.at<uchar>(int(i))) continue;
    const Eigen::Vector2d xa(pa[i].x, pa[i].y), xb(pb[i].x, pb[i].y);
    sum_sq += (registration::transferPoint(H, xa) - xb).squaredNorm();
    const Eigen::MatrixXd J =
        registration::warpJacobian(model, r.parameters, xa.x() - r.centre_px.x(), xa.y() - r.centre_px.y());
    jtj += J.transpose() * J;
    ++r.inliers;
  }
  if (r.inliers < 30 || r.inliers < 0.5 * r.matches) return r;
  const double sigma2 = sum_sq / (2.0 * r.inliers - 8.0);
  r.residual_px = std::sqrt(sigma2);
  r.covariance = sigma2 * jtj.inverse();
  r.found = r.covariance.allFinite();
  return r;
}

// ---- Filter runs: the sensors through the node's front-end ------------------------------------------------------

/// Half-width of the window over which the front-end fits roll, pitch and the altimeter range at each image
/// (fusion_node's ~view_half_window_s): an image's motion reaches the filter that long after its stamp.
constexpr double kViewHalfWindow_s = 1.0;
/// Frames of the simulated rig, as fusion_node finds them in tf.
const char* const kCameraFrame = "camera";
const char* const kAltimeterFrame = "altimeter";

/// One input of the fusion, as it arrives: what fusion_node gets from its topics.
struct NavEvent {
  enum Kind { kImage, kDeadReckoning, kFix, kAttitude, kAltitude } kind = kImage;
  double arrival_s = 0.0;
  double stamp_s = 0.0;
  int frame = -1;                                        ///< images: the current frame's index
  Eigen::Vector3d position_m = Eigen::Vector3d::Zero();  ///< dead reckoning, fixes: base_link in the UTM grid
  Eigen::Quaterniond orientation = Eigen::Quaterniond::Identity();  ///< dead reckoning, attitude: world from base
  double range_m = 0.0;                                             ///< altimeter
  Eigen::Matrix2d covariance = Eigen::Matrix2d::Identity();
};

/// Every input of one realisation of the sensors, in arrival order. The image motion of frame k arrives once its
/// view's window has passed (plus the registration's time).
std::vector<NavEvent> buildEvents(const CapturedDive& d, const exocet_common::UtmGrid& grid) {
  std::vector<NavEvent> events;
  const double t0 = d.frame_stamps_s.front();
  const double image_latency_s = kViewHalfWindow_s + 0.03;
  for (size_t k = 1; k < d.frame_stamps_s.size(); ++k) {
    NavEvent e;
    e.kind = NavEvent::kImage;
    e.stamp_s = d.frame_stamps_s[k];
    e.arrival_s = e.stamp_s + image_latency_s;
    e.frame = static_cast<int>(k);
    events.push_back(e);
  }
  for (const dive::ImuRecord& r : d.imu) {
    NavEvent e;
    e.kind = NavEvent::kAttitude;
    e.stamp_s = e.arrival_s = r.stamp_s;
    e.orientation = r.orientation;
    events.push_back(e);
  }
  for (const dive::AltitudeRecord& r : d.altitude) {
    if (!std::isfinite(r.range_m) || r.range_m <= 0.0) continue;  // fusion_node rejects these
    NavEvent e;
    e.kind = NavEvent::kAltitude;
    e.stamp_s = e.arrival_s = r.stamp_s;
    e.range_m = r.range_m;
    events.push_back(e);
  }
  for (const dive::PoseRecord& r : d.dead_reckoning) {
    if (r.stamp_s < t0) continue;
    NavEvent e;
    e.kind = NavEvent::kDeadReckoning;
    e.stamp_s = e.arrival_s = r.stamp_s;
    e.position_m = r.position_m;
    e.orientation = r.orientation;
    e.covariance = r.pose_covariance.block<2, 2>(0, 0);
    events.push_back(e);
  }
  for (const dive::FixRecord& f : d.usbl) {
    if (f.stamp_s <= t0) continue;
    NavEvent e;
    e.kind = NavEvent::kFix;
    e.stamp_s = f.stamp_s;
    e.arrival_s = f.arrival_s;
    const Eigen::Vector2d base_en = grid.toGrid(f.latitude_deg, f.longitude_deg);
    e.position_m = Eigen::Vector3d(base_en.x(), base_en.y(), f.altitude_m);
    e.covariance = f.horizontal_sigma_m * f.horizontal_sigma_m * Eigen::Matrix2d::Identity();
    events.push_back(e);
  }
  std::stable_sort(events.begin(), events.end(),
                   [](const NavEvent& a, const NavEvent& b) { return a.arrival_s < b.arrival_s; });
  return events;
}

struct FilterRun {
  std::vector<Eigen::Vector2d> filtered;  ///< at each frame, from the final log (each fix at its own stamp)
  std::vector<Eigen::Matrix2d> filtered_covariance;
  std::vector<Eigen::Vector2d> live;  ///< at each frame, as known when its image event had been processed
  std::vector<Eigen::Vector2d> smoothed;
  std::vector<Eigen::Matrix2d> smoothed_covariance;
  std::vector<int> frame_step;  ///< index of each frame's step in the log (-1: none)
  std::vector<fusion::FilterState> smoothed_states;
  std::vector<fusion::MetricMotion> motions;  ///< the front-end's metric motion of each pair (invalid: none)
  std::vector<std::optional<fusion::ViewGeometry>> views;  ///< the front-end's view of each frame
  std::map<double, Eigen::Vector2d> dr_at;        ///< dead-reckoning camera centre by stamp, as the front-end placed it
  std::vector<fusion::AbsoluteConstraint> fixes;  ///< the fixes moved to the camera, as the front-end gave them
  int events = 0;
  double filter_seconds = 0.0, smoother_seconds = 0.0;
  int fixes_rejected_at_arrival = 0, fixes_rejected_final = 0, fixes_applied_final = 0, recoveries = 0;
  long rewinds = 0;
  fusion::FilterState last;
  fusion::FilterLog log;
};

/// The front-end as fusion_node configures it from its parameters, for these sensors and this filter.
fusion::FusionFrontEndConfig frontEndConfig(const fusion::FilterConfig& filter,
                                            const sim::NavigationSensorConfig& nav) {
  fusion::FusionFrontEndConfig c;
  c.filter = filter;
  c.keep_log = true;
  c.view_half_window_s = kViewHalfWindow_s;
  c.altimeter_sigma_m = nav.altimeter_noise_m;
  c.default_camera_frame = kCameraFrame;
  return c;
}

/// Feeds `events` through a FusionFrontEnd, the object fusion_node runs: attitude and altimeter into its histories,
/// each pair's registration estimate (`estimates`, with the intrinsics `camera_matrix`) converted by it, dead
/// reckoning and fixes moved to the camera by it. `images` / `nav` select the sources; the attitude and the altimeter
/// always speak. The filter starts, as in the node, from the first dead reckoning.
FilterRun runFilter(const fusion::FusionFrontEndConfig& config, const sim::CameraRig& rig,
                    const Eigen::Matrix3d& camera_matrix, const std::vector<registration::MotionEstimate>& estimates,
                    const std::vector<NavEvent>& events, bool images, bool nav,
                    const std::vector<double>& frame_stamps) {
  FilterRun run;
  const size_t n = frame_stamps.size();
  const Eigen::Vector2d nan2(std::nan(""), std::nan(""));
  run.live.assign(n, nan2);
  run.motions.assign(n, fusion::MetricMotion());
  run.views.assign(n, std::nullopt);
  const Eigen::Isometry3d base_from_camera = rig.baseFromCamera();
  fusion::FusionFrontEnd front(config, [&](const std::string& frame) -> std::optional<Eigen::Isometry3d> {
    if (frame == kCameraFrame) return base_from_camera;
    if (frame == kAltimeterFrame) return Eigen::Isometry3d::Identity();  // the simulator's altimeter sits at base_link
    return std::nullopt;
  });
  front.setCameraMatrix(camera_matrix);
  const fusion::NavigationFilter& filter = front.filter();
  const auto step_at = [&](double stamp) -> const fusion::FilterStep* {
    const auto& steps = filter.log().steps;
    auto it = std::lower_bound(steps.begin(), steps.end(), stamp,
                               [](const fusion::FilterStep& s, double t) { return s.stamp_s < t; });
    return it != steps.end() && it->stamp_s == stamp ? &*it : nullptr;
  };
  const auto start = Clock::now();
  for (const NavEvent& e : events) {
    fusion::InputOutcome outcome;
    switch (e.kind) {
      case NavEvent::kAttitude:
        front.addImuAttitude(e.stamp_s, e.orientation);
        continue;
      case NavEvent::kAltitude:
        front.addAltimeterRange(e.stamp_s, e.range_m, kAltimeterFrame);
        continue;
      case NavEvent::kImage: {
        if (!images) continue;
        const registration::MotionEstimate& estimate = estimates[e.frame];
        fusion::ImageMotionInput input;
        input.previous_stamp_s = frame_stamps[e.frame - 1];
        input.stamp_s = e.stamp_s;
        input.failed = estimate.failed;
        input.model = registration::toString(estimate.model);
        input.parameters = estimate.parameters;
        input.covariance = estimate.covariance;
        input.centre_px = estimate.centre_px;
        input.pixel_matrix = estimate.pixel_matrix;
        input.camera_matrix = camera_matrix;
        outcome = front.addImageMotion(input);
        if (outcome.metric) run.motions[e.frame] = *outcome.metric;
        if (!run.views[e.frame - 1]) run.views[e.frame - 1] = front.viewAt(input.previous_stamp_s, base_from_camera);
        run.views[e.frame] = front.viewAt(e.stamp_s, base_from_camera);
        if (const fusion::FilterStep* s = step_at(e.stamp_s)) run.live[e.frame] = s->x_posterior.head<2>();
        break;
      }
      case NavEvent::kDeadReckoning:
        front.addNavigationAttitude(e.stamp_s, e.orientation);
        if (!nav) continue;
        outcome = front.addDeadReckoning(e.stamp_s, e.position_m, e.covariance);
        if (outcome.camera_en_m) run.dr_at[e.stamp_s] = *outcome.camera_en_m;
        break;
      case NavEvent::kFix:
        if (!nav) continue;
        outcome = front.addFix(e.stamp_s, e.position_m.head<2>(), e.covariance, "", false);
        if (outcome.camera_en_m) run.fixes.push_back({e.stamp_s, *outcome.camera_en_m, e.covariance});
        if (outcome.update)
          run.fixes_rejected_at_arrival += outcome.update->status == fusion::UpdateStatus::kRejectedByGate;
        break;
    }
    ++run.events;
    if (!outcome.rejected.empty() || !outcome.problem.empty())
      std::cout << "  event at " << std::fixed << std::setprecision(3) << e.stamp_s << std::defaultfloat << ": "
                << outcome.rejected << outcome.problem << "\n";
    else if (outcome.update && outcome.update->status == fusion::UpdateStatus::kInvalid)
      std::cout << "  event at " << std::fixed << std::setprecision(3) << e.stamp_s << std::defaultfloat << ": "
                << fusion::toString(outcome.update->status) << " " << outcome.update->detail << "\n";
  }
  run.filter_seconds = secondsSince(start);
  const auto smoother_start = Clock::now();
  run.smoothed_states = fusion::smoothRts(filter.log());
  run.smoother_seconds = secondsSince(smoother_start);
  run.filtered.assign(n, nan2);
  run.smoothed.assign(n, nan2);
  run.filtered_covariance.assign(n, Eigen::Matrix2d::Identity());
  run.smoothed_covariance.assign(n, Eigen::Matrix2d::Identity());
  run.frame_step.assign(n, -1);
  const auto& steps = filter.log().steps;
  size_t k = 0;
  for (size_t i = 0; i < steps.size(); ++i) {
    run.fixes_rejected_final += steps[i].fixes_rejected;
    run.fixes_applied_final += steps[i].fixes_applied;
    while (k < n && frame_stamps[k] < steps[i].stamp_s) ++k;
    if (k < n && frame_stamps[k] == steps[i].stamp_s) {
      run.filtered[k] = steps[i].x_posterior.head<2>();
      run.filtered_covariance[k] = steps[i].P_posterior.block<2, 2>(0, 0);
      run.smoothed[k] = run.smoothed_states[i].position_en_m;
      run.smoothed_covariance[k] = run.smoothed_states[i].position_covariance_m2;
      run.frame_step[k] = static_cast<int>(i);
    }
  }
  run.recoveries = static_cast<int>(filter.counters().recoveries);
  run.rewinds = filter.counters().rewinds;
  run.last = filter.current();
  run.log = filter.log();
  return run;
}

/// How far the front-end's metric motions are from the truth, overall and along / across each step's motion.
struct MetricStats {
  double step_rmse_m = 0.0;
  double step_reported_rms_m = 0.0;  ///< sqrt of the mean trace of the motions' covariances
  int count = 0;
  double along_sq_m2 = 0.0, cross_sq_m2 = 0.0;              ///< sums of squared step errors per axis
  double along_reported_m2 = 0.0, cross_reported_m2 = 0.0;  ///< sums of reported variances
  int axis_count = 0;
};

MetricStats metricStats(const std::vector<fusion::MetricMotion>& motions, const std::vector<Eigen::Vector2d>& truth) {
  MetricStats m;
  double error_sum = 0.0;
  for (size_t k = 1; k < motions.size(); ++k) {
    if (!motions[k].valid) continue;
    const Eigen::Vector2d true_step = truth[k] - truth[k - 1];
    const Eigen::Vector2d step_error = motions[k].camera_displacement_en_m - true_step;
    error_sum += step_error.squaredNorm();
    if (true_step.norm() > 1e-6) {  // along and across the step's motion: is the registration's error isotropic?
      const Eigen::Vector2d along = true_step.normalized();
      m.along_sq_m2 += std::pow(along.dot(step_error), 2);
      m.cross_sq_m2 += std::pow(along.x() * step_error.y() - along.y() * step_error.x(), 2);
      const Eigen::Vector2d cross(-along.y(), along.x());
      m.along_reported_m2 += along.dot(motions[k].covariance_m2 * along);
      m.cross_reported_m2 += cross.dot(motions[k].covariance_m2 * cross);
      ++m.axis_count;
    }
    m.step_reported_rms_m += motions[k].covariance_m2.trace();
    ++m.count;
  }
  m.step_rmse_m = std::sqrt(error_sum / std::max(1, m.count));
  m.step_reported_rms_m = std::sqrt(m.step_reported_rms_m / std::max(1, m.count));
  return m;
}

/// Image motion alone from the true first position (a failed pair keeps the previous pair's motion).
std::vector<Eigen::Vector2d> imageOnlyTrack(const std::vector<fusion::MetricMotion>& motions,
                                            const Eigen::Vector2d& start_en_m) {
  std::vector<Eigen::Vector2d> track(motions.size());
  track[0] = start_en_m;
  Eigen::Vector2d last_motion = Eigen::Vector2d::Zero();
  for (size_t k = 1; k < motions.size(); ++k) {
    if (motions[k].valid) last_motion = motions[k].camera_displacement_en_m;
    track[k] = track[k - 1] + last_motion;
  }
  return track;
}

/// The dead-reckoning camera centre at each frame stamp (NaN where none was received at that stamp).
std::vector<Eigen::Vector2d> navigationTrack(const std::map<double, Eigen::Vector2d>& dr_at,
                                             const std::vector<double>& frame_stamps) {
  std::vector<Eigen::Vector2d> track(frame_stamps.size(), Eigen::Vector2d(std::nan(""), std::nan("")));
  for (size_t k = 0; k < frame_stamps.size(); ++k) {
    auto it = dr_at.find(frame_stamps[k]);
    if (it != dr_at.end()) track[k] = it->second;
  }
  return track;
}

/// The fixes' errors against the truth at their stamps (fixes at whole seconds coincide with frame stamps).
std::vector<double> fixErrors(const std::vector<fusion::AbsoluteConstraint>& fixes,
                              const std::vector<double>& frame_stamps, const std::vector<Eigen::Vector2d>& truth) {
  std::vector<double> errors;
  for (const fusion::AbsoluteConstraint& f : fixes) {
    auto it = std::lower_bound(frame_stamps.begin(), frame_stamps.end(), f.stamp_s);
    if (it != frame_stamps.end() && *it == f.stamp_s)
      errors.push_back((f.position_en_m - truth[it - frame_stamps.begin()]).norm());
  }
  return errors;
}

/// The filter configured from the navigation sensors' specifications, as an operator would from their datasheets
/// (the simulator's values stand for the datasheet): gyro noise and bias for the heading, DVL noise and scale error
/// for the dead reckoning. The heading starts from the attitude sensor's alignment at launch; the pixel-size
/// correction keeps its default prior.
fusion::FilterConfig filterConfigForSensors(const sim::NavigationSensorConfig& nav) {
  fusion::FilterConfig c;
  c.initial_heading_sigma_rad = std::max(1e-4, nav.heading_alignment_sigma_rad);
  c.heading_noise_rad_per_sqrt_s = nav.gyro_noise_rps / std::sqrt(nav.imu_rate_hz);  // angle random walk
  c.initial_heading_drift_sigma_rps = nav.gyro_bias_rps;
  c.heading_drift_noise_rps_per_sqrt_s = nav.gyro_bias_walk_rps_sqrt_s;
  c.initial_dr_scale_sigma = nav.dvl_scale_error;
  c.dr_scale_noise_per_sqrt_s = 1e-6;  // the DVL's scale error is a constant of the instrument and the water
  // The pixel size's error is the camera's calibration and the altimeter's white noise: nothing in it drifts.
  c.pixel_size_correction_noise_per_sqrt_s = 1e-6;
  // DVL white noise integrated: each sample's error lasts one DVL period.
  c.dr_offset_noise_m2_per_s = nav.dvl_noise_mps * nav.dvl_noise_mps / nav.dvl_rate_hz;
  c.dr_offset_noise_m2_per_m = 0.0;
  return c;
}

/// Sets a numeric FilterConfig field by name (for sensitivity studies); false for an unknown name.
bool setFilterField(fusion::FilterConfig* c, const std::string& name, double value) {
  const std::map<std::string, double*> fields = {
      {"position_noise_m2_per_s", &c->position_noise_m2_per_s},
      {"image_step_noise_along_m", &c->image_step_noise_along_m},
      {"image_step_noise_across_m", &c->image_step_noise_across_m},
      {"initial_pixel_size_correction_sigma", &c->initial_pixel_size_correction_sigma},
      {"pixel_size_correction_noise_per_sqrt_s", &c->pixel_size_correction_noise_per_sqrt_s},
      {"initial_heading_sigma_rad", &c->initial_heading_sigma_rad},
      {"initial_heading_drift_sigma_rps", &c->initial_heading_drift_sigma_rps},
      {"heading_noise_rad_per_sqrt_s", &c->heading_noise_rad_per_sqrt_s},
      {"heading_drift_noise_rps_per_sqrt_s", &c->heading_drift_noise_rps_per_sqrt_s},
      {"dr_measurement_sigma_m", &c->dr_measurement_sigma_m},
      {"dr_offset_noise_m2_per_m", &c->dr_offset_noise_m2_per_m},
      {"dr_offset_noise_m2_per_s", &c->dr_offset_noise_m2_per_s},
      {"initial_dr_scale_sigma", &c->initial_dr_scale_sigma},
      {"dr_scale_noise_per_sqrt_s", &c->dr_scale_noise_per_sqrt_s},
      {"gate_probability", &c->gate_probability}};
  const auto it = fields.find(name);
  if (it == fields.end()) return false;
  *it->second = value;
  return true;
}

/// "NAME=VALUE" of --filter: NAME a numeric FilterConfig field, VALUE a number; empty if `text` is one.
std::string filterOverrideError(const std::string& text, std::pair<std::string, double>* parsed = nullptr) {
  const size_t eq = text.find('=');
  if (eq == std::string::npos) return "takes NAME=VALUE, got '" + text + "'";
  const std::string name = text.substr(0, eq), value = text.substr(eq + 1);
  char* end = nullptr;
  const double number = std::strtod(value.c_str(), &end);
  if (value.empty() || *end != '\0') return "'" + value + "' is not a number (in '" + text + "')";
  fusion::FilterConfig scratch;
  if (!setFilterField(&scratch, name, number)) return "'" + name + "' is no numeric FilterConfig field";
  if (parsed) *parsed = {name, number};
  return "";
}

}  // namespace

int main(int argc, char** argv) {
  exocet_common::BenchmarkPaths paths;
  std::string dive_yaml = exocet_common::testing::configDir() + "/dives/bench_fusion.yaml";
  bool no_cross_pass = false;
  int monte_carlo_runs = 50;
  bool mc_exact_camera = false;
  std::vector<std::string> monte_carlo_overrides;  // "navigation.key=value": the Monte Carlo's sensors differ
  std::vector<std::string> filter_texts;
  CLI::App app(
      "bench_fusion: the navigation fusion on a simulated dive, every sensor through fusion_node's front-end:\n"
      "each source alone, filtered, smoothed, with cross-pass constraints, and the filter's consistency (NEES)\n"
      "over Monte Carlo runs. Writes OUTPUT_DIR/fusion.json and OUTPUT_DIR/fusion_tracks.csv.",
      "bench_fusion");
  exocet_common::addBenchmarkPathOptions(app, &paths, false);
  app.add_option("--dive", dive_yaml, "dive description")
      ->type_name("YAML")
      ->check(CLI::ExistingFile)
      ->capture_default_str();
  app.add_flag("--no-cross-pass", no_cross_pass, "skip the cross-pass registration and constraints");
  app.add_option("--monte-carlo", monte_carlo_runs, "Monte Carlo runs of the NEES (0: none)")
      ->type_name("RUNS")
      ->check(exocet_common::atLeast(0))
      ->capture_default_str();
  app.add_option("--monte-carlo-set", monte_carlo_overrides,
                 "a setting of the Monte Carlo runs' sensors (repeatable): their dive is the --dive YAML\nwith these")
      ->type_name("navigation.KEY=VALUE")
      ->expected(1)
      ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
  app.add_flag("--monte-carlo-exact-camera", mc_exact_camera,
               "keep the camera's focal length in the Monte Carlo runs (default: drawn from the\npixel-size prior)");
  app.add_option("--filter", filter_texts, "set a numeric FilterConfig field (repeatable)")
      ->type_name("NAME=VALUE")
      ->expected(1)
      ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll)
      ->check(CLI::Validator([](std::string& text) { return filterOverrideError(text); }, ""));
  if (const auto exit_status = exocet_common::parseCommandLine(app, argc, argv)) return *exit_status;
  const std::string& out_dir = paths.output_dir;
  const bool cross_pass = !no_cross_pass;
  const bool mc_draw_focal = !mc_exact_camera;  // each Monte Carlo run's focal length drawn from the pixel-size prior
  std::vector<std::pair<std::string, double>> filter_overrides(filter_texts.size());
  for (size_t i = 0; i < filter_texts.size(); ++i) filterOverrideError(filter_texts[i], &filter_overrides[i]);
  cv::setNumThreads(1);
  std::cout << std::unitbuf;
  nlohmann::json json;  // keys sorted, as make-benchmarks-doc lists them
  const auto bench_start = Clock::now();

  // ---- 1. The dive ----
  const sim::DiveDescription dive = sim::loadDiveDescription(dive_yaml, {});
  const sim::CameraRig& rig = dive.synthesis.rig;
  const CapturedDive d = simulate(dive, out_dir + "/cache", 2);
  const size_t n = d.gray.size();
  const exocet_common::UtmGrid grid =
      exocet_common::UtmGrid::forLatLon(dive.origin_latitude_deg, dive.origin_longitude_deg);
  std::vector<Eigen::Vector2d> truth(n);
  for (size_t k = 0; k < n; ++k) truth[k] = d.world_from_camera[k].translation().head<2>();
  const double t0 = d.frame_stamps_s.front();
  double path_m = 0.0;
  for (size_t k = 1; k < n; ++k) path_m += (truth[k] - truth[k - 1]).norm();
  std::cout << "dive: " << n << " frames over " << d.frame_stamps_s.back() - t0 << " s, camera path " << path_m
            << " m, grid " << grid.name() << " (EPSG " << grid.epsg() << "), " << d.usbl.size() << " USBL fixes, "
            << d.dead_reckoning.size() << " DR records\n";

  // ---- 2. Registration of consecutive frames, through registration_node's front-end ----
  registration::RegistrationConfig reg_config;
  reg_config.method = registration::RegistrationMethod::kAuto;
  reg_config.model = registration::MotionModel::kHomography;
  registration::SequenceRegistrar sequence(registration::makeRegistrar(reg_config),
                                           registration::SequenceRegistrarConfig());
  std::vector<registration::MotionEstimate> estimates(n);
  auto t_start = Clock::now();
  int registration_failures = 0;
  for (size_t k = 0; k < n; ++k) {
    const registration::SequenceStep step = sequence.add(d.gray[k], d.frame_stamps_s[k]);
    if (k == 0) continue;
    if (step.has_motion) estimates[k] = step.motion;  // otherwise a restart: the default estimate is a failure
    if (estimates[k].failed) ++registration_failures;
  }
  const double registration_s = secondsSince(t_start);
  std::cout << "registration: " << n - 1 << " pairs in " << registration_s << " s (" << (n - 1) / registration_s
            << " pairs/s), " << registration_failures << " failed\n";

  // ---- 3. Every source in arrival order; the metric conversion by the front-end ----
  fusion::CameraMount mount;
  mount.camera_matrix << rig.camera.fx, 0.0, rig.camera.cx, 0.0, rig.camera.fy, rig.camera.cy, 0.0, 0.0, 1.0;
  mount.base_from_camera = rig.baseFromCamera();
  const double usbl_sigma = dive.synthesis.navigation.usbl_noise_m;
  const std::vector<NavEvent> events = buildEvents(d, grid);
  // A first pass gives the metric motions, the views, the dead reckoning and the fixes as the front-end makes them
  // (none of them depends on the filter's settings, which are calibrated from them below).
  const FilterRun conversion =
      runFilter(frontEndConfig(filterConfigForSensors(dive.synthesis.navigation), dive.synthesis.navigation), rig,
                mount.camera_matrix, estimates, events, true, true, d.frame_stamps_s);
  const std::vector<std::optional<fusion::ViewGeometry>>& views = conversion.views;
  const std::vector<fusion::MetricMotion>& motions = conversion.motions;
  const MetricStats metric = metricStats(motions, truth);
  const std::vector<double> usbl_errors = fixErrors(conversion.fixes, d.frame_stamps_s, truth);
  int usbl_outliers = 0;
  for (double e : usbl_errors) usbl_outliers += e > 4.0 * usbl_sigma;
  std::cout << "metric motion: per-pair displacement RMSE " << 1000.0 * metric.step_rmse_m << " mm over "
            << metric.count << " pairs (their covariances say " << 1000.0 * metric.step_reported_rms_m
            << " mm); per axis, along the motion "
            << 1000.0 * std::sqrt(metric.along_sq_m2 / std::max(1, metric.axis_count)) << " mm, across it "
            << 1000.0 * std::sqrt(metric.cross_sq_m2 / std::max(1, metric.axis_count)) << " mm\n";

  // ---- 5. Single sources ----
  const std::vector<Eigen::Vector2d> image_only = imageOnlyTrack(motions, truth[0]);
  const std::vector<Eigen::Vector2d> nav_only = navigationTrack(conversion.dr_at, d.frame_stamps_s);
  double usbl_sq = 0.0, usbl_inlier_sq = 0.0;
  int usbl_inliers = 0;
  for (double e : usbl_errors) {
    usbl_sq += e * e;
    if (e <= 4.0 * usbl_sigma) {
      usbl_inlier_sq += e * e;
      ++usbl_inliers;
    }
  }
  const double rmse_usbl = std::sqrt(usbl_sq / usbl_errors.size());
  const double rmse_usbl_inliers = std::sqrt(usbl_inlier_sq / std::max(1, usbl_inliers));

  // ---- 6. The filter: DR + USBL only, then all sources; RTS over the whole dive ----
  // The filter from the sensors' specifications, then the command line's changes.
  // The image motion's extra noise, calibrated as a sensor's noise is against ground truth: what the registration's
  // measured per-pair error (against the simulator's truth) leaves beyond the covariance the registrar reports, per
  // axis along and across each step's motion (the error is anisotropic). (The default, 1 mm on both axes, is a guess
  // for relief and refraction, neither of which this flat dive has.)
  const double axis_count = std::max(1, metric.axis_count);
  const double calibrated_image_step_noise_along_m =
      std::sqrt(std::max(0.0, (metric.along_sq_m2 - metric.along_reported_m2) / axis_count));
  const double calibrated_image_step_noise_across_m =
      std::sqrt(std::max(0.0, (metric.cross_sq_m2 - metric.cross_reported_m2) / axis_count));
  std::cout << "image step noise calibrated from the registration's accuracy: "
            << 1000.0 * calibrated_image_step_noise_along_m << " mm along the motion, "
            << 1000.0 * calibrated_image_step_noise_across_m << " mm across it (the registrar's covariances say "
            << 1000.0 * std::sqrt(metric.along_reported_m2 / axis_count) << " / "
            << 1000.0 * std::sqrt(metric.cross_reported_m2 / axis_count) << " mm)\n";
  const auto configure = [&](const sim::NavigationSensorConfig& sensors, fusion::FilterConfig* c) {
    *c = filterConfigForSensors(sensors);
    c->image_step_noise_along_m = calibrated_image_step_noise_along_m;
    c->image_step_noise_across_m = calibrated_image_step_noise_across_m;
    for (const auto& [name, value] : filter_overrides)
      if (!setFilterField(c, name, value)) {
        std::cerr << "bench_fusion: --filter " << name << ": no such numeric FilterConfig field\n";
        return false;
      }
    return true;
  };
  fusion::FilterConfig config;
  if (!configure(dive.synthesis.navigation, &config)) return 2;
  for (const auto& [name, value] : filter_overrides) std::cout << "filter: " << name << " = " << value << "\n";
  const fusion::FusionFrontEndConfig front_end = frontEndConfig(config, dive.synthesis.navigation);
  const FilterRun nav_run =
      runFilter(front_end, rig, mount.camera_matrix, estimates, events, false, true, d.frame_stamps_s);
  const FilterRun all = runFilter(front_end, rig, mount.camera_matrix, estimates, events, true, true, d.frame_stamps_s);

  // ---- 7. Scores ----
  const double rmse_image_only = rmse(image_only, truth);
  const double rmse_nav_only = rmse(nav_only, truth);
  const double rmse_nav_filter = rmse(nav_run.filtered, truth);
  const double rmse_nav_smoothed = rmse(nav_run.smoothed, truth);
  const double rmse_filtered = rmse(all.filtered, truth);
  const double rmse_live = rmse(all.live, truth);
  const double rmse_smoothed = rmse(all.smoothed, truth);
  int nees_in = 0, nees_below = 0, nees_above = 0, nees_count = 0;
  double nees_sum = 0.0, smoothed_nees_sum = 0.0;
  for (size_t k = 0; k < n; ++k) {
    if (all.frame_step[k] < 0) continue;
    const Eigen::Vector2d e = all.filtered[k] - truth[k];
    const double nees = e.dot(all.filtered_covariance[k].ldlt().solve(e));
    const Eigen::Vector2d es = all.smoothed[k] - truth[k];
    smoothed_nees_sum += es.dot(all.smoothed_covariance[k].ldlt().solve(es));
    nees_sum += nees;
    nees_in += nees >= 0.0506 && nees <= 7.38;
    nees_below += nees < 0.0506;
    nees_above += nees > 7.38;
    ++nees_count;
  }

  // Outbound and return passes: heading within 10 deg of the line's, or of its reverse; the turn is left out.
  const double line_yaw = M_PI / 2 - dive.synthesis.trajectory.heading_deg * M_PI / 180.0;
  const auto angle_to = [](double a, double b) { return std::abs(std::remainder(a - b, 2.0 * M_PI)); };
  std::vector<int> outbound, returning;
  bool turned = false;
  for (size_t k = 0; k < n; ++k) {
    if (angle_to(d.vehicle_yaw_rad[k], line_yaw) > 10.0 * M_PI / 180.0) turned = true;
    if (!turned && angle_to(d.vehicle_yaw_rad[k], line_yaw) < 10.0 * M_PI / 180.0) outbound.push_back(int(k));
    if (turned && angle_to(d.vehicle_yaw_rad[k], line_yaw + M_PI) < 10.0 * M_PI / 180.0) returning.push_back(int(k));
  }
  std::vector<std::pair<int, int>> pass_pairs;  // (return frame, nearest outbound frame)
  for (int r : returning) {
    int best = -1;
    double best_d = 1e300;
    for (int o : outbound) {
      const double dist = (truth[r] - truth[o]).norm();
      if (dist < best_d) best_d = dist, best = o;
    }
    if (best >= 0 && best_d < 0.5) pass_pairs.emplace_back(r, best);
  }
  const Misalignment mis_filtered = misalignment(pass_pairs, all.filtered, truth, d.gsd_m);
  const Misalignment mis_smoothed = misalignment(pass_pairs, all.smoothed, truth, d.gsd_m);
  const Misalignment mis_image_only = misalignment(pass_pairs, image_only, truth, d.gsd_m);
  const Misalignment mis_nav_only = misalignment(pass_pairs, nav_only, truth, d.gsd_m);
  double gsd_mean = 0.0;
  for (double g : d.gsd_m) gsd_mean += g / n;

  // ---- 8. Cross-pass image constraints in a batch smoother ----
  Misalignment mis_cross;
  double rmse_cross = std::nan("");
  int cross_constraints = 0, cross_attempts = 0;
  double cross_seconds = 0.0;
  if (cross_pass) {
    const auto cross_start = Clock::now();
    std::vector<fusion::RelativeConstraint> cross;
    std::vector<double> residuals_px, constraint_errors_m;
    for (size_t i = 0; i < pass_pairs.size(); i += 5) {  // one return frame a second
      const auto [ret, out] = pass_pairs[i];
      ++cross_attempts;
      const CrossRegistration reg = registerAcrossPasses(siftFeatures(d.gray[out]), siftFeatures(d.gray[ret]),
                                                         d.gray[ret].cols, d.gray[ret].rows);
      if (!reg.found) continue;
      if (!views[out] || !views[ret]) continue;
      const fusion::MetricMotion m =
          fusion::toMetricMotion(registration::MotionModel::kHomography, reg.parameters, reg.covariance, reg.centre_px,
                                 mount, *views[out], *views[ret]);
      if (!m.valid) continue;
      fusion::RelativeConstraint c;
      c.from_stamp_s = d.frame_stamps_s[out];
      c.to_stamp_s = d.frame_stamps_s[ret];
      c.delta_en_m = m.camera_displacement_en_m;
      c.covariance_m2 = m.covariance_m2;
      cross.push_back(c);
      residuals_px.push_back(reg.residual_px);
      constraint_errors_m.push_back((m.camera_displacement_en_m - (truth[ret] - truth[out])).norm());
    }
    std::cout << "cross-pass registration: median inlier residual " << percentile(residuals_px, 0.5)
              << " px, constraint error median " << 1000.0 * percentile(constraint_errors_m, 0.5) << " mm, p95 "
              << 1000.0 * percentile(constraint_errors_m, 0.95) << " mm\n";
    json["cross_pass_constraint_error_median_m"] = percentile(constraint_errors_m, 0.5);
    cross_constraints = static_cast<int>(cross.size());
    const fusion::CrossPassResult result =
        fusion::smoothWithCrossPassConstraints(all.log, all.smoothed_states, all.fixes, cross);
    cross_seconds = secondsSince(cross_start);
    std::vector<Eigen::Vector2d> cross_track(n, Eigen::Vector2d(std::nan(""), std::nan("")));
    for (size_t k = 0; k < n; ++k)
      if (all.frame_step[k] >= 0) cross_track[k] = result.positions_en_m[all.frame_step[k]];
    mis_cross = misalignment(pass_pairs, cross_track, truth, d.gsd_m);
    rmse_cross = rmse(cross_track, truth);
    std::cout << "cross-pass: " << cross_constraints << " constraints from " << cross_attempts << " pairs, "
              << result.iterations << " iterations, " << cross_seconds << " s; " << result.message << "\n";
  }

  // ---- 9. Monte Carlo over the navigation sensors' noise ----
  // One dive is one realisation: its NEES is correlated over the whole dive, so the fraction of its epochs inside
  // the 2-dof bounds says little about consistency. The standard test (Bar-Shalom, Li and Kirubarajan, 5.4) averages
  // the NEES over R independent runs at each epoch: R times that average is chi-square with 2R dof when the filter
  // is consistent. The runs re-draw every navigation sensor (gyro bias and noise, DVL scale and noise, altimeter,
  // roll and pitch, USBL noise and outliers) along the same trajectory; the images and their registration are the
  // rendered dive's (rendering is the expensive part), their metric conversion is redone with each run's attitude
  // and altimeter.
  std::vector<double> mc_ratio, mc_rmse_filtered, mc_rmse_nav;
  std::vector<double> mc_nees_sum(n, 0.0);
  std::vector<int> mc_nees_count(n, 0);
  // Diagnostics of a miss: the NEES per axis (along and across the track, 1 dof each), and the error common to the
  // runs (its mean over them), which averaging cannot remove and the chi-square bounds do not expect.
  std::vector<double> mc_nees_along_sum(n, 0.0), mc_nees_cross_sum(n, 0.0), mc_error_sq_sum(n, 0.0);
  std::vector<Eigen::Vector2d> mc_error_sum(n, Eigen::Vector2d::Zero());
  const auto mc_start = Clock::now();
  if (monte_carlo_runs > 0) {
    // The Monte Carlo's sensors: the dive's, or changed from the command line (to find which sensor's model a
    // consistency problem comes from); the filter follows them.
    const sim::DiveDescription mc_dive =
        monte_carlo_overrides.empty() ? dive : sim::loadDiveDescription(dive_yaml, monte_carlo_overrides);
    const sim::DiveSynthesisConfig& sc = mc_dive.synthesis;
    fusion::FilterConfig mc_config;
    if (!configure(sc.navigation, &mc_config)) return 2;
    for (const std::string& o : monte_carlo_overrides) std::cout << "Monte Carlo sensors: " << o << "\n";
    const sim::VehicleTrajectory trajectory(sc.trajectory);
    const double duration_s =
        sc.duration_s > 0.0 ? std::min(sc.duration_s, trajectory.duration_s()) : trajectory.duration_s();
    const sim::Seabed seabed = sim::makeSeabed(dive.seabed, sc.seed);
    const sim::SeabedRelief* relief = seabed.relief.get();
    for (int run = 0; run < monte_carlo_runs; ++run) {
      CapturedDive r;  // the images (shared, not copied) and truth of the dive, this run's navigation
      r.gray = d.gray;
      r.frame_stamps_s = d.frame_stamps_s;
      sim::NavigationSensorSimulator sensors(sc.navigation, sc.geo, sc.seabed_depth_m, sc.start_time_unix_s,
                                             sc.seed + 7919 * (run + 1),
                                             [relief](double x, double y) { return relief->heightAt_m(x, y); });
      sim::NavigationSinks sinks;
      sinks.imu = [&](const dive::ImuRecord& x) { r.imu.push_back(x); };
      sinks.altitude = [&](const dive::AltitudeRecord& x) { r.altitude.push_back(x); };
      sinks.dead_reckoning = [&](const dive::PoseRecord& x) { r.dead_reckoning.push_back(x); };
      sinks.usbl = [&](const dive::FixRecord& x) { r.usbl.push_back(x); };
      sensors.advanceTo(trajectory, duration_s, sinks);
      // The pixel size's prior stands for the camera's calibration (alpha known to that relative sigma, e.g. from
      // self-calibration): each run converts with a focal length drawn from it, as the truth of a consistent test
      // must be drawn from the filter's priors. (The rendered dive itself converts with the exact camera.)
      fusion::CameraMount run_mount = mount;
      if (mc_draw_focal) {
        std::mt19937 focal_rng(sc.seed + 104729 * (run + 1));
        const double focal_scale =
            1.0 + std::normal_distribution<double>(0.0, mc_config.initial_pixel_size_correction_sigma)(focal_rng);
        run_mount.camera_matrix(0, 0) *= focal_scale;
        run_mount.camera_matrix(1, 1) *= focal_scale;
      }
      const FilterRun fr = runFilter(frontEndConfig(mc_config, sc.navigation), rig, run_mount.camera_matrix, estimates,
                                     buildEvents(r, grid), true, true, d.frame_stamps_s);
      const std::vector<Eigen::Vector2d> r_nav = navigationTrack(fr.dr_at, d.frame_stamps_s);
      double usbl_sq = 0.0;
      const std::vector<double> r_usbl_errors = fixErrors(fr.fixes, d.frame_stamps_s, truth);
      for (double e : r_usbl_errors) usbl_sq += e * e;
      const double r_rmse_usbl = std::sqrt(usbl_sq / std::max<size_t>(1, r_usbl_errors.size()));
      const double r_rmse_image = rmse(imageOnlyTrack(fr.motions, truth[0]), truth);
      const double r_filtered = rmse(fr.filtered, truth), r_nav_rmse = rmse(r_nav, truth);
      mc_rmse_filtered.push_back(r_filtered);
      mc_rmse_nav.push_back(r_nav_rmse);
      // The better single source among the three the filter fuses: dead reckoning, USBL, the images.
      mc_ratio.push_back(r_filtered / std::min({r_nav_rmse, r_rmse_usbl, r_rmse_image}));
      for (size_t k = 0; k < n; ++k) {
        if (fr.frame_step[k] < 0) continue;
        const Eigen::Vector2d e = fr.filtered[k] - truth[k];
        const Eigen::Matrix2d& P = fr.filtered_covariance[k];
        mc_nees_sum[k] += e.dot(P.ldlt().solve(e));
        ++mc_nees_count[k];
        const size_t a = k > 0 ? k - 1 : 0, b = std::min(n - 1, k + 1);
        const Eigen::Vector2d along = (truth[b] - truth[a]).norm() > 1e-9 ? (truth[b] - truth[a]).normalized().eval()
                                                                          : Eigen::Vector2d::UnitX().eval();
        const Eigen::Vector2d cross(-along.y(), along.x());
        mc_nees_along_sum[k] += std::pow(along.dot(e), 2) / along.dot(P * along);
        mc_nees_cross_sum[k] += std::pow(cross.dot(e), 2) / cross.dot(P * cross);
        mc_error_sum[k] += e;
        mc_error_sq_sum[k] += e.squaredNorm();
      }
    }
  }
  const double mc_seconds = secondsSince(mc_start);
  int mc_in = 0, mc_below = 0, mc_above = 0, mc_epochs = 0;
  double mc_low = 0.0, mc_high = 0.0, mc_nees_mean = 0.0;
  if (monte_carlo_runs > 0) {
    const boost::math::chi_squared chi2(2.0 * monte_carlo_runs);
    mc_low = boost::math::quantile(chi2, 0.025) / monte_carlo_runs;
    mc_high = boost::math::quantile(chi2, 0.975) / monte_carlo_runs;
    for (size_t k = 0; k < n; ++k) {
      if (mc_nees_count[k] != monte_carlo_runs) continue;
      const double average = mc_nees_sum[k] / monte_carlo_runs;
      mc_nees_mean += average;
      ++mc_epochs;
      mc_in += average >= mc_low && average <= mc_high;
      mc_below += average < mc_low;
      mc_above += average > mc_high;
    }
    mc_nees_mean /= std::max(1, mc_epochs);
  }
  // Per axis: R times the 1-dof average is chi-square with R dof.
  int mc_along_in = 0, mc_cross_in = 0;
  double mc_along_mean = 0.0, mc_cross_mean = 0.0, mc_common_fraction = 0.0;
  if (monte_carlo_runs > 0 && mc_epochs > 0) {
    const boost::math::chi_squared chi1(monte_carlo_runs);
    const double low1 = boost::math::quantile(chi1, 0.025) / monte_carlo_runs;
    const double high1 = boost::math::quantile(chi1, 0.975) / monte_carlo_runs;
    double common_sq = 0.0, total_sq = 0.0;
    for (size_t k = 0; k < n; ++k) {
      if (mc_nees_count[k] != monte_carlo_runs) continue;
      const double along = mc_nees_along_sum[k] / monte_carlo_runs, cross = mc_nees_cross_sum[k] / monte_carlo_runs;
      mc_along_mean += along / mc_epochs;
      mc_cross_mean += cross / mc_epochs;
      mc_along_in += along >= low1 && along <= high1;
      mc_cross_in += cross >= low1 && cross <= high1;
      common_sq += (mc_error_sum[k] / monte_carlo_runs).squaredNorm();
      total_sq += mc_error_sq_sum[k] / monte_carlo_runs;
    }
    // Independent zero-mean runs give 1/R.
    mc_common_fraction = common_sq / std::max(1e-300, total_sq);
  }
  const auto mean_of = [](const std::vector<double>& v) {
    double sum = 0.0;
    for (double x : v) sum += x;
    return v.empty() ? std::nan("") : sum / v.size();
  };

  // ---- 10. Table ----
  const double true_heading_error_end =
      std::remainder(sim::rpyFromRotation(attitudeAt(d.imu, d.frame_stamps_s.back()).toRotationMatrix()).z() -
                         d.vehicle_yaw_rad.back(),
                     2.0 * M_PI);
  // The better single source among the three the filter fuses: dead reckoning, USBL, the images.
  const double better_single = std::min({rmse_nav_only, rmse_usbl, rmse_image_only});
  const double updates_per_s = all.events / all.filter_seconds;
  std::cout << "\nFusion, out-and-back over " << path_m << " m (" << n << " PAL frames at " << rig.fps
            << " fps, mean GSD " << 1000.0 * gsd_mean << " mm), against the true camera centre:\n"
            << std::left << std::setw(44) << "track" << std::right << std::setw(11) << "RMSE m" << std::setw(15)
            << "return med GSD" << std::setw(15) << "return p95 GSD"
            << "\n";
  const auto row = [](const std::string& name, double r, const Misalignment& m) {
    std::ostringstream line;
    line << std::left << std::setw(44) << name << std::right << std::fixed << std::setprecision(3) << std::setw(11) << r
         << std::setprecision(1) << std::setw(15) << m.median_gsd << std::setw(15) << m.p95_gsd << "\n";
    std::cout << line.str();
  };
  row("image motion alone (from the true start)", rmse_image_only, mis_image_only);
  row("dead reckoning (vehicle navigation)", rmse_nav_only, mis_nav_only);
  row("USBL fixes (all, at their stamps)", rmse_usbl, Misalignment());
  row("USBL fixes (without the outliers > 4 sigma)", rmse_usbl_inliers, Misalignment());
  row("filter: DR + USBL", rmse_nav_filter, misalignment(pass_pairs, nav_run.filtered, truth, d.gsd_m));
  row("RTS: DR + USBL", rmse_nav_smoothed, misalignment(pass_pairs, nav_run.smoothed, truth, d.gsd_m));
  row("filter: all sources (fixes at their stamps)", rmse_filtered, mis_filtered);
  row("filter: all sources, live (before late fixes)", rmse_live, misalignment(pass_pairs, all.live, truth, d.gsd_m));
  row("RTS smoother: all sources", rmse_smoothed, mis_smoothed);
  if (cross_pass) row("RTS + cross-pass constraints (Ceres)", rmse_cross, mis_cross);
  if (monte_carlo_runs > 0) {
    int mc_met = 0;
    for (double x : mc_ratio) mc_met += x <= 0.5;
    std::cout << "Monte Carlo over the navigation noise, " << monte_carlo_runs << " runs (" << mc_seconds << " s):\n"
              << "  filtered RMSE mean " << mean_of(mc_rmse_filtered) << " m (DR alone " << mean_of(mc_rmse_nav)
              << " m); filtered / better single source: mean " << mean_of(mc_ratio) << ", median "
              << percentile(mc_ratio, 0.5) << ", p90 " << percentile(mc_ratio, 0.9) << "; " << mc_met << " of "
              << monte_carlo_runs << " runs <= 0.5\n"
              << "  NEES averaged over the runs: mean " << mc_nees_mean << " (2 if consistent), "
              << 100.0 * mc_in / std::max(1, mc_epochs) << " % of " << mc_epochs << " epochs in the 95 % bounds ["
              << mc_low << ", " << mc_high << "] (" << 100.0 * mc_below / std::max(1, mc_epochs) << " % below, "
              << 100.0 * mc_above / std::max(1, mc_epochs) << " % above)\n"
              << "  per axis (1 dof each): along-track mean " << mc_along_mean << ", "
              << 100.0 * mc_along_in / std::max(1, mc_epochs) << " % in bounds; cross-track mean " << mc_cross_mean
              << ", " << 100.0 * mc_cross_in / std::max(1, mc_epochs) << " % in bounds\n"
              << "  error common to the runs (squared mean error / mean squared error): " << mc_common_fraction << " ("
              << 1.0 / monte_carlo_runs << " for independent runs)\n";
  }
  std::cout << "filtered / better single source: " << rmse_filtered / better_single << " (goal <= 0.5)\n"
            << "NEES (filter, position, 2 dof): mean " << nees_sum / nees_count << ", " << 100.0 * nees_in / nees_count
            << " % of " << nees_count << " epochs in [0.0506, 7.38] (" << 100.0 * nees_below / nees_count
            << " % below, " << 100.0 * nees_above / nees_count << " % above); smoothed mean "
            << smoothed_nees_sum / nees_count << "\n"
            << "fixes: " << usbl_errors.size() << " (" << usbl_outliers << " outliers > 4 sigma), gated "
            << all.fixes_rejected_final << " (at arrival " << all.fixes_rejected_at_arrival << "), recoveries "
            << all.recoveries << "\n"
            << "heading error of the IMU at the end " << true_heading_error_end << " rad (truth); estimated "
            << all.last.heading_error_rad << " +- " << all.last.heading_error_sigma_rad
            << " rad, pixel-size correction " << all.last.pixel_size_correction << " +- "
            << all.last.pixel_size_correction_sigma << "\n"
            << "filter: " << all.events << " events in " << all.filter_seconds << " s (" << updates_per_s
            << " updates/s, " << all.rewinds << " rewinds); RTS over " << all.smoothed_states.size() << " steps in "
            << all.smoother_seconds << " s\n";

  json["frames"] = double(n);
  json["path_length_m"] = path_m;
  json["mean_gsd_m"] = gsd_mean;
  json["registration_failures"] = registration_failures;
  json["registration_pairs_per_s"] = (n - 1) / registration_s;
  json["metric_step_rmse_m"] = metric.step_rmse_m;
  json["image_step_noise_calibrated_along_m"] = calibrated_image_step_noise_along_m;
  json["image_step_noise_calibrated_across_m"] = calibrated_image_step_noise_across_m;
  json["rmse_image_only_m"] = rmse_image_only;
  json["rmse_nav_only_m"] = rmse_nav_only;
  json["rmse_usbl_only_m"] = rmse_usbl;
  json["rmse_usbl_only_inliers_m"] = rmse_usbl_inliers;
  json["rmse_nav_filter_m"] = rmse_nav_filter;
  json["rmse_nav_smoothed_m"] = rmse_nav_smoothed;
  json["rmse_filtered_m"] = rmse_filtered;
  json["rmse_filtered_live_m"] = rmse_live;
  json["rmse_smoothed_m"] = rmse_smoothed;
  json["filtered_over_better_single_source"] = rmse_filtered / better_single;
  json["return_misalignment_gsd_filtered_median"] = mis_filtered.median_gsd;
  json["return_misalignment_gsd_filtered_p95"] = mis_filtered.p95_gsd;
  json["return_misalignment_gsd_smoothed_median"] = mis_smoothed.median_gsd;
  json["return_misalignment_gsd_smoothed_p95"] = mis_smoothed.p95_gsd;
  json["return_misalignment_gsd_image_only_median"] = mis_image_only.median_gsd;
  json["return_misalignment_gsd_nav_only_median"] = mis_nav_only.median_gsd;
  json["return_pairs"] = double(pass_pairs.size());
  if (cross_pass) {
    json["return_misalignment_gsd_cross_pass_median"] = mis_cross.median_gsd;
    json["return_misalignment_gsd_cross_pass_p95"] = mis_cross.p95_gsd;
    json["rmse_cross_pass_m"] = rmse_cross;
    json["cross_pass_constraints"] = cross_constraints;
    json["cross_pass_seconds"] = cross_seconds;
  }
  // The figure: the p95 over the return pairs of the final smoothed track (RTS with the cross-pass
  // constraints; RTS alone with --no-cross-pass), so that "at most 3 GSD" holds for 95 % of the seabed, not the median.
  json["return_misalignment_gsd"] = cross_pass ? mis_cross.p95_gsd : mis_smoothed.p95_gsd;
  // nees_in_bounds_fraction: the Monte Carlo test (the NEES averaged over the runs at each epoch against the
  // chi-square bounds of 2R dof); the single dive's per-epoch fraction is kept beside it.
  json["nees_in_bounds_fraction"] = monte_carlo_runs > 0 ? double(mc_in) / std::max(1, mc_epochs) : std::nan("");
  json["nees_monte_carlo_runs"] = monte_carlo_runs;
  json["nees_monte_carlo_mean"] = mc_nees_mean;
  json["nees_monte_carlo_along_track_mean"] = mc_along_mean;
  json["nees_monte_carlo_cross_track_mean"] = mc_cross_mean;
  json["monte_carlo_common_error_fraction"] = mc_common_fraction;
  json["nees_monte_carlo_bounds_low"] = mc_low;
  json["nees_monte_carlo_bounds_high"] = mc_high;
  json["nees_monte_carlo_below_fraction"] = double(mc_below) / std::max(1, mc_epochs);
  json["nees_monte_carlo_above_fraction"] = double(mc_above) / std::max(1, mc_epochs);
  json["monte_carlo_rmse_filtered_mean_m"] = mean_of(mc_rmse_filtered);
  json["monte_carlo_rmse_nav_only_mean_m"] = mean_of(mc_rmse_nav);
  json["monte_carlo_filtered_over_better_single_mean"] = mean_of(mc_ratio);
  json["monte_carlo_filtered_over_better_single_p90"] = monte_carlo_runs > 0 ? percentile(mc_ratio, 0.9) : 0.0;
  json["monte_carlo_seconds"] = mc_seconds;
  json["nees_single_dive_in_bounds_fraction"] = double(nees_in) / nees_count;
  json["nees_mean"] = nees_sum / nees_count;
  json["nees_below_fraction"] = double(nees_below) / nees_count;
  json["nees_above_fraction"] = double(nees_above) / nees_count;
  json["true_heading_error_end_rad"] = true_heading_error_end;
  json["estimated_heading_error_end_rad"] = all.last.heading_error_rad;
  json["estimated_heading_error_end_sigma_rad"] = all.last.heading_error_sigma_rad;
  json["nees_smoothed_mean"] = smoothed_nees_sum / nees_count;
  json["usbl_fixes"] = double(usbl_errors.size());
  json["usbl_outliers"] = usbl_outliers;
  json["gated_fixes"] = all.fixes_rejected_final;
  json["gated_fixes_at_arrival"] = all.fixes_rejected_at_arrival;
  json["recoveries"] = all.recoveries;
  json["filter_events"] = all.events;
  json["filter_updates_per_s"] = updates_per_s;
  json["filter_rewinds"] = double(all.rewinds);
  json["rts_seconds"] = all.smoother_seconds;
  json["bench_seconds"] = secondsSince(bench_start);
  std::error_code error;
  std::filesystem::create_directories(out_dir, error);
  const std::string path = out_dir + "/fusion.json";
  try {
    exocet_common::writeJsonFileAtomically(path, json);
  } catch (const std::exception& e) {
    std::cerr << "bench_fusion: " << e.what() << "\n";
    return 1;
  }
  // Every track at every frame, against the truth, for plots and for diagnosing where the error comes from.
  const std::string tracks_path = out_dir + "/fusion_tracks.csv";
  {
    std::ofstream csv(tracks_path);
    csv << "stamp_s,true_e,true_n,image_e,image_n,dr_e,dr_n,filtered_e,filtered_n,filtered_see,filtered_snn,"
           "filtered_sen,smoothed_e,smoothed_n,smoothed_see,smoothed_snn,smoothed_sen,monte_carlo_nees_average,"
           "monte_carlo_nees_along,monte_carlo_nees_cross,monte_carlo_mean_error_e,monte_carlo_mean_error_n,"
           "monte_carlo_rms_error_m\n";
    csv << std::setprecision(12);
    for (size_t k = 0; k < n; ++k) {
      const Eigen::Matrix2d& P = all.filtered_covariance[k];
      const Eigen::Matrix2d& S = all.smoothed_covariance[k];
      csv << d.frame_stamps_s[k] << ',' << truth[k].x() << ',' << truth[k].y() << ',' << image_only[k].x() << ','
          << image_only[k].y() << ',' << nav_only[k].x() << ',' << nav_only[k].y() << ',' << all.filtered[k].x() << ','
          << all.filtered[k].y() << ',' << P(0, 0) << ',' << P(1, 1) << ',' << P(0, 1) << ',' << all.smoothed[k].x()
          << ',' << all.smoothed[k].y() << ',' << S(0, 0) << ',' << S(1, 1) << ',' << S(0, 1) << ','
          << (mc_nees_count[k] > 0 ? mc_nees_sum[k] / mc_nees_count[k] : std::nan(""));
      const double runs = mc_nees_count[k] > 0 ? mc_nees_count[k] : std::nan("");
      csv << ',' << mc_nees_along_sum[k] / runs << ',' << mc_nees_cross_sum[k] / runs << ','
          << mc_error_sum[k].x() / runs << ',' << mc_error_sum[k].y() / runs << ','
          << std::sqrt(mc_error_sq_sum[k] / runs) << '\n';
    }
  }
  std::cout << "wrote " << path << " and " << tracks_path << " (" << secondsSince(bench_start) << " s)\n";
  return 0;
}
