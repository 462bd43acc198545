/**
 * @file free_heap.h
 * @brief Hands the heap's free pages back to the system. A node that runs for hours with large short-lived buffers in
 * several threads (SIFT pyramids, tile rasters) otherwise keeps their pages in glibc's per-thread arenas: its resident
 * memory creeps up although nothing it holds grows. The chain's nodes run on jemalloc (exocet_long_running_allocator
 * in exocet_cmake), found here at run time: these calls then use its controls; a process on glibc's malloc (a test, a
 * nodelet manager) keeps glibc's.
 */
#pragma once

#include <cstddef>
#include <optional>
#include <string>

namespace exocet_common {

/// The allocator serving this process's malloc: "jemalloc", "glibc" or "other".
std::string heapAllocator();

/// Releases the free memory of every malloc arena (jemalloc's arena purge, or glibc's malloc_trim); a no-op elsewhere.
/// Takes a few milliseconds on a heap of hundreds of MB: call it from a timer, not per message. @return true when
/// memory was released
bool releaseFreeHeap();

/// What malloc holds, over every arena (jemalloc's statistics, or glibc's mallinfo2).
struct HeapUsage {
  double in_use_mb = 0.0;     ///< in blocks the program holds, mmapped ones included
  double free_held_mb = 0.0;  ///< glibc: freed but kept (part of it resident, until releaseFreeHeap); jemalloc: its
                              ///< resident pages beyond in_use_mb (free ones not yet returned, its metadata)
  double mmapped_mb = 0.0;    ///< glibc: in blocks of their own mapping (large ones), included in in_use_mb; jemalloc 0
};

/// The heap's use now; empty where neither jemalloc's statistics nor glibc's mallinfo2 is available. Walks the free
/// lists: from a 1 Hz timer at most.
std::optional<HeapUsage> heapUsage();

}  // namespace exocet_common
