// OrderedWorkPool: items handed over in index order whatever order they finish in, a bounded window ahead of the
// consumer, an item's error rethrown at that item, bad windows refused.
#include <atomic>
#include <chrono>
#include <stdexcept>
#include <string>
#include <thread>

#include <gtest/gtest.h>

#include "exocet_common/ordered_work_pool.h"

using exocet_common::OrderedWorkPool;

TEST(OrderedWorkPool, DeliversEveryItemInOrderWhateverOrderTheyFinishIn) {
  std::atomic<int> running{0}, most_running{0};
  OrderedWorkPool<int> pool(40, 4, 6, [&](int k) {
    const int now = ++running;
    int seen = most_running.load();
    while (now > seen && !most_running.compare_exchange_weak(seen, now)) {
    }
    // Later items often finish first: the pool must still hand them over in order.
    std::this_thread::sleep_for(std::chrono::milliseconds((k * 7) % 5 + (k % 3 == 0 ? 4 : 0)));
    --running;
    return k * k;
  });
  for (int k = 0; k < 40; ++k) EXPECT_EQ(pool.take(k), k * k);
  EXPECT_GT(most_running.load(), 1) << "the items were never computed concurrently";
  EXPECT_LE(most_running.load(), 4);
}

TEST(OrderedWorkPool, ComputesAtMostAheadItemsBeyondTheConsumer) {
  std::atomic<int> started{0};
  OrderedWorkPool<int> pool(100, 3, 5, [&](int k) {
    ++started;
    return k;
  });
  EXPECT_EQ(pool.take(0), 0);
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  // Item 0 taken: items 1..5 may be under way, not item 6.
  EXPECT_LE(started.load(), 6);
  EXPECT_GE(started.load(), 2);
}

TEST(OrderedWorkPool, RethrowsAnItemsErrorAtThatItemAndStopsCleanly) {
  OrderedWorkPool<std::string> pool(50, 2, 4, [](int k) {
    if (k == 3) throw std::runtime_error("item 3 failed");
    return std::to_string(k);
  });
  for (int k = 0; k < 3; ++k) EXPECT_EQ(pool.take(k), std::to_string(k));
  EXPECT_THROW(
      {
        try {
          pool.take(3);
        } catch (const std::runtime_error& e) {
          EXPECT_STREQ(e.what(), "item 3 failed");
          throw;
        }
      },
      std::runtime_error);
  EXPECT_THROW(pool.take(7), std::logic_error) << "items are taken in order";
  // Leaving scope with items not taken must not hang.
}

TEST(OrderedWorkPool, RejectsAWindowSmallerThanTheThreads) {
  EXPECT_THROW(OrderedWorkPool<int>(10, 4, 3, [](int k) { return k; }), std::invalid_argument);
  EXPECT_THROW(OrderedWorkPool<int>(10, 0, 3, [](int k) { return k; }), std::invalid_argument);
}
