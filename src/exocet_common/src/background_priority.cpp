#include "exocet_common/background_priority.h"

#include <cerrno>

#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

namespace exocet_common {

bool lowerThisThreadPriority(int nice) {
  // On Linux a thread is a task of its own: PRIO_PROCESS with its tid changes that thread only.
  const auto tid = static_cast<id_t>(::syscall(SYS_gettid));
  errno = 0;
  const int current = ::getpriority(PRIO_PROCESS, tid);
  if (errno == 0 && current >= nice) return true;  // already as low (a node started under nice): never raised
  return ::setpriority(PRIO_PROCESS, tid, nice) == 0;
}

}  // namespace exocet_common
