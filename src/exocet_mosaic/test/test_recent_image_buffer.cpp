/**
 * Tests of graph::RecentImageBuffer: the loop closer's recent images, bounded in age, count and bytes.
 */
#include <gtest/gtest.h>

#include <string>

#include "exocet_mosaic/graph/recent_image_buffer.h"

namespace eg = exocet_mosaic::graph;

TEST(RecentImageBuffer, TheOldestGoWhenTheBytesPassTheLimit) {
  eg::RecentImageBufferLimits limits;
  limits.max_bytes = 5'000'000;
  eg::RecentImageBuffer<int> buffer(limits);
  // 4K JPEGs of about 1.3 MB at 25 frames/s: three fit in 5 MB.
  for (int i = 0; i < 10; ++i) buffer.add(100.0 + 0.04 * i, i, 1'300'000);
  EXPECT_EQ(buffer.size(), 3u);
  EXPECT_EQ(buffer.bytes(), 3'900'000u);
  EXPECT_FALSE(buffer.find(100.0 + 0.04 * 6).has_value());
  ASSERT_TRUE(buffer.find(100.0 + 0.04 * 7).has_value());
  EXPECT_EQ(*buffer.find(100.0 + 0.04 * 9), 9);
}

TEST(RecentImageBuffer, AgeAndCountBoundItTooAndTheNewestStays) {
  eg::RecentImageBufferLimits limits;
  limits.max_age_s = 1.0;
  limits.max_images = 4;
  eg::RecentImageBuffer<std::string> buffer(limits);
  buffer.add(10.0, "a", 10);
  buffer.add(10.5, "b", 10);
  buffer.add(11.6, "c", 10);  // 10.0 and 10.5 are more than 1 s older
  EXPECT_EQ(buffer.size(), 1u);
  EXPECT_EQ(*buffer.find(11.6), "c");
  for (int i = 1; i <= 6; ++i) buffer.add(11.6 + 0.01 * i, "d", 10);
  EXPECT_EQ(buffer.size(), 4u);
  eg::RecentImageBufferLimits tiny;
  tiny.max_bytes = 1;
  eg::RecentImageBuffer<int> one(tiny);
  one.add(1.0, 1, 100);  // larger than the limit: kept, as the newest
  EXPECT_EQ(one.size(), 1u);
  one.add(1.0, 2, 50);  // the same stamp replaces it
  EXPECT_EQ(one.bytes(), 50u);
  EXPECT_EQ(*one.find(1.0), 2);
  EXPECT_FALSE(one.find(2.0).has_value());
}
