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

}  // namespace exocet_common
