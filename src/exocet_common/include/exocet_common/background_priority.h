/**
 * @file background_priority.h
 * @brief Background work (loop verification, pose-graph solves, tiles drawn again) may fall behind; the live chain
 * may not. Threads that do such work lower their own scheduling priority, so that on a loaded machine the kernel gives
 * the chain's threads the CPU first and the background catches up when it idles.
 */
#pragma once

namespace exocet_common {

/// Nice value of the background threads (the chain's run at 0).
constexpr int kBackgroundNice = 10;

/// Lowers the calling thread's priority to `nice` (Linux: per thread; 0-19); a thread already at that nice value or
/// lower priority is left as it is. @return false when the system refused.
bool lowerThisThreadPriority(int nice = kBackgroundNice);

}  // namespace exocet_common
