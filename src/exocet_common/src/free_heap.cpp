#include "exocet_common/free_heap.h"

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace exocet_common {

bool releaseFreeHeap() {
#if defined(__GLIBC__)
  return malloc_trim(0) != 0;
#else
  return false;
#endif
}

std::optional<HeapUsage> heapUsage() {
#if defined(__GLIBC__) && (__GLIBC__ > 2 || (__GLIBC__ == 2 && __GLIBC_MINOR__ >= 33))
  const struct mallinfo2 info = mallinfo2();
  constexpr double kMb = 1024.0 * 1024.0;
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
