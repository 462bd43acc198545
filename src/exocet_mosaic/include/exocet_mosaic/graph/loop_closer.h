/**
 * @file loop_closer.h
 * @brief Live loop closure: keeps the dive's key-frame images, looks for the earlier key frames each new one may
 * overlap (LoopCandidateFinder, at the graph's latest poses), verifies them by registration (LoopVerifier) and adds
 * the verified loops to the pose graph, all in a worker thread: the caller (the fusion's thread) never waits. No ROS.
 *
 * Memory: a key frame keeps its image JPEG-encoded (grey, quality jpeg_quality: about 20-40 kB for PAL) in a
 * KeyFrameImageStore: with an image_folder only the most recent images_in_memory stay in memory and the others are
 * read back from their files (an hour of key frames every 0.3 m would otherwise hold about 200 MB); SIFT features are
 * computed when a key frame is verified and the most recent feature_cache_size of them kept. A queue of at most
 * max_queue key frames waits for the worker; beyond it the oldest waiting key frame is verified against nothing (still
 * kept as a candidate for later ones) and counted as dropped.
 */
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <list>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <unordered_map>
#include <vector>

#include <opencv2/core.hpp>

#include "exocet_mosaic/graph/background_pose_graph.h"
#include "exocet_mosaic/graph/key_frame_image_store.h"
#include "exocet_mosaic/graph/loop_candidates.h"
#include "exocet_mosaic/graph/loop_verifier.h"

namespace exocet_mosaic {
namespace graph {

struct LoopCloserConfig {
  LoopCandidateConfig candidates;
  LoopVerifierConfig verifier;
  int max_loops_per_key_frame = 2;  ///< verified loops added per new key frame at most, >= 1
  int max_queue = 50;               ///< key frames waiting for the worker at most, >= 1
  int feature_cache_size = 32;      ///< key frames whose SIFT features are kept, >= 2
  int jpeg_quality = 90;            ///< of the kept key-frame images, [50, 100]
  /// Key-frame images larger than this (larger side, px) are downscaled to it, [64, 100000]: an HD or 4K image's
  /// SIFT pyramid takes hundreds of MB and seconds, and the loops' precision does not need its pixels.
  int max_image_side_px = 1024;
  double idle_wait_s = 0.05;  ///< longest sleep of the worker between checks, > 0
  /// Folder of the key-frame images beyond images_in_memory ("": all in memory). Emptied of earlier runs' images.
  std::string image_folder;
  int images_in_memory = 64;     ///< key-frame images kept in memory with an image_folder, >= 1
  std::string validate() const;  ///< "" or each bad field with its allowed range
};

/// A new key frame for the loop closer.
struct LoopCloserKeyFrame {
  LoopKeyFrame key_frame;  ///< id (the graph's), stamp, pose, covariances, height, camera
  LoopView view;           ///< the image's geometry for the verifier
  cv::Mat gray;            ///< 8-bit grey, undistorted, of view.image_size
};

/// Counters, for diagnostics and tests.
struct LoopCloserStats {
  uint64_t key_frames = 0;                   ///< key frames given
  uint64_t key_frames_done = 0;              ///< key frames the worker has searched for loops
  uint64_t dropped = 0;                      ///< key frames not searched (queue full)
  uint64_t candidates = 0;                   ///< candidates verified
  uint64_t loops_added = 0;                  ///< verified loops handed to the graph
  std::map<std::string, uint64_t> refusals;  ///< by the first words of the verifier's reason
  std::string last_refusal;
  std::string last_error;          ///< an exception of the worker ("" normally)
  KeyFrameImageStoreStats images;  ///< the key-frame images' store
};

/**
 * @brief Owns the worker that proposes verified loops to a BackgroundPoseGraph (which must outlive it).
 * addKeyFrame is thread-safe and never blocks on the work.
 */
class LoopCloser {
 public:
  /// @throws std::invalid_argument when config.validate() is not empty or the graph is null
  LoopCloser(const LoopCloserConfig& config, BackgroundPoseGraph* graph);
  ~LoopCloser();  ///< stop()s
  LoopCloser(const LoopCloser&) = delete;
  LoopCloser& operator=(const LoopCloser&) = delete;

  /// Queues a key frame. @throws std::invalid_argument for an image that is empty, not CV_8UC1 or not of the view's
  /// size
  void addKeyFrame(const LoopCloserKeyFrame& key_frame);
  /// Waits until every key frame queued so far is searched, at most `timeout_s`. @return true when idle
  bool waitIdle(double timeout_s);
  LoopCloserStats stats() const;
  /// Stops the worker after the verification in hand and joins it. Idempotent.
  void stop();

 private:
  struct Pending {
    LoopCloserKeyFrame key_frame;
    bool search = true;  ///< false: dropped from the search (queue full), only kept as a candidate
  };
  void run();
  void process(const Pending& pending);
  /// The features of a stored key frame (nullptr when its image is lost), or of `gray` when given.
  const LoopFeatures* featuresOf(int64_t id, const cv::Mat* gray);

  const LoopCloserConfig config_;
  BackgroundPoseGraph* graph_;
  LoopVerifier verifier_;
  // The worker's own.
  LoopCandidateFinder finder_;
  std::unordered_map<int64_t, LoopView> views_;  ///< of the key frames searched, by id
  KeyFrameImageStore images_;
  std::list<std::pair<int64_t, LoopFeatures>> feature_cache_;  ///< most recent first
  uint64_t snapshot_applied_ = 0;                              ///< the graph snapshot whose poses the finder has

  mutable std::mutex mutex_;
  std::condition_variable wake_, idle_;
  std::deque<Pending> queue_;
  bool busy_ = false;
  bool stopping_ = false;
  LoopCloserStats stats_;
  std::thread worker_;
};

}  // namespace graph
}  // namespace exocet_mosaic
