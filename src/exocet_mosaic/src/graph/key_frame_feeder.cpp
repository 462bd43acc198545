#include "exocet_mosaic/graph/key_frame_feeder.h"

#include <algorithm>
#include <cmath>
#include <iterator>
#include <sstream>
#include <stdexcept>

#include <Eigen/Eigenvalues>

namespace exocet_mosaic {
namespace graph {

namespace {

Eigen::Matrix2d rotation(double angle_rad) {
  Eigen::Matrix2d r;
  r << std::cos(angle_rad), -std::sin(angle_rad), std::sin(angle_rad), std::cos(angle_rad);
  return r;
}

void requireFinite(bool finite, const char* what) {
  if (!finite) throw std::invalid_argument(std::string("key-frame feeder: ") + what + " is not finite");
}

}  // namespace

std::string KeyFrameFeederConfig::validate() const {
  std::ostringstream e;
  if (!(keyframe_distance_m > 0.0 && keyframe_distance_m <= 100.0))
    e << "keyframe_distance_m = " << keyframe_distance_m << " outside (0, 100] m; ";
  if (!(keyframe_max_interval_s > 0.0 && keyframe_max_interval_s <= 3600.0))
    e << "keyframe_max_interval_s = " << keyframe_max_interval_s << " outside (0, 3600] s; ";
  if (!(image_yaw_sigma_rad > 0.0 && image_yaw_sigma_rad <= 1.0))
    e << "image_yaw_sigma_rad = " << image_yaw_sigma_rad << " outside (0, 1] rad; ";
  if (!(odometry_floor_m >= 0.0 && odometry_floor_m <= 10.0))
    e << "odometry_floor_m = " << odometry_floor_m << " outside [0, 10] m; ";
  if (!(gap_sigma_m > 0.0 && gap_sigma_m <= 1000.0)) e << "gap_sigma_m = " << gap_sigma_m << " outside (0, 1000] m; ";
  if (!(gap_drift_mps >= 0.0 && gap_drift_mps <= 100.0))
    e << "gap_drift_mps = " << gap_drift_mps << " outside [0, 100] m/s; ";
  if (!(gap_yaw_sigma_rad > 0.0 && gap_yaw_sigma_rad <= 10.0))
    e << "gap_yaw_sigma_rad = " << gap_yaw_sigma_rad << " outside (0, 10] rad; ";
  if (!(dr_measurement_sigma_m > 0.0 && dr_measurement_sigma_m <= 100.0))
    e << "dr_measurement_sigma_m = " << dr_measurement_sigma_m << " outside (0, 100] m; ";
  if (!(dr_noise_m2_per_m >= 0.0 && dr_noise_m2_per_m <= 100.0))
    e << "dr_noise_m2_per_m = " << dr_noise_m2_per_m << " outside [0, 100] m^2/m; ";
  if (!(dr_noise_m2_per_s >= 0.0 && dr_noise_m2_per_s <= 100.0))
    e << "dr_noise_m2_per_s = " << dr_noise_m2_per_s << " outside [0, 100] m^2/s; ";
  if (!(dr_max_gap_s > 0.0 && dr_max_gap_s <= 3600.0))
    e << "dr_max_gap_s = " << dr_max_gap_s << " outside (0, 3600] s; ";
  std::string text = e.str();
  if (text.size() >= 2) text.resize(text.size() - 2);
  return text;
}

KeyFrameFeeder::KeyFrameFeeder(const KeyFrameFeederConfig& config, BackgroundPoseGraph* graph)
    : config_(config), graph_(graph) {
  const std::string error = config_.validate();
  if (!error.empty()) throw std::invalid_argument("key-frame feeder: " + error);
  if (!graph_) throw std::invalid_argument("key-frame feeder: no pose graph given");
}

int64_t KeyFrameFeeder::start(double stamp_s, const Eigen::Vector2d& camera_en_m, double yaw_rad) {
  requireFinite(std::isfinite(stamp_s) && camera_en_m.allFinite() && std::isfinite(yaw_rad), "the start");
  if (started()) throw std::invalid_argument("key-frame feeder: start() called twice");
  FeederKeyFrame k;
  k.id = 0;
  k.stamp_s = stamp_s;
  k.initial.position_en_m = camera_en_m;
  k.initial.yaw_rad = yaw_rad;
  graph_->addKeyFrame(k.id, k.stamp_s, k.initial);
  key_frames_.push_back(k);
  last_stamp_s_ = stamp_s;
  if (!placeByDeadReckoning(0)) awaitDeadReckoning(0);
  return k.id;
}

Pose2d KeyFrameFeeder::chainPose() const {
  if (key_frames_.empty()) return Pose2d();
  Pose2d p = key_frames_.back().initial;
  p.position_en_m += displacement_en_m_;
  p.yaw_rad = wrapAngle(p.yaw_rad + yaw_change_rad_);
  return p;
}

std::optional<int64_t> KeyFrameFeeder::addImageMotion(double stamp_s, const Eigen::Vector2d& displacement_en_m,
                                                      const Eigen::Matrix2d& covariance_m2, double yaw_change_rad,
                                                      std::optional<double> sensor_yaw_rad,
                                                      double sensor_yaw_sigma_rad) {
  if (!started()) throw std::invalid_argument("key-frame feeder: an image motion before start()");
  requireFinite(std::isfinite(stamp_s) && displacement_en_m.allFinite() && covariance_m2.allFinite() &&
                    std::isfinite(yaw_change_rad) && (!sensor_yaw_rad || std::isfinite(*sensor_yaw_rad)),
                "an image motion");
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eigen(0.5 * (covariance_m2 + covariance_m2.transpose()));
  if (eigen.eigenvalues().minCoeff() < -1e-12)
    throw std::invalid_argument("key-frame feeder: an image motion's covariance is not positive semi-definite");
  displacement_en_m_ += displacement_en_m;
  covariance_m2_ += 0.5 * (covariance_m2 + covariance_m2.transpose());
  yaw_change_rad_ += yaw_change_rad;
  ++pairs_;
  const bool far = displacement_en_m_.norm() >= config_.keyframe_distance_m;
  const bool late = stamp_s - key_frames_.back().stamp_s >= config_.keyframe_max_interval_s;
  last_stamp_s_ = stamp_s;
  if (!far && !late) return std::nullopt;
  // Odometry in the earlier key frame's axes: p_B - p_A turned by -yaw_A.
  const Eigen::Matrix2d to_a = rotation(-key_frames_.back().initial.yaw_rad);
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
  covariance.topLeftCorner<2, 2>() = to_a * covariance_m2_ * to_a.transpose() +
                                     Eigen::Matrix2d::Identity() * config_.odometry_floor_m * config_.odometry_floor_m;
  covariance(2, 2) = pairs_ * config_.image_yaw_sigma_rad * config_.image_yaw_sigma_rad;
  return makeKeyFrame(stamp_s, covariance, sensor_yaw_rad, sensor_yaw_sigma_rad);
}

int64_t KeyFrameFeeder::makeKeyFrame(double stamp_s, const Eigen::Matrix3d& odometry_covariance,
                                     std::optional<double> sensor_yaw_rad, double sensor_yaw_sigma_rad) {
  const FeederKeyFrame& a = key_frames_.back();
  FeederKeyFrame b;
  b.id = a.id + 1;
  b.stamp_s = stamp_s;
  RelativePose2d delta;
  delta.translation_m = rotation(-a.initial.yaw_rad) * displacement_en_m_;
  delta.yaw_rad = wrapAngle(yaw_change_rad_);
  // Started where the graph last put the previous key frame, moved by this odometry: the chain alone drifts, and a
  // new key frame started far from the solution costs the bounded windowed solve its convergence.
  b.initial = chainPose();
  if (const std::shared_ptr<const GraphSnapshot> snapshot = graph_->snapshot())
    if (const KeyFramePose* solved = snapshot->find(a.id)) b.initial = compose(solved->pose, delta);
  graph_->addKeyFrame(b.id, b.stamp_s, b.initial);
  graph_->addOdometry(a.id, b.id, delta, odometry_covariance);
  if (sensor_yaw_rad && sensor_yaw_sigma_rad > 0.0) graph_->addHeading(b.id, *sensor_yaw_rad, sensor_yaw_sigma_rad);
  key_frames_.push_back(b);
  if (!placeByDeadReckoning(key_frames_.size() - 1)) awaitDeadReckoning(key_frames_.size() - 1);
  displacement_en_m_.setZero();
  covariance_m2_.setZero();
  yaw_change_rad_ = 0.0;
  pairs_ = 0;
  return b.id;
}

int64_t KeyFrameFeeder::addImageFailure(double stamp_s, const Eigen::Vector2d& fused_displacement_en_m,
                                        double fused_yaw_rad) {
  if (!started()) throw std::invalid_argument("key-frame feeder: an image failure before start()");
  requireFinite(std::isfinite(stamp_s) && fused_displacement_en_m.allFinite() && std::isfinite(fused_yaw_rad),
                "an image failure");
  // Across the gap the chain knows nothing: the fused navigation's displacement stands in, with its relative error.
  displacement_en_m_ = fused_displacement_en_m;
  yaw_change_rad_ = wrapAngle(fused_yaw_rad - key_frames_.back().initial.yaw_rad);
  pairs_ = 0;
  const double gap_s = std::max(0.0, stamp_s - key_frames_.back().stamp_s);
  const double sigma_m = config_.gap_sigma_m + config_.gap_drift_mps * gap_s;
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
  covariance(0, 0) = covariance(1, 1) = sigma_m * sigma_m;
  covariance(2, 2) = config_.gap_yaw_sigma_rad * config_.gap_yaw_sigma_rad;
  last_stamp_s_ = stamp_s;
  return makeKeyFrame(stamp_s, covariance, std::nullopt, 0.0);
}

void KeyFrameFeeder::addDeadReckoning(double stamp_s, const Eigen::Vector2d& camera_en_m,
                                      const Eigen::Matrix2d& covariance_m2) {
  requireFinite(std::isfinite(stamp_s) && camera_en_m.allFinite() && covariance_m2.allFinite(), "a dead reckoning");
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eigen(0.5 * (covariance_m2 + covariance_m2.transpose()));
  if (!(eigen.eigenvalues().minCoeff() > 0.0))
    throw std::invalid_argument("key-frame feeder: a dead reckoning's covariance is not positive definite");
  // Out of order or repeated: left out, so that the samples stay in order.
  if (!dr_samples_.empty() && !(stamp_s > dr_samples_.back().stamp_s)) return;
  dr_samples_.push_back(DeadReckoningSample{stamp_s, camera_en_m, 0.5 * (covariance_m2 + covariance_m2.transpose())});
  while (dr_samples_.size() > kDeadReckoningHistoryMax ||
         (dr_samples_.size() > 2 && dr_samples_.front().stamp_s < stamp_s - kDeadReckoningHistoryS))
    dr_samples_.pop_front();
  std::vector<size_t> waiting;
  for (const size_t index : awaiting_dr_)
    if (!placeByDeadReckoning(index)) waiting.push_back(index);
  awaiting_dr_.swap(waiting);
}

void KeyFrameFeeder::awaitDeadReckoning(size_t index) {
  awaiting_dr_.push_back(index);
  // A key frame whose dead reckoning has not come kDeadReckoningHistoryS after it will not get one (the dead reckoning
  // stopped): it is let go, so that the list does not grow for the rest of the dive.
  const double oldest_s = key_frames_[index].stamp_s - kDeadReckoningHistoryS;
  const auto kept = std::find_if(awaiting_dr_.begin(), awaiting_dr_.end(),
                                 [&](size_t i) { return key_frames_[i].stamp_s >= oldest_s; });
  awaiting_dr_.erase(awaiting_dr_.begin(), kept);
}

bool KeyFrameFeeder::placeByDeadReckoning(size_t index) {
  const double t = key_frames_[index].stamp_s;
  if (dr_samples_.empty() || dr_samples_.back().stamp_s < t) return false;  // the sample after it is still to come
  const auto after = std::lower_bound(dr_samples_.begin(), dr_samples_.end(), t,
                                      [](const DeadReckoningSample& s, double v) { return s.stamp_s < v; });
  if (after->stamp_s > t && after == dr_samples_.begin()) return true;  // no sample before it: it has no position
  const DeadReckoningSample& b = *after;
  const DeadReckoningSample& a = after->stamp_s > t ? *std::prev(after) : b;
  if (b.stamp_s - a.stamp_s > config_.dr_max_gap_s) return true;  // a gap in the dead reckoning
  const double w = b.stamp_s > a.stamp_s ? (t - a.stamp_s) / (b.stamp_s - a.stamp_s) : 0.0;
  key_frames_[index].dead_reckoning_en_m = (1.0 - w) * a.camera_en_m + w * b.camera_en_m;
  tieByDeadReckoning(index, (1.0 - w) * a.covariance_m2 + w * b.covariance_m2);
  return true;
}

void KeyFrameFeeder::tieByDeadReckoning(size_t index, const Eigen::Matrix2d& covariance_m2) {
  const FeederKeyFrame& b = key_frames_[index];
  if (!dr_anchored_) {
    // Where the dead reckoning started the dive, as it knows it (its launch point's error): a prior on the graph's
    // absolute position, which the later samples, correlated with it, do not repeat.
    graph_->addPositionFix(b.stamp_s, *b.dead_reckoning_en_m, covariance_m2, false);
    dr_anchored_ = true;
    return;
  }
  if (index == 0 || !key_frames_[index - 1].dead_reckoning_en_m) return;  // the one before has none: no tie
  const FeederKeyFrame& a = key_frames_[index - 1];
  const Eigen::Vector2d displacement = *b.dead_reckoning_en_m - *a.dead_reckoning_en_m;
  const double variance = 2.0 * config_.dr_measurement_sigma_m * config_.dr_measurement_sigma_m +
                          config_.dr_noise_m2_per_m * displacement.norm() +
                          config_.dr_noise_m2_per_s * std::max(0.0, b.stamp_s - a.stamp_s);
  graph_->addRelativePosition(a.id, b.id, rotation(-a.initial.yaw_rad) * displacement,
                              Eigen::Matrix2d::Identity() * variance);
  ++dr_factors_;
}

void KeyFrameFeeder::addPositionFix(double stamp_s, const Eigen::Vector2d& camera_en_m,
                                    const Eigen::Matrix2d& covariance_m2, bool robust) {
  requireFinite(std::isfinite(stamp_s) && camera_en_m.allFinite() && covariance_m2.allFinite(), "a position fix");
  graph_->addPositionFix(stamp_s, camera_en_m, covariance_m2, robust);
}

}  // namespace graph
}  // namespace exocet_mosaic
