#include "exocet_mosaic/graph/key_frame_image_store.h"

#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <system_error>

namespace exocet_mosaic {
namespace graph {

namespace fs = std::filesystem;

namespace {

bool isStoreFile(const fs::path& path) {
  const std::string name = path.filename().string();
  return name.size() > 7 && name.compare(0, 3, "kf_") == 0 && name.compare(name.size() - 4, 4, ".jpg") == 0;
}

}  // namespace

KeyFrameImageStore::KeyFrameImageStore(const std::string& folder, int max_in_memory)
    : folder_(folder), max_in_memory_(max_in_memory > 0 ? static_cast<size_t>(max_in_memory) : 0) {
  if (max_in_memory < 1)
    throw std::invalid_argument("key-frame image store: max_in_memory = " + std::to_string(max_in_memory) +
                                " must be >= 1");
  if (folder_.empty()) return;
  std::error_code error;
  fs::create_directories(folder_, error);
  if (error || !fs::is_directory(folder_))
    throw std::runtime_error("key-frame image store: cannot create the folder " + folder_ + ": " + error.message());
  for (const fs::directory_entry& entry : fs::directory_iterator(folder_, error))
    if (entry.is_regular_file() && isStoreFile(entry.path())) fs::remove(entry.path(), error);
}

KeyFrameImageStore::~KeyFrameImageStore() {
  std::error_code error;
  for (int64_t id : on_disk_) fs::remove(pathOf(id), error);
}

std::string KeyFrameImageStore::pathOf(int64_t id) const { return folder_ + "/kf_" + std::to_string(id) + ".jpg"; }

bool KeyFrameImageStore::contains(int64_t id) const { return memory_index_.count(id) || on_disk_.count(id); }

bool KeyFrameImageStore::writeFile(int64_t id, const std::vector<unsigned char>& jpeg) {
  // Written whole under a temporary name, then renamed: a crash or a full disk never leaves a short image.
  const std::string path = pathOf(id);
  const std::string partial = path + ".partial-" + std::to_string(::getpid());
  {
    std::ofstream out(partial, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(jpeg.data()), static_cast<std::streamsize>(jpeg.size()));
    out.flush();
    if (!out) {
      std::remove(partial.c_str());
      ++stats_.write_failures;
      stats_.last_error = "cannot write " + path + " (disk full or not writable)";
      return false;
    }
  }
  if (std::rename(partial.c_str(), path.c_str()) != 0) {
    std::remove(partial.c_str());
    ++stats_.write_failures;
    stats_.last_error = "cannot rename " + partial + " to " + path;
    return false;
  }
  on_disk_.insert(id);
  ++stats_.on_disk;
  return true;
}

void KeyFrameImageStore::put(int64_t id, std::vector<unsigned char> jpeg) {
  ++stats_.images;
  if (auto it = memory_index_.find(id); it != memory_index_.end()) {
    stats_.bytes_in_memory -= it->second->second.size();
    memory_.erase(it->second);
    memory_index_.erase(it);
  }
  if (on_disk_.erase(id)) {
    std::error_code error;
    fs::remove(pathOf(id), error);
  }
  // Written at once, so that an image evicted later needs no write then (and a full disk shows at once).
  if (!folder_.empty()) writeFile(id, jpeg);
  stats_.bytes_in_memory += jpeg.size();
  memory_.emplace_front(id, std::move(jpeg));
  memory_index_[id] = memory_.begin();
  evict();
  stats_.in_memory = memory_.size();
}

void KeyFrameImageStore::evict() {
  if (folder_.empty()) return;
  while (memory_.size() > max_in_memory_) {
    auto& [id, jpeg] = memory_.back();
    // Not on disk (its write failed): one more try, else it is lost.
    if (!on_disk_.count(id) && !writeFile(id, jpeg)) ++stats_.lost;
    stats_.bytes_in_memory -= jpeg.size();
    memory_index_.erase(id);
    memory_.pop_back();
  }
}

std::optional<std::vector<unsigned char>> KeyFrameImageStore::get(int64_t id) {
  if (auto it = memory_index_.find(id); it != memory_index_.end()) return it->second->second;
  if (!on_disk_.count(id)) return std::nullopt;
  const std::string path = pathOf(id);
  std::ifstream in(path, std::ios::binary);
  std::vector<unsigned char> jpeg((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (!in.good() && !in.eof()) {
    stats_.last_error = "cannot read " + path;
    return std::nullopt;
  }
  if (jpeg.empty()) {
    stats_.last_error = path + " is empty or missing";
    return std::nullopt;
  }
  return jpeg;
}

}  // namespace graph
}  // namespace exocet_mosaic
