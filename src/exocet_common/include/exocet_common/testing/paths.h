/**
 * @file paths.h
 * @brief Where tests and benchmarks find the presets and dive descriptions, the shared data and the built tools, at
 * run time: no path is compiled into a binary. `source devel/setup.bash` sets the variables (env hooks of
 * exocet_common: EXOCET_SHARED_DATA_DIR; of exocet_mosaic: EXOCET_CONFIG_DIR), and catkin runs every gtest through
 * devel/env.sh, which does the same. Header only, no ROS.
 */
#pragma once

#include <unistd.h>

#include <cstdlib>
#include <stdexcept>
#include <string>
#include <vector>

namespace exocet_common {
namespace testing {

/// The value of the environment variable `name`. @throws std::runtime_error naming it when unset or empty.
inline std::string directoryFromEnvironment(const char* name) {
  const char* value = std::getenv(name);
  if (value == nullptr || *value == '\0')
    throw std::runtime_error(std::string(name) +
                             " is not set: source the workspace's devel/setup.bash (the packages' env hooks set it)");
  return value;
}

/// The dive descriptions and presets (exocet_mosaic's config/, share/exocet_mosaic/config installed):
/// $EXOCET_CONFIG_DIR.
inline std::string configDir() { return directoryFromEnvironment("EXOCET_CONFIG_DIR"); }

/// The real data of the tests and benchmarks (../shared/data beside the workspace): $EXOCET_SHARED_DATA_DIR.
inline std::string sharedDataDir() { return directoryFromEnvironment("EXOCET_SHARED_DATA_DIR"); }

/// The directory of the running executable: a package's gtests are built beside its tools (devel/lib/<package>).
/// @throws std::runtime_error when /proc/self/exe cannot be read.
inline std::string executableDir() {
  std::vector<char> path(4096);
  const ssize_t n = ::readlink("/proc/self/exe", path.data(), path.size() - 1);
  if (n <= 0) throw std::runtime_error("cannot read /proc/self/exe to find the built tools");
  const std::string exe(path.data(), static_cast<size_t>(n));
  return exe.substr(0, exe.find_last_of('/'));
}

}  // namespace testing
}  // namespace exocet_common
