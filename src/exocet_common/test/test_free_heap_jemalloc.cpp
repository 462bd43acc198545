// exocet_common's heap calls in a process on jemalloc (linked as the chain's nodes are, exocet_long_running_allocator):
// they find it at run time and use its statistics and its purge.
#include <gtest/gtest.h>

#include <unistd.h>

#include <cstdlib>
#include <cstring>
#include <vector>

#include "exocet_common/free_heap.h"
#include "exocet_common/testing/resident_memory.h"

using exocet_common::testing::residentMb;

TEST(FreeHeapOnJemalloc, TheProcessRunsOnJemalloc) { EXPECT_EQ(exocet_common::heapAllocator(), "jemalloc"); }

TEST(FreeHeapOnJemalloc, HeapUsageCountsWhatIsHeldAndFreedPagesGoBack) {
  const auto before = exocet_common::heapUsage();
  ASSERT_TRUE(before.has_value());
  // 32 MB in 16 kB blocks and 48 MB in one block, touched.
  std::vector<char*> blocks;
  for (int i = 0; i < 2048; ++i) {
    blocks.push_back(static_cast<char*>(std::malloc(16 * 1024)));
    ASSERT_NE(blocks.back(), nullptr);
    std::memset(blocks.back(), 1 + i % 200, 16 * 1024);
  }
  char* large = static_cast<char*>(std::malloc(48u << 20));
  ASSERT_NE(large, nullptr);
  std::memset(large, 1, 48u << 20);
  const auto held = exocet_common::heapUsage();
  ASSERT_TRUE(held.has_value());
  EXPECT_NEAR(held->in_use_mb - before->in_use_mb, 80.0, 2.0);
  EXPECT_DOUBLE_EQ(held->mmapped_mb, 0.0);
  // Freed but the last small block: jemalloc keeps the freed pages (dirty) until they decay or are purged.
  for (size_t i = 0; i + 1 < blocks.size(); ++i) std::free(blocks[i]);
  std::free(large);
  const auto freed = exocet_common::heapUsage();
  ASSERT_TRUE(freed.has_value());
  EXPECT_NEAR(freed->in_use_mb - before->in_use_mb, 0.0, 2.0);
  const double resident_before_mb = residentMb();
  EXPECT_TRUE(exocet_common::releaseFreeHeap());
  const double resident_after_mb = residentMb();
  EXPECT_LT(resident_after_mb, resident_before_mb - 32.0)
      << "resident " << resident_before_mb << " MB -> " << resident_after_mb << " MB";
  const auto purged = exocet_common::heapUsage();
  ASSERT_TRUE(purged.has_value());
  EXPECT_LT(purged->free_held_mb, freed->free_held_mb);
  std::free(blocks.back());
}
