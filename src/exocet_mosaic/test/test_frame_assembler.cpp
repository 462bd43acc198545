// FrameAssembler: the tile writer's synchronisation of images, motions, poses and heights by stamp.
#include <gtest/gtest.h>

#include "exocet_mosaic/ros/frame_assembler.h"

namespace exocet_mosaic {
namespace {

ImageDecoder image() {
  return [](int) { return cv::Mat(4, 4, CV_8UC1, cv::Scalar(7)); };
}

MotionPart motion(std::int64_t previous) {
  MotionPart m;
  m.previous_stamp_ns = previous;
  m.failed = false;
  return m;
}

TEST(FrameAssembler, ReleasesCompleteFramesInStampOrderWhateverTheArrivalOrder) {
  FrameAssembler assembler(10.0, 100);
  // Frame 2's parts arrive before frame 1's pose: frame 1 must still come out first.
  assembler.addImage(1, image(), 0.0);
  assembler.addImage(2, image(), 0.0);
  assembler.addMotion(2, motion(1), 0.0);
  assembler.addMotion(1, motion(0), 0.0);
  assembler.addHeight(1, 2.5, 0.0);
  assembler.addHeight(2, 2.5, 0.0);
  assembler.addPose(2, PosePart(), 0.0);
  std::vector<AssembledFrame> out = assembler.popReady(0.1);
  // The newest complete frame (2) releases the older one (1) with what it has: its pose will not come any more.
  ASSERT_EQ(out.size(), 2u);
  EXPECT_EQ(out[0].stamp_ns, 1);
  EXPECT_FALSE(out[0].pose.has_value());
  EXPECT_EQ(out[1].stamp_ns, 2);
  EXPECT_TRUE(out[1].complete());
  EXPECT_EQ(out[1].decode_image(1).at<uchar>(0, 0), 7);
  // A part for a released stamp is late: refused and counted.
  EXPECT_FALSE(assembler.addPose(1, PosePart(), 0.2));
  EXPECT_EQ(assembler.lateParts(), 1);
}

TEST(FrameAssembler, ARepeatedImageStampKeepsTheFirstImageAndIsCounted) {
  FrameAssembler assembler(10.0, 100);
  EXPECT_TRUE(assembler.addImage(1, image(), 0.0));
  EXPECT_FALSE(assembler.addImage(
      1, [](int) { return cv::Mat(4, 4, CV_8UC1, cv::Scalar(9)); }, 0.0));
  EXPECT_EQ(assembler.duplicateImages(), 1);
  EXPECT_EQ(assembler.pendingImages(), 1u);
  const auto out = assembler.popAll();
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].decode_image(1).at<uchar>(0, 0), 7);
  EXPECT_FALSE(assembler.addImage(1, image(), 0.1)) << "released: late";
  EXPECT_EQ(assembler.lateParts(), 1);
}

TEST(FrameAssembler, WaitsForMissingPartsUntilTheTimeoutThenReleasesWhatItHas) {
  FrameAssembler assembler(2.0, 100);
  assembler.addImage(10, image(), 0.0);
  assembler.addMotion(10, motion(5), 0.0);
  EXPECT_TRUE(assembler.popReady(1.0).empty());  // the pose may still come
  EXPECT_EQ(assembler.pendingImages(), 1u);
  const auto out = assembler.popReady(2.5);
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].stamp_ns, 10);
  EXPECT_FALSE(out[0].complete());
  EXPECT_EQ(assembler.timedOut(), 1);
}

TEST(FrameAssembler, PartsWithoutImageAreDroppedAndTheBufferIsBounded) {
  FrameAssembler assembler(100.0, 3);
  // The fusion publishes between images (navigation rate): those stamps never get an image.
  assembler.addPose(5, PosePart(), 0.0);
  for (int i = 0; i < 6; ++i) assembler.addImage(10 + i, image(), 0.0);
  const auto out = assembler.popReady(0.0);
  EXPECT_EQ(assembler.pendingImages(), 3u);
  ASSERT_EQ(out.size(), 3u);
  EXPECT_EQ(out[0].stamp_ns, 10);  // the pose-only stamp 5 is not handed out
  EXPECT_EQ(assembler.popAll().size(), 3u);
  EXPECT_EQ(assembler.pendingImages(), 0u);
}

TEST(FrameAssembler, ResetAcceptsOlderStampsAgain) {
  FrameAssembler assembler(1.0, 10);
  assembler.addImage(100, image(), 0.0);
  assembler.popAll();
  EXPECT_FALSE(assembler.addImage(50, image(), 0.0));  // older than what was released
  assembler.reset();                                   // the clock jumped back (a bag played again)
  EXPECT_TRUE(assembler.addImage(50, image(), 0.0));
}

TEST(FrameAssembler, RejectsBadSettings) {
  EXPECT_THROW(FrameAssembler(0.0, 1), std::invalid_argument);
  EXPECT_THROW(FrameAssembler(1.0, 0), std::invalid_argument);
}

}  // namespace
}  // namespace exocet_mosaic
