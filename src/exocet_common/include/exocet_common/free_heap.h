/**
 * @file free_heap.h
 * @brief Hands the heap's free pages back to the system. A node that runs for hours with large short-lived buffers in
 * several threads (SIFT pyramids, tile rasters) otherwise keeps their pages in glibc's per-thread arenas: its resident
 * memory creeps up although nothing it holds grows.
 */
#pragma once

#include <cstddef>
#include <optional>

namespace exocet_common {

/// Releases the free memory of every malloc arena (glibc's malloc_trim); a no-op elsewhere. Takes a few milliseconds
/// on a heap of hundreds of MB: call it from a timer, not per message. @return true when memory was released
bool releaseFreeHeap();

/// What malloc holds, over every arena (glibc's mallinfo2).
struct HeapUsage {
  double in_use_mb = 0.0;      ///< in blocks the program holds, mmapped ones included
  double free_held_mb = 0.0;   ///< freed but kept by malloc (part of it resident, until releaseFreeHeap)
  double mmapped_mb = 0.0;     ///< in blocks of their own mapping (large ones), included in in_use_mb
};

/// The heap's use now; empty where glibc's mallinfo2 is not available. Walks the free lists: from a 1 Hz timer at most.
std::optional<HeapUsage> heapUsage();

}  // namespace exocet_common
