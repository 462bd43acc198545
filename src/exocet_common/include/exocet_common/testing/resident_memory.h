/**
 * @file resident_memory.h
 * @brief The process's resident memory, for the tests of what the heap gives back to the system.
 */
#pragma once

#include <unistd.h>

#include <fstream>

namespace exocet_common {
namespace testing {

/// Resident memory of this process (MB), from /proc/self/statm.
inline double residentMb() {
  std::ifstream statm("/proc/self/statm");
  long size = 0, resident = 0;
  statm >> size >> resident;
  return resident * static_cast<double>(sysconf(_SC_PAGESIZE)) / (1024.0 * 1024.0);
}

}  // namespace testing
}  // namespace exocet_common
