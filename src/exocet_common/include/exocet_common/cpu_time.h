/**
 * @file cpu_time.h
 * @brief CPU time of the calling thread, for the figures of work done in background threads (a solve, a
 * computation of marginals) that wall time would blur with the chain's load.
 */
#pragma once

#include <time.h>

namespace exocet_common {

/// CPU seconds the calling thread has used (CLOCK_THREAD_CPUTIME_ID).
inline double threadCpuSeconds() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return t.tv_sec + 1e-9 * t.tv_nsec;
}

}  // namespace exocet_common
