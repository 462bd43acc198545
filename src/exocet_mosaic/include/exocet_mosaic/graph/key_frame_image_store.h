/**
 * @file key_frame_image_store.h
 * @brief The loop closer's key-frame images (JPEG bytes by key-frame id), bounded in memory: the most recent
 * `max_in_memory` stay in memory and the others live in files of a folder, read back when a loop candidate needs
 * one. An hour of key frames every 0.3 m is about 6000 images (200 MB at 30 kB), which a long dive must not hold.
 * Without a folder every image stays in memory (short replays, tests). No ROS.
 */
#pragma once

#include <cstdint>
#include <list>
#include <optional>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <vector>

namespace exocet_mosaic {
namespace graph {

struct KeyFrameImageStoreStats {
  uint64_t images = 0;           ///< images put
  uint64_t in_memory = 0;        ///< images held in memory now
  uint64_t bytes_in_memory = 0;  ///< their bytes
  uint64_t on_disk = 0;          ///< images written to the folder
  uint64_t write_failures = 0;   ///< files that could not be written (disk full...)
  uint64_t lost = 0;             ///< images dropped: evicted from memory and not on disk
  std::string last_error;        ///< of the last failed write or read ("" if none)
};

/**
 * @brief JPEG bytes by id, at most `max_in_memory` in memory, the others in `folder` (one file per id).
 *
 * An image that cannot be written (disk full) stays in memory while it is among the most recent; evicted without a
 * file it is lost (counted), so memory stays bounded whatever the disk does. Not thread-safe (the loop closer's
 * worker owns it).
 */
class KeyFrameImageStore {
 public:
  /**
   * @param folder "" to keep every image in memory; else created if missing, and emptied of this store's files
   *        (kf_*.jpg) left by an earlier run, whose ids meant other key frames
   * @param max_in_memory >= 1 (ignored without a folder)
   * @throws std::invalid_argument for max_in_memory < 1, std::runtime_error when the folder cannot be created
   */
  KeyFrameImageStore(const std::string& folder, int max_in_memory);
  ~KeyFrameImageStore();  ///< removes the files it wrote (they serve this run only)
  KeyFrameImageStore(const KeyFrameImageStore&) = delete;
  KeyFrameImageStore& operator=(const KeyFrameImageStore&) = delete;

  /// Keeps `jpeg` under `id` (replacing an earlier image of that id).
  void put(int64_t id, std::vector<unsigned char> jpeg);
  /// The image of `id`, from memory or its file; nullopt when unknown, lost or unreadable (last_error says why).
  std::optional<std::vector<unsigned char>> get(int64_t id);
  bool contains(int64_t id) const;
  KeyFrameImageStoreStats stats() const { return stats_; }
  /// The file of `id` in the folder (whether or not it exists).
  std::string pathOf(int64_t id) const;

 private:
  bool writeFile(int64_t id, const std::vector<unsigned char>& jpeg);
  void evict();

  const std::string folder_;
  const size_t max_in_memory_;
  std::list<std::pair<int64_t, std::vector<unsigned char>>> memory_;  ///< most recent first
  std::unordered_map<int64_t, decltype(memory_)::iterator> memory_index_;
  std::unordered_set<int64_t> on_disk_;
  KeyFrameImageStoreStats stats_;
};

}  // namespace graph
}  // namespace exocet_mosaic
