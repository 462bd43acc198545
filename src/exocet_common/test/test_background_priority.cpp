// Background threads lower their own priority only: the thread that calls it, not the process.
#include <gtest/gtest.h>

#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <thread>

#include "exocet_common/background_priority.h"

namespace {

int threadNice() {
  errno = 0;
  return ::getpriority(PRIO_PROCESS, static_cast<id_t>(::syscall(SYS_gettid)));
}

}  // namespace

TEST(BackgroundPriority, LowersTheCallingThreadOnly) {
  const int before = threadNice();
  int in_thread = -100;
  bool ok = false;
  std::thread worker([&]() {
    ok = exocet_common::lowerThisThreadPriority();
    in_thread = threadNice();
  });
  worker.join();
  ASSERT_TRUE(ok);
  EXPECT_EQ(in_thread, std::max(before, exocet_common::kBackgroundNice));
  EXPECT_EQ(threadNice(), before) << "the calling thread's priority must not change the others'";
}
