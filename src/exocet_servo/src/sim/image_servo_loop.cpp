#include "exocet_servo/sim/image_servo_loop.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <random>
#include <sstream>
#include <stdexcept>

#include "exocet_servo/trajectory/se3.h"

namespace exocet_servo {
namespace sim {

namespace {

using Clock = std::chrono::steady_clock;

double seconds(Clock::time_point a, Clock::time_point b) { return std::chrono::duration<double>(b - a).count(); }

/// CPU time of the calling thread (s).
double threadCpuSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

Eigen::Vector2d eigen(const cv::Point2f& p) { return Eigen::Vector2d(p.x, p.y); }

}  // namespace

std::string ImageServoConfig::validate() const {
  std::ostringstream errors;
  auto add = [&errors](const std::string& what) {
    if (what.empty()) return;
    if (errors.tellp() > 0) errors << "; ";
    errors << what;
  };
  auto check = [&add](bool ok, const char* field, const std::string& range) {
    if (!ok) add(std::string(field) + " must be in " + range);
  };
  const std::string s = servo.validate(), m = matcher.validate(), t = tracker.validate();
  if (!s.empty()) add("servo: " + s);
  if (!m.empty()) add("matcher: " + m);
  if (!t.empty()) add("tracker: " + t);
  check(dt_s > 0.0 && dt_s <= 100.0, "dt_s", "(0, 100]");
  check(depth_noise_fraction >= 0.0 && depth_noise_fraction <= 0.5, "depth_noise_fraction", "[0, 0.5]");
  check(max_points >= 4 && max_points <= 100000, "max_points", "[4, 100000]");
  check(depth_check_radius_px >= 0 && depth_check_radius_px <= 50, "depth_check_radius_px", "[0, 50]");
  check(depth_max_relative_step >= 0.0 && depth_max_relative_step <= 10.0, "depth_max_relative_step", "[0, 10]");
  check(max_rematches >= 0 && max_rematches <= 100000, "max_rematches", "[0, 100000]");
  check(anchor_below_error >= 0.0 && anchor_below_error <= 1.0, "anchor_below_error", "[0, 1]");
  check(anchor_max_residual_px > 0.0 && anchor_max_residual_px <= 50.0, "anchor_max_residual_px", "(0, 50]");
  return errors.str();
}

std::string toString(ImageServoStatus status) {
  switch (status) {
    case ImageServoStatus::kConverged:
      return "converged";
    case ImageServoStatus::kLostTracking:
      return "lost tracking";
    case ImageServoStatus::kServoStopped:
      return "servo stopped";
    case ImageServoStatus::kMaxIterations:
      return "max iterations";
    case ImageServoStatus::kReferenceFailed:
      return "reference failed";
  }
  return "unknown";
}

ImageServoResult runImageServo(const VentRenderer& renderer, const ImageServoSetup& setup,
                               const ImageServoConfig& config, const CurrentImageRenderer& render_current) {
  const std::string errors = config.validate();
  if (!errors.empty()) throw std::invalid_argument("ImageServoConfig: " + errors);
  control::ServoConfig law_config = config.servo;
  law_config.image_width_px = setup.controlled_camera.width_px;
  law_config.image_height_px = setup.controlled_camera.height_px;
  // The law's reference is re-set whenever the point set changes, which restarts its count: the loop keeps the budget.
  law_config.max_iterations = 1000000;
  control::InvariantServo law(law_config);
  vision::PointMatcher matcher(config.matcher);
  vision::PointTracker tracker(config.tracker);
  std::mt19937 rng(config.seed);
  std::normal_distribution<double> gauss(0.0, 1.0);

  ImageServoResult result;
  result.final_pose = setup.world_T_start;
  result.initial_error = poseError(setup.world_T_start, setup.world_T_reference);
  result.final_error = result.initial_error;

  const RenderedView reference = renderer.render(setup.reference_camera, setup.world_T_reference);
  std::string err = matcher.setReference(reference.image);
  if (!err.empty()) {
    result.message = err;
    return result;
  }

  // Reference side of the current pairing, indexed by track id.
  std::vector<Eigen::Vector2d> ref_px;
  std::vector<cv::Point2f> ref_px_cv;
  std::vector<double> ref_depth, cur_depth_factor;
  auto depth_ok = [&config](const RenderedView& view, const Eigen::Vector2d& px) {
    double d = 0.0;
    return view.smoothDepthAt(px, config.depth_check_radius_px, config.depth_max_relative_step, &d);
  };
  auto noisy = [&config, &gauss, &rng]() {
    return config.depth_noise_fraction > 0.0 ? std::max(0.1, 1.0 + config.depth_noise_fraction * gauss(rng)) : 1.0;
  };
  // Matches the current image against the reference and restarts the tracker; "" or why it failed.
  auto rematch = [&](const RenderedView& view) -> std::string {
    const vision::PointMatches m = matcher.match(view.image);
    if (!m.ok()) return m.error;
    ref_px.clear();
    ref_px_cv.clear();
    ref_depth.clear();
    cur_depth_factor.clear();
    std::vector<cv::Point2f> cur;
    std::vector<int> ids;
    const size_t n = m.reference_px.size();
    const double stride = std::max(1.0, static_cast<double>(n) / config.max_points);
    for (double k = 0.0; k < n; k += stride) {
      const size_t i = static_cast<size_t>(k);
      const Eigen::Vector2d r = eigen(m.reference_px[i]), c = eigen(m.current_px[i]);
      if (!depth_ok(reference, r) || !depth_ok(view, c)) continue;
      const double z = renderer.depthAt(setup.reference_camera, setup.world_T_reference, r);
      if (!std::isfinite(z)) continue;
      ids.push_back(static_cast<int>(ref_px.size()));
      ref_px.push_back(r);
      ref_px_cv.push_back(m.reference_px[i]);
      ref_depth.push_back(z * noisy());
      cur_depth_factor.push_back(noisy());
      cur.push_back(m.current_px[i]);
    }
    if (static_cast<int>(cur.size()) < config.tracker.min_points) {
      std::ostringstream msg;
      msg << "only " << cur.size() << " SIFT matches with a usable depth (tracker.min_points "
          << config.tracker.min_points << ")";
      return msg.str();
    }
    tracker.reset(view.image, cur, ids);
    return "";
  };

  Eigen::Isometry3d pose = setup.world_T_start;
  std::vector<int> law_ids;  // ids of the law's current reference set
  bool finished = false;
  bool anchoring = false;  // |e| fell below config.anchor_below_error
  bool force_rematch = false;
  double control_sum = 0.0, control_cpu_sum = 0.0;
  for (int it = 0; it < config.servo.max_iterations && !finished; ++it) {
    const RenderedView view =
        render_current ? render_current(pose, it) : renderer.render(setup.controlled_camera, pose);
    ImageServoIteration rec;
    rec.error = poseError(pose, setup.world_T_reference);
    auto t0 = Clock::now();
    double c0 = threadCpuSeconds();
    double control_s = 0.0, control_cpu_s = 0.0;
    if (it > 0) {
      if (anchoring) {
        rec.anchored =
            tracker.anchorOnReference(reference.image, ref_px_cv, view.image, config.anchor_max_residual_px) >= 0;
      }
      if (!rec.anchored) tracker.track(view.image);
    }
    control_s += seconds(t0, Clock::now());
    control_cpu_s += threadCpuSeconds() - c0;
    if (it == 0 || tracker.needsRematch() || force_rematch) {
      force_rematch = false;
      if (it > 0 && result.rematches >= config.max_rematches) {
        result.status = ImageServoStatus::kLostTracking;
        result.message = "lost tracking: " + std::to_string(tracker.points().size()) +
                         " points tracked and max_rematches " + std::to_string(config.max_rematches) + " spent";
        break;
      }
      const auto m0 = Clock::now();
      err = rematch(view);
      rec.match_time_s = seconds(m0, Clock::now());
      rec.rematched = true;
      if (!err.empty()) {
        result.status = ImageServoStatus::kLostTracking;
        result.message = "lost tracking at iteration " + std::to_string(it) + ": " +
                         std::to_string(tracker.points().size()) + " points tracked, SIFT re-matching failed: " + err;
        break;
      }
      if (it == 0) {
        result.initial_matches = static_cast<int>(ref_px.size());
      } else {
        ++result.rematches;
      }
      law_ids.clear();
    }
    // Depths of the tracked points (the stereo rig's job; not timed), screened for discontinuities.
    std::vector<int> ids;
    std::vector<Eigen::Vector2d> cur;
    std::vector<double> cur_depth;
    for (size_t i = 0; i < tracker.points().size(); ++i) {
      const Eigen::Vector2d p = eigen(tracker.points()[i]);
      if (!depth_ok(view, p)) continue;
      const double z = renderer.depthAt(setup.controlled_camera, pose, p);
      if (!std::isfinite(z)) continue;
      const int id = tracker.ids()[i];
      ids.push_back(id);
      cur.push_back(p);
      cur_depth.push_back(z * cur_depth_factor[id]);
    }
    t0 = Clock::now();
    c0 = threadCpuSeconds();
    if (ids != law_ids) {
      std::vector<Eigen::Vector2d> r;
      std::vector<double> rd;
      for (int id : ids) {
        r.push_back(ref_px[id]);
        rd.push_back(ref_depth[id]);
      }
      err = law.setReference(r, setup.k_estimate_reference, rd);
      if (!err.empty()) {
        result.status = ImageServoStatus::kServoStopped;
        result.servo_status = control::ServoStatus::kDegenerate;
        result.message = "reference subset unusable at iteration " + std::to_string(it) + ": " + err;
        break;
      }
      law_ids = ids;
    }
    const control::ServoStep step = law.step(cur, setup.k_estimate_controlled, cur_depth);
    control_s += seconds(t0, Clock::now());
    control_cpu_s += threadCpuSeconds() - c0;
    rec.control_time_s = control_s;
    rec.control_cpu_time_s = control_cpu_s;
    control_cpu_sum += control_cpu_s;
    rec.error_norm = step.error_norm;
    rec.servo_status = step.status;
    rec.points = static_cast<int>(cur.size());
    result.history.push_back(rec);
    control_sum += control_s;
    result.max_control_time_s = std::max(result.max_control_time_s, control_s);
    result.iterations = it + 1;
    result.servo_status = step.status;
    // (a degenerate step reports |e| = 0: only a real step's error counts)
    if (step.status == control::ServoStatus::kRunning && config.anchor_below_error > 0.0 &&
        step.error_norm < config.anchor_below_error)
      anchoring = true;
    switch (step.status) {
      case control::ServoStatus::kRunning:
        pose = pose * trajectory::expSe3(step.velocity * config.dt_s);
        break;
      case control::ServoStatus::kConverged:
        result.status = ImageServoStatus::kConverged;
        result.message = step.message;
        finished = true;
        break;
      case control::ServoStatus::kDegenerate:
        // A point set left on one plane (e.g. the seabed after an occlusion) cannot drive the translations: match the
        // whole next image again rather than stop (the law restarts with the new set).
        if (result.rematches < config.max_rematches) {
          force_rematch = true;
          break;
        }
        result.status = ImageServoStatus::kServoStopped;
        result.message = control::toString(step.status) + ": " + step.message;
        finished = true;
        break;
      default:
        result.status = ImageServoStatus::kServoStopped;
        result.message = control::toString(step.status) + ": " + step.message;
        finished = true;
        break;
    }
  }
  if (!finished && result.message.empty()) {
    result.status = ImageServoStatus::kMaxIterations;
    result.message = "not converged after " + std::to_string(result.iterations) + " iterations (servo.max_iterations)";
  }
  result.final_pose = pose;
  result.final_error = poseError(pose, setup.world_T_reference);
  if (!result.history.empty()) {
    result.mean_control_time_s = control_sum / result.history.size();
    result.mean_control_cpu_time_s = control_cpu_sum / result.history.size();
  }
  return result;
}

}  // namespace sim
}  // namespace exocet_servo
