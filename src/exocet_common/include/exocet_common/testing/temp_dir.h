/**
 * @file temp_dir.h
 * @brief A temporary folder for tests and benchmarks, removed with everything in it when the object goes. Header
 * only, no ROS; shared by the packages' tests (exocet_stereo depends on exocet_mosaic).
 */
#pragma once

#include <stdlib.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <system_error>
#include <vector>

namespace exocet_common {
namespace testing {

class TempDir {
 public:
  /// Creates <system temp>/<prefix>XXXXXX. @throws std::runtime_error naming the folder and why it failed.
  explicit TempDir(const std::string& prefix = "exocet_test_") {
    std::string pattern = (std::filesystem::temp_directory_path() / (prefix + "XXXXXX")).string();
    if (::mkdtemp(pattern.data()) == nullptr)
      throw std::runtime_error("cannot create the temporary folder " + pattern + ": " + std::strerror(errno));
    path_ = pattern;
  }
  ~TempDir() {
    std::error_code ignored;
    std::filesystem::remove_all(path_, ignored);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;

  const std::string& path() const { return path_; }
  /// Path of a file in the folder.
  std::string file(const std::string& name) const { return (std::filesystem::path(path_) / name).string(); }
  std::string operator/(const std::string& name) const { return file(name); }
  /// Sorted names of the entries in the folder (to check that nothing partial is left behind).
  std::vector<std::string> files() const {
    std::vector<std::string> names;
    for (const auto& entry : std::filesystem::directory_iterator(path_))
      names.push_back(entry.path().filename().string());
    std::sort(names.begin(), names.end());
    return names;
  }

 private:
  std::string path_;
};

}  // namespace testing
}  // namespace exocet_common
