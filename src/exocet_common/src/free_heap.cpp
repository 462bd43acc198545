#include "exocet_common/free_heap.h"

#include <dlfcn.h>

#include <cstdint>
#include <string>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace exocet_common {

namespace {

// jemalloc's control entry point, when the process runs on it (a node linked with it, or LD_PRELOAD): looked up at run
// time, so that the library does not depend on jemalloc and a process on glibc's malloc keeps using glibc's calls.
using MallctlFunction = int (*)(const char*, void*, size_t*, void*, size_t);

MallctlFunction jemallocControl() {
  static const MallctlFunction mallctl = reinterpret_cast<MallctlFunction>(::dlsym(RTLD_DEFAULT, "mallctl"));
  return mallctl;
}

bool readJemallocStat(MallctlFunction mallctl, const char* name, size_t* value) {
  size_t length = sizeof(*value);
  return mallctl(name, value, &length, nullptr, 0) == 0;
}

}  // namespace

std::string heapAllocator() {
  if (jemallocControl()) return "jemalloc";
#if defined(__GLIBC__)
  return "glibc";
#else
  return "other";
#endif
}

bool releaseFreeHeap() {
  if (const MallctlFunction mallctl = jemallocControl()) {
    // MALLCTL_ARENAS_ALL (4096): every arena's unused dirty and muzzy pages back to the system.
    return mallctl("arena.4096.purge", nullptr, nullptr, nullptr, 0) == 0;
  }
#if defined(__GLIBC__)
  return malloc_trim(0) != 0;
#else
  return false;
#endif
}

std::optional<HeapUsage> heapUsage() {
  constexpr double kMb = 1024.0 * 1024.0;
  if (const MallctlFunction mallctl = jemallocControl()) {
    // The statistics are a snapshot taken at each epoch: advance it first.
    uint64_t epoch = 1;
    size_t epoch_length = sizeof(epoch);
    size_t allocated = 0, resident = 0;
    if (mallctl("epoch", &epoch, &epoch_length, &epoch, epoch_length) != 0 ||
        !readJemallocStat(mallctl, "stats.allocated", &allocated) ||
        !readJemallocStat(mallctl, "stats.resident", &resident))
      return std::nullopt;  // a jemalloc built without statistics
    HeapUsage usage;
    usage.in_use_mb = double(allocated) / kMb;
    // Resident pages of the allocator that the program does not hold: free ones not yet returned, and its metadata.
    usage.free_held_mb = resident > allocated ? double(resident - allocated) / kMb : 0.0;
    usage.mmapped_mb = 0.0;  // every block of jemalloc is in its extents; none has a mapping of its own
    return usage;
  }
#if defined(__GLIBC__) && (__GLIBC__ > 2 || (__GLIBC__ == 2 && __GLIBC_MINOR__ >= 33))
  const struct mallinfo2 info = mallinfo2();
  HeapUsage usage;
  usage.in_use_mb = double(info.uordblks + info.hblkhd) / kMb;
  usage.free_held_mb = double(info.fordblks) / kMb;
  usage.mmapped_mb = double(info.hblkhd) / kMb;
  return usage;
#else
  return std::nullopt;
#endif
}

}  // namespace exocet_common
