#include "exocet_mosaic/graph/loop_closer.h"

#include <algorithm>
#include <chrono>
#include <sstream>
#include <stdexcept>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "exocet_common/background_priority.h"

namespace exocet_mosaic {
namespace graph {

std::string LoopCloserConfig::validate() const {
  std::ostringstream e;
  if (const std::string c = candidates.validate(); !c.empty()) e << "candidates: " << c << "; ";
  if (const std::string v = verifier.validate(); !v.empty()) e << "verifier: " << v << "; ";
  if (max_loops_per_key_frame < 1) e << "max_loops_per_key_frame = " << max_loops_per_key_frame << " must be >= 1; ";
  if (max_queue < 1) e << "max_queue = " << max_queue << " must be >= 1; ";
  if (feature_cache_size < 2) e << "feature_cache_size = " << feature_cache_size << " must be >= 2; ";
  if (jpeg_quality < 50 || jpeg_quality > 100) e << "jpeg_quality = " << jpeg_quality << " outside [50, 100]; ";
  if (max_image_side_px < 64 || max_image_side_px > 100000)
    e << "max_image_side_px = " << max_image_side_px << " outside [64, 100000]; ";
  if (!(idle_wait_s > 0.0)) e << "idle_wait_s = " << idle_wait_s << " must be > 0; ";
  if (images_in_memory < 1) e << "images_in_memory = " << images_in_memory << " must be >= 1; ";
  std::string text = e.str();
  if (text.size() >= 2) text.resize(text.size() - 2);
  return text;
}

namespace {

const LoopCloserConfig& validated(const LoopCloserConfig& config) {
  const std::string error = config.validate();
  if (!error.empty()) throw std::invalid_argument("loop closer: " + error);
  return config;
}

/// The first words of a refusal (before the measured values), so that refusals group by kind.
std::string refusalKind(const std::string& reason) {
  const size_t cut = reason.find_first_of(":(0123456789");
  std::string kind = reason.substr(0, cut);
  while (!kind.empty() && (kind.back() == ' ' || kind.back() == ',')) kind.pop_back();
  return kind.empty() ? reason : kind;
}

}  // namespace

LoopCloser::LoopCloser(const LoopCloserConfig& config, BackgroundPoseGraph* graph)
    : config_(validated(config)),
      graph_(graph),
      verifier_(config_.verifier),
      finder_(config_.candidates),
      images_(config_.image_folder, config_.images_in_memory) {
  if (!graph_) throw std::invalid_argument("loop closer: no pose graph given");
  worker_ = std::thread([this]() { run(); });
}

LoopCloser::~LoopCloser() { stop(); }

void LoopCloser::stop() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
  }
  wake_.notify_all();
  idle_.notify_all();
  if (worker_.joinable()) worker_.join();
}

void LoopCloser::addKeyFrame(const LoopCloserKeyFrame& key_frame) {
  if (key_frame.gray.empty() || key_frame.gray.type() != CV_8UC1 || key_frame.gray.size() != key_frame.view.image_size)
    throw std::invalid_argument("loop closer: key frame " + std::to_string(key_frame.key_frame.id) +
                                ": the image must be 8-bit grey of the view's size");
  checkLoopView(key_frame.view, "key frame");
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (stopping_) return;
    Pending pending;
    pending.key_frame = key_frame;
    const int side = std::max(key_frame.gray.cols, key_frame.gray.rows);
    if (side > config_.max_image_side_px) {
      // Downscaled, its camera with it: pixel centres scale about the image's corner (x' + 0.5 = s (x + 0.5)).
      const double f = static_cast<double>(config_.max_image_side_px) / side;
      cv::resize(key_frame.gray, pending.key_frame.gray, cv::Size(), f, f, cv::INTER_AREA);
      LoopKeyFrame& k = pending.key_frame.key_frame;
      k.camera.fx_px *= f;
      k.camera.fy_px *= f;
      k.camera.cx_px = (k.camera.cx_px + 0.5) * f - 0.5;
      k.camera.cy_px = (k.camera.cy_px + 0.5) * f - 0.5;
      k.camera.width_px = pending.key_frame.gray.cols;
      k.camera.height_px = pending.key_frame.gray.rows;
      Eigen::Matrix3d& m = pending.key_frame.view.camera_matrix;
      m(0, 0) *= f;
      m(1, 1) *= f;
      m(0, 1) *= f;
      m(0, 2) = (m(0, 2) + 0.5) * f - 0.5;
      m(1, 2) = (m(1, 2) + 0.5) * f - 0.5;
      pending.key_frame.view.image_size = pending.key_frame.gray.size();
    } else {
      pending.key_frame.gray = key_frame.gray.clone();  // the caller may reuse its buffer
    }
    queue_.push_back(std::move(pending));
    ++stats_.key_frames;
    // Full: the oldest waiting key frame is only kept as a candidate, not searched (the newest matter most live).
    int searching = 0;
    for (const Pending& p : queue_) searching += p.search;
    for (Pending& p : queue_) {
      if (searching <= config_.max_queue) break;
      if (p.search) {
        p.search = false;
        --searching;
        ++stats_.dropped;
      }
    }
  }
  wake_.notify_one();
}

bool LoopCloser::waitIdle(double timeout_s) {
  std::unique_lock<std::mutex> lock(mutex_);
  return idle_.wait_for(lock, std::chrono::duration<double>(timeout_s), [this]() {
    return stopping_ || (queue_.empty() && !busy_);
  }) && !stopping_;
}

LoopCloserStats LoopCloser::stats() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return stats_;
}

void LoopCloser::run() {
  // Loops may be verified late (the graph takes them whenever they come); the chain's frames may not wait.
  exocet_common::lowerThisThreadPriority();
  for (;;) {
    Pending pending;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      busy_ = false;
      idle_.notify_all();
      wake_.wait_for(lock, std::chrono::duration<double>(config_.idle_wait_s),
                     [this]() { return stopping_ || !queue_.empty(); });
      if (stopping_) return;
      if (queue_.empty()) continue;
      pending = std::move(queue_.front());
      queue_.pop_front();
      busy_ = true;
    }
    try {
      process(pending);
    } catch (const std::exception& e) {
      std::lock_guard<std::mutex> lock(mutex_);
      stats_.last_error = std::string("key frame ") + std::to_string(pending.key_frame.key_frame.id) + ": " + e.what();
    }
  }
}

const LoopFeatures* LoopCloser::featuresOf(int64_t id, const cv::Mat* gray) {
  for (auto it = feature_cache_.begin(); it != feature_cache_.end(); ++it)
    if (it->first == id) {
      feature_cache_.splice(feature_cache_.begin(), feature_cache_, it);
      return &feature_cache_.front().second;
    }
  cv::Mat image;
  if (gray) {
    image = *gray;
  } else {
    const std::optional<std::vector<uchar>> jpeg = images_.get(id);
    if (jpeg) image = cv::imdecode(*jpeg, cv::IMREAD_GRAYSCALE);
    if (image.empty()) return nullptr;
  }
  feature_cache_.emplace_front(id, verifier_.features(image));
  while (static_cast<int>(feature_cache_.size()) > config_.feature_cache_size) feature_cache_.pop_back();
  return &feature_cache_.front().second;
}

void LoopCloser::process(const Pending& pending) {
  const LoopCloserKeyFrame& k = pending.key_frame;
  // The stored key frames at the graph's latest poses (their covariances as given: the graph's marginals are costly).
  const std::shared_ptr<const GraphSnapshot> snapshot = graph_->snapshot();
  if (snapshot && snapshot->sequence != snapshot_applied_) {
    for (const KeyFramePose& p : snapshot->key_frames) {
      if (!views_.count(p.id)) continue;
      const LoopKeyFrame& old = finder_.keyFrame(p.id);
      finder_.updatePose(p.id, p.pose, old.position_cov_m2, old.yaw_sigma_rad);
    }
    snapshot_applied_ = snapshot->sequence;
  }
  // The new key frame where the graph has it, if it got there already.
  LoopKeyFrame query = k.key_frame;
  if (snapshot)
    if (const KeyFramePose* p = snapshot->find(query.id)) query.pose = p->pose;

  int added = 0;
  if (pending.search) {
    for (const LoopCandidate& c : finder_.candidates(query)) {
      if (added >= config_.max_loops_per_key_frame) break;
      {
        std::lock_guard<std::mutex> lock(mutex_);
        if (stopping_) return;
        ++stats_.candidates;
      }
      const LoopFeatures* old_features = featuresOf(c.id, nullptr);
      if (!old_features) {
        std::lock_guard<std::mutex> lock(mutex_);
        ++stats_.refusals["image unavailable"];
        stats_.last_refusal = "key frames " + std::to_string(c.id) + " -> " + std::to_string(query.id) +
                              ": the earlier key frame's image is unavailable (" + images_.stats().last_error + ")";
        continue;
      }
      // The query's features go in front of the candidate's, which stay (feature_cache_size >= 2; list nodes stay put).
      const LoopVerification v =
          verifier_.verify(*old_features, views_.at(c.id), *featuresOf(query.id, &k.gray), k.view);
      std::lock_guard<std::mutex> lock(mutex_);
      if (!v.accepted) {
        ++stats_.refusals[refusalKind(v.reason)];
        stats_.last_refusal =
            "key frames " + std::to_string(c.id) + " -> " + std::to_string(query.id) + ": " + v.reason;
        continue;
      }
      graph_->addLoop(c.id, query.id, v.new_in_old, v.covariance);
      ++stats_.loops_added;
      ++added;
    }
  }
  std::vector<uchar> jpeg;
  cv::imencode(".jpg", k.gray, jpeg, {cv::IMWRITE_JPEG_QUALITY, config_.jpeg_quality});
  images_.put(query.id, std::move(jpeg));
  views_[query.id] = k.view;
  finder_.addKeyFrame(k.key_frame);
  std::lock_guard<std::mutex> lock(mutex_);
  ++stats_.key_frames_done;
  stats_.images = images_.stats();
}

}  // namespace graph
}  // namespace exocet_mosaic
