// Tests of rendering a dive on several threads: a dive rendered with one and with three
// threads giving the same bag and companion files byte for byte, each frame depending on its index alone.
#include <atomic>
#include <chrono>
#include <fstream>
#include <iterator>
#include <random>
#include <set>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/CompressedImage.h>
#include <sensor_msgs/Image.h>
#include <opencv2/core.hpp>

#include "exocet_mosaic/ros/dive_topics.h"
#include "exocet_mosaic/ros/synthetic_dive_bag.h"
#include "exocet_mosaic/sim/dive_description.h"
#include "exocet_common/testing/paths.h"
#include "exocet_common/testing/temp_dir.h"

using namespace exocet_mosaic;
using namespace exocet_mosaic::sim;
using exocet_common::testing::TempDir;

namespace {

std::string readFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

/// The demo dive's look (relief, lamp, turbid water, noise, marine snow, landmarks), cut to a few dozen frames,
/// with lost frames so that their draws are exercised too.
DiveDescription shortDive(const std::string& storage, int threads) {
  return loadDiveDescription(exocet_common::testing::configDir() + "/dives/sample_lawnmower.yaml",
                             {"duration_s=5.6", "camera.drop_probability=0.1", "output.image_storage=" + storage,
                              "threads=" + std::to_string(threads)});
}

/// Image payloads of the bag in bag order, with their stamps.
struct BagImages {
  std::vector<std::string> payloads;
  std::vector<double> stamps_s;
};

BagImages readImages(const std::string& bag_path) {
  rosbag::Bag bag(bag_path, rosbag::bagmode::Read);
  rosbag::View view(bag, rosbag::TopicQuery(std::vector<std::string>{topics::kImageRaw, topics::kImageCompressed}));
  BagImages out;
  for (const rosbag::MessageInstance& m : view) {
    if (const auto jpeg = m.instantiate<sensor_msgs::CompressedImage>()) {
      out.payloads.emplace_back(jpeg->data.begin(), jpeg->data.end());
      out.stamps_s.push_back(jpeg->header.stamp.toSec());
    } else if (const auto raw = m.instantiate<sensor_msgs::Image>()) {
      out.payloads.emplace_back(raw->data.begin(), raw->data.end());
      out.stamps_s.push_back(raw->header.stamp.toSec());
    }
  }
  return out;
}

void expectSameOutputsWithOneAndThreeThreads(const std::string& storage) {
  TempDir dir("exocet_parallel_");
  const SyntheticDiveSummary one = writeSyntheticDive(shortDive(storage, 1), dir / "one.bag", nullptr);
  const SyntheticDiveSummary three = writeSyntheticDive(shortDive(storage, 3), dir / "three.bag", nullptr);
  ASSERT_EQ(one.frames, 29);
  EXPECT_EQ(one.frames, three.frames);
  EXPECT_EQ(one.messages, three.messages);

  // What makes the comparison able to fail: frames that differ from each other, some of them lost, in time order.
  const BagImages images = readImages(dir / "one.bag");
  ASSERT_GE(images.payloads.size(), 20u);
  EXPECT_LT(images.payloads.size(), static_cast<size_t>(one.frames)) << "the dive is meant to lose a few frames";
  for (size_t i = 1; i < images.payloads.size(); ++i) {
    EXPECT_NE(images.payloads[i], images.payloads[i - 1]) << "images " << i - 1 << " and " << i << " are equal";
    EXPECT_GT(images.stamps_s[i], images.stamps_s[i - 1]) << "image " << i << " is out of time order";
  }
  EXPECT_EQ(std::set<std::string>(images.payloads.begin(), images.payloads.end()).size(), images.payloads.size());

  const std::string bag_one = readFile(dir / "one.bag"), bag_three = readFile(dir / "three.bag");
  ASSERT_GT(bag_one.size(), 1000000u);
  EXPECT_TRUE(bag_one == bag_three) << storage << ": the bags differ (" << bag_one.size() << " and " << bag_three.size()
                                    << " bytes)";
  // Where they differ, if they do: the images in order, one by one.
  const BagImages threaded = readImages(dir / "three.bag");
  ASSERT_EQ(threaded.payloads.size(), images.payloads.size());
  for (size_t i = 0; i < images.payloads.size(); ++i)
    EXPECT_TRUE(images.payloads[i] == threaded.payloads[i]) << "image " << i << " differs";
  for (const char* companion : {".ground_truth.csv", ".landmarks.csv"}) {
    const std::string a = readFile(dir / (std::string("one") + companion));
    EXPECT_FALSE(a.empty()) << companion;
    EXPECT_EQ(a, readFile(dir / (std::string("three") + companion))) << companion;
  }
}

}  // namespace

// ------------------------------------------------------------------------------------------------- whole dives
TEST(DiveSynthParallel, JpegBagAndCsvsAreByteIdenticalWithOneAndThreeThreads) {
  expectSameOutputsWithOneAndThreeThreads("jpeg");
}

TEST(DiveSynthParallel, RawBagAndCsvsAreByteIdenticalWithOneAndThreeThreads) {
  expectSameOutputsWithOneAndThreeThreads("raw");
}

// Frames must not depend on what was rendered before them (texture cache state, a shared random stream): rendering
// them backwards, on a fresh seabed whose tiles are then generated in the other order, gives the same images.
TEST(DiveSynthParallel, EachFrameDependsOnItsIndexAlone) {
  DiveDescription dive = shortDive("raw", 1);
  dive.synthesis.rig.drop_probability = 0.0;
  dive.synthesis.duration_s = 2.8;
  std::vector<cv::Mat> forward;
  {
    Seabed seabed = makeSeabed(dive.seabed, dive.synthesis.seed);
    DiveSynthesizer synth(dive.synthesis, seabed.texture.get(), seabed.relief.get());
    DiveSink sink;
    sink.frame = [&](const FrameTruth& f) { forward.push_back(f.frame.image); };
    synth.run(sink);
  }
  ASSERT_EQ(forward.size(), 15u);
  Seabed seabed = makeSeabed(dive.seabed, dive.synthesis.seed);
  DiveSynthesizer synth(dive.synthesis, seabed.texture.get(), seabed.relief.get());
  const auto pose_at = [&](double t) { return synth.cameraPoseLocal(t); };
  for (int k = static_cast<int>(forward.size()) - 1; k >= 0; k -= 2) {
    const cv::Mat backward = synth.renderer().render(pose_at, k / dive.synthesis.rig.fps, k, "bgr8");
    ASSERT_EQ(backward.size(), forward[k].size());
    EXPECT_EQ(cv::norm(backward, forward[k], cv::NORM_INF), 0.0) << "frame " << k;
  }
}
