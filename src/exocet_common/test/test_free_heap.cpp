// exocet_common::releaseFreeHeap: the pages of freed blocks in the middle of the heap (which free() keeps) go back to
// the system.
#include <gtest/gtest.h>

#include <unistd.h>

#include <cstdlib>
#include <cstring>
#include <vector>

#include "exocet_common/free_heap.h"
#include "exocet_common/testing/resident_memory.h"

using exocet_common::testing::residentMb;

TEST(FreeHeap, ThisTestRunsOnGlibcsMalloc) {
#if defined(__GLIBC__)
  EXPECT_EQ(exocet_common::heapAllocator(), "glibc");
#endif
}

TEST(FreeHeap, TheFreedMiddleOfTheHeapGoesBackToTheSystem) {
#if !defined(__GLIBC__)
  GTEST_SKIP() << "glibc's malloc_trim only";
#endif
  // 64 MB in 16 kB blocks (below the mmap threshold: on the heap), touched; all freed but the last, which keeps the
  // heap's top where it is, so free() cannot give the pages back by itself.
  constexpr int kBlocks = 4096;
  constexpr size_t kBlockBytes = 16 * 1024;
  std::vector<char*> blocks;
  for (int i = 0; i < kBlocks; ++i) {
    blocks.push_back(static_cast<char*>(std::malloc(kBlockBytes)));
    ASSERT_NE(blocks.back(), nullptr);
    std::memset(blocks.back(), 1 + i % 200, kBlockBytes);
  }
  for (int i = 0; i + 1 < kBlocks; ++i) std::free(blocks[i]);
  const double before_mb = residentMb();
  EXPECT_TRUE(exocet_common::releaseFreeHeap());
  const double after_mb = residentMb();
  EXPECT_LT(after_mb, before_mb - 32.0) << "resident " << before_mb << " MB -> " << after_mb << " MB";
  std::free(blocks.back());
}

TEST(FreeHeap, HeapUsageCountsWhatIsHeldAndWhatIsFreed) {
#if !defined(__GLIBC__)
  GTEST_SKIP() << "glibc's mallinfo2 only";
#endif
  const auto before = exocet_common::heapUsage();
  ASSERT_TRUE(before.has_value());
  // 32 MB in 16 kB blocks (on the heap, not mmapped), then 48 MB in one block (above glibc's largest mmap threshold:
  // mmapped).
  std::vector<char*> blocks;
  for (int i = 0; i < 2048; ++i) {
    blocks.push_back(static_cast<char*>(std::malloc(16 * 1024)));
    std::memset(blocks.back(), 1, 16 * 1024);
  }
  char* large = static_cast<char*>(std::malloc(48u << 20));
  std::memset(large, 1, 48u << 20);
  const auto held = exocet_common::heapUsage();
  ASSERT_TRUE(held.has_value());
  EXPECT_NEAR(held->in_use_mb - before->in_use_mb, 80.0, 2.0);
  EXPECT_GE(held->mmapped_mb - before->mmapped_mb, 47.9);
  // Freed but the last small block (it pins the heap's top): malloc keeps the small ones as free.
  for (size_t i = 0; i + 1 < blocks.size(); ++i) std::free(blocks[i]);
  std::free(large);
  const auto freed = exocet_common::heapUsage();
  ASSERT_TRUE(freed.has_value());
  EXPECT_NEAR(freed->in_use_mb - before->in_use_mb, 0.0, 2.0);
  EXPECT_GT(freed->free_held_mb - before->free_held_mb, 30.0);
  std::free(blocks.back());
}
