#include "exocet_servo/control/image_servo_controller.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <limits>
#include <sstream>
#include <stdexcept>

#include <Eigen/Geometry>

namespace exocet_servo {
namespace control {

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

/// Pairs consistent with one rigid motion between the two sets of 3D points (RANSAC over 3-point samples, the
/// consensus refitted by Umeyama's least squares): a pair is kept when its residual is within fraction x its depth.
std::vector<bool> rigidInliers(const std::vector<Eigen::Vector3d>& a, const std::vector<Eigen::Vector3d>& b,
                               double fraction, std::mt19937* rng) {
  const size_t n = a.size();
  std::vector<bool> best(n, true);
  if (n < 4 || fraction <= 0.0) return best;
  const auto inliers_of = [&](const Eigen::Matrix4d& t, std::vector<bool>* in) {
    int count = 0;
    for (size_t i = 0; i < n; ++i) {
      const Eigen::Vector3d p = t.topLeftCorner<3, 3>() * a[i] + t.topRightCorner<3, 1>();
      (*in)[i] = (p - b[i]).norm() <= fraction * b[i].z();
      count += (*in)[i];
    }
    return count;
  };
  const auto fit = [&](const std::vector<size_t>& idx) {
    Eigen::Matrix3Xd pa(3, idx.size()), pb(3, idx.size());
    for (size_t k = 0; k < idx.size(); ++k) {
      pa.col(k) = a[idx[k]];
      pb.col(k) = b[idx[k]];
    }
    return Eigen::Matrix4d(Eigen::umeyama(pa, pb, false));
  };
  std::uniform_int_distribution<size_t> pick(0, n - 1);
  int best_count = -1;
  std::vector<bool> in(n);
  for (int trial = 0; trial < 300; ++trial) {
    const size_t i = pick(*rng), j = pick(*rng), k = pick(*rng);
    if (i == j || j == k || i == k) continue;
    const int count = inliers_of(fit({i, j, k}), &in);
    if (count > best_count) best_count = count, best = in;
  }
  std::vector<size_t> consensus;
  for (size_t i = 0; i < n; ++i)
    if (best[i]) consensus.push_back(i);
  if (consensus.size() >= 3) inliers_of(fit(consensus), &best);
  return best;
}

ServoConfig lawConfig(const ImageServoConfig& config, int width_px, int height_px) {
  const std::string errors = config.validate();
  if (!errors.empty()) throw std::invalid_argument("ImageServoConfig: " + errors);
  ServoConfig law = config.servo;
  law.image_width_px = width_px;
  law.image_height_px = height_px;
  // The law's reference is re-set whenever the point set changes, which restarts its count: the caller keeps the
  // budget.
  law.max_iterations = 1000000;
  return law;
}

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
  check(rematch_below_error >= 0.0 && rematch_below_error <= 1.0, "rematch_below_error", "[0, 1]");
  check(stall_rematch_images >= 0 && stall_rematch_images <= 100000, "stall_rematch_images", "[0, 100000]");
  check(rigid_outlier_fraction >= 0.0 && rigid_outlier_fraction <= 1.0, "rigid_outlier_fraction", "[0, 1]");
  return errors.str();
}

std::string toString(ImageStepStatus status) {
  switch (status) {
    case ImageStepStatus::kRunning:
      return "running";
    case ImageStepStatus::kConverged:
      return "converged";
    case ImageStepStatus::kLostTracking:
      return "lost tracking";
    case ImageStepStatus::kServoStopped:
      return "servo stopped";
    case ImageStepStatus::kNoReference:
      return "no reference";
  }
  return "unknown";
}

ImageServoController::ImageServoController(const ImageServoConfig& config, const Eigen::Matrix3d& k_estimate_reference,
                                           const Eigen::Matrix3d& k_estimate_current, int current_width_px,
                                           int current_height_px)
    : config_(config),
      k_reference_(k_estimate_reference),
      k_current_(k_estimate_current),
      law_(lawConfig(config, current_width_px, current_height_px)),
      matcher_(config.matcher),
      tracker_(config.tracker),
      rng_(config.seed) {}

std::string ImageServoController::setReference(const cv::Mat& reference_image, const DepthLookup& reference_depth) {
  have_reference_ = false;
  iterations_ = rematches_ = initial_matches_ = stall_rematches_ = stalled_images_ = 0;
  best_error_since_match_ = std::numeric_limits<double>::infinity();
  anchoring_ = force_rematch_ = rematched_near_goal_ = false;
  law_ids_.clear();
  ref_px_.clear();
  ref_px_cv_.clear();
  ref_depth_.clear();
  cur_depth_factor_.clear();
  if (!reference_depth) return "no depth lookup for the reference image";
  const std::string err = matcher_.setReference(reference_image);
  if (!err.empty()) return err;
  reference_image_ = reference_image.clone();
  reference_depth_ = reference_depth;
  have_reference_ = true;
  return "";
}

std::string ImageServoController::rematch(const cv::Mat& image, const DepthLookup& current_depth) {
  const vision::PointMatches m = matcher_.match(image);
  if (!m.ok()) return m.error;
  const auto noisy = [this]() {
    return config_.depth_noise_fraction > 0.0 ? std::max(0.1, 1.0 + config_.depth_noise_fraction * gauss_(rng_)) : 1.0;
  };
  ref_px_.clear();
  ref_px_cv_.clear();
  ref_depth_.clear();
  cur_depth_factor_.clear();
  std::vector<cv::Point2f> cur;
  std::vector<int> ids;
  // Pairs with a usable depth on both sides, checked against one rigid motion in 3D.
  std::vector<size_t> usable;
  std::vector<double> ref_z, cur_z;
  std::vector<Eigen::Vector3d> ref_3d, cur_3d;
  const Eigen::Matrix3d k_ref_inv = k_reference_.inverse(), k_cur_inv = k_current_.inverse();
  for (size_t i = 0; i < m.reference_px.size(); ++i) {
    const Eigen::Vector2d r = eigen(m.reference_px[i]), c = eigen(m.current_px[i]);
    const double zr = reference_depth_(r), zc = current_depth(c);
    if (!std::isfinite(zr) || !std::isfinite(zc)) continue;
    usable.push_back(i);
    ref_z.push_back(zr);
    cur_z.push_back(zc);
    ref_3d.push_back(zr * (k_ref_inv * r.homogeneous()));
    cur_3d.push_back(zc * (k_cur_inv * c.homogeneous()));
  }
  const std::vector<bool> rigid = rigidInliers(ref_3d, cur_3d, config_.rigid_outlier_fraction, &ransac_rng_);
  std::vector<size_t> kept;
  for (size_t u = 0; u < usable.size(); ++u)
    if (rigid[u]) kept.push_back(u);
  const size_t n = kept.size();
  const double stride = std::max(1.0, static_cast<double>(n) / config_.max_points);
  for (double k = 0.0; k < n; k += stride) {
    const size_t u = kept[static_cast<size_t>(k)], i = usable[u];
    const Eigen::Vector2d r = eigen(m.reference_px[i]);
    const double z_ref = ref_z[u];
    ids.push_back(static_cast<int>(ref_px_.size()));
    ref_px_.push_back(r);
    ref_px_cv_.push_back(m.reference_px[i]);
    ref_depth_.push_back(z_ref * noisy());
    cur_depth_factor_.push_back(noisy());
    cur.push_back(m.current_px[i]);
  }
  if (static_cast<int>(cur.size()) < config_.tracker.min_points) {
    std::ostringstream msg;
    msg << "only " << cur.size() << " SIFT matches with a usable depth (tracker.min_points "
        << config_.tracker.min_points << ")";
    return msg.str();
  }
  tracker_.reset(image, cur, ids);
  law_ids_.clear();
  return "";
}

ImageStep ImageServoController::step(const cv::Mat& current_image, const DepthLookup& current_depth) {
  ImageStep rec;
  if (!have_reference_) {
    rec.status = ImageStepStatus::kNoReference;
    rec.message = "no usable reference image: call setReference() first";
    return rec;
  }
  if (!current_depth) {
    rec.status = ImageStepStatus::kServoStopped;
    rec.message = "no depth lookup for the current image";
    return rec;
  }
  const int it = iterations_++;
  auto t0 = Clock::now();
  double c0 = threadCpuSeconds();
  double control_s = 0.0, control_cpu_s = 0.0;
  if (it > 0) {
    if (anchoring_)
      rec.anchored =
          tracker_.anchorOnReference(reference_image_, ref_px_cv_, current_image, config_.anchor_max_residual_px) >= 0;
    if (!rec.anchored) tracker_.track(current_image);
  }
  control_s += seconds(t0, Clock::now());
  control_cpu_s += threadCpuSeconds() - c0;
  if (it == 0 || tracker_.needsRematch() || force_rematch_) {
    force_rematch_ = false;
    if (it > 0 && rematches_ >= config_.max_rematches) {
      rec.status = ImageStepStatus::kLostTracking;
      rec.message = "lost tracking: " + std::to_string(tracker_.points().size()) +
                    " points tracked and max_rematches " + std::to_string(config_.max_rematches) + " spent";
      return rec;
    }
    const auto m0 = Clock::now();
    const std::string err = rematch(current_image, current_depth);
    rec.match_time_s = seconds(m0, Clock::now());
    rec.rematched = true;
    if (!err.empty()) {
      rec.status = ImageStepStatus::kLostTracking;
      rec.message = "lost tracking at iteration " + std::to_string(it) + ": " +
                    std::to_string(tracker_.points().size()) + " points tracked, SIFT re-matching failed: " + err;
      return rec;
    }
    if (it == 0)
      initial_matches_ = static_cast<int>(ref_px_.size());
    else
      ++rematches_;
  }
  // Depths of the tracked points (the stereo rig's job; not timed).
  std::vector<int> ids;
  std::vector<Eigen::Vector2d> cur;
  std::vector<double> cur_depth;
  for (size_t i = 0; i < tracker_.points().size(); ++i) {
    const Eigen::Vector2d p = eigen(tracker_.points()[i]);
    const double z = current_depth(p);
    if (!std::isfinite(z)) continue;
    const int id = tracker_.ids()[i];
    ids.push_back(id);
    cur.push_back(p);
    cur_depth.push_back(z * cur_depth_factor_[id]);
  }
  t0 = Clock::now();
  c0 = threadCpuSeconds();
  const std::vector<int> law_ids_before = law_ids_;
  if (ids != law_ids_) {
    std::vector<Eigen::Vector2d> r;
    std::vector<double> rd;
    for (int id : ids) {
      r.push_back(ref_px_[id]);
      rd.push_back(ref_depth_[id]);
    }
    const std::string err = law_.setReference(r, k_reference_, rd);
    if (!err.empty()) {
      rec.status = ImageStepStatus::kServoStopped;
      rec.servo_status = ServoStatus::kDegenerate;
      rec.message = "reference subset unusable at iteration " + std::to_string(it) + ": " + err;
      return rec;
    }
    law_ids_ = ids;
  }
  const ServoStep step = law_.step(cur, k_current_, cur_depth);
  control_s += seconds(t0, Clock::now());
  control_cpu_s += threadCpuSeconds() - c0;
  rec.control_time_s = control_s;
  rec.control_cpu_time_s = control_cpu_s;
  rec.error_norm = step.error_norm;
  rec.servo_status = step.status;
  rec.points = static_cast<int>(cur.size());
  rec.message = step.message;
  // (a degenerate step reports |e| = 0: only a real step's error counts)
  if (step.status == ServoStatus::kRunning && config_.anchor_below_error > 0.0 &&
      step.error_norm < config_.anchor_below_error)
    anchoring_ = true;
  if (rec.rematched || ids != law_ids_before) {
    // A new point set (matched again, or tracks lost): its |e| is not comparable with the last one's.
    best_error_since_match_ = std::numeric_limits<double>::infinity();
    stalled_images_ = 0;
  }
  if (step.status == ServoStatus::kRunning) {
    if (step.error_norm < 0.8 * best_error_since_match_) {
      best_error_since_match_ = step.error_norm;
      stalled_images_ = 0;
    } else if (++stalled_images_ >= config_.stall_rematch_images && config_.stall_rematch_images > 0 &&
               step.error_norm > config_.rematch_below_error && rematches_ < config_.max_rematches && !force_rematch_) {
      force_rematch_ = true;
      ++stall_rematches_;
      stalled_images_ = 0;
    }
  }
  if (step.status == ServoStatus::kRunning && step.error_norm < config_.rematch_below_error && !rematched_near_goal_ &&
      rematches_ < config_.max_rematches) {
    rematched_near_goal_ = true;
    force_rematch_ = true;
  }
  switch (step.status) {
    case ServoStatus::kRunning:
      rec.status = ImageStepStatus::kRunning;
      rec.velocity = step.velocity;
      break;
    case ServoStatus::kConverged:
      rec.status = ImageStepStatus::kConverged;
      break;
    case ServoStatus::kDegenerate:
      // A point set left on one plane (e.g. the seabed after an occlusion) cannot drive the translations: match the
      // whole next image again rather than stop (the law restarts with the new set).
      if (rematches_ < config_.max_rematches) {
        force_rematch_ = true;
        rec.status = ImageStepStatus::kRunning;  // no motion this image
        break;
      }
      rec.status = ImageStepStatus::kServoStopped;
      rec.message = toString(step.status) + ": " + step.message;
      break;
    default:
      rec.status = ImageStepStatus::kServoStopped;
      rec.message = toString(step.status) + ": " + step.message;
      break;
  }
  return rec;
}

}  // namespace control
}  // namespace exocet_servo
