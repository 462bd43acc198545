/**
 * @file free_heap.h
 * @brief Hands the heap's free pages back to the system. A node that runs for hours with large short-lived buffers in
 * several threads (SIFT pyramids, tile rasters) otherwise keeps their pages in glibc's per-thread arenas: its resident
 * memory creeps up although nothing it holds grows.
 */
#pragma once

#include <cstddef>

namespace exocet_common {

/// Releases the free memory of every malloc arena (glibc's malloc_trim); a no-op elsewhere. Takes a few milliseconds
/// on a heap of hundreds of MB: call it from a timer, not per message. @return true when memory was released
bool releaseFreeHeap();

}  // namespace exocet_common
