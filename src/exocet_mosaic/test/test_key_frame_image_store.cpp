// KeyFrameImageStore: bounded memory, images read back from their files, a folder that fails.
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "exocet_mosaic/graph/key_frame_image_store.h"

namespace exocet_mosaic {
namespace graph {
namespace {

namespace fs = std::filesystem;

std::vector<unsigned char> bytesOf(int id) {
  std::vector<unsigned char> b(1000 + id);
  for (size_t i = 0; i < b.size(); ++i) b[i] = static_cast<unsigned char>((i * 7 + id) & 0xff);
  return b;
}

fs::path freshFolder(const std::string& name) {
  const fs::path folder = fs::temp_directory_path() / name;
  fs::remove_all(folder);
  return folder;
}

TEST(KeyFrameImageStore, KeepsTheRecentInMemoryAndReadsTheOthersBack) {
  const fs::path folder = freshFolder("exocet_test_image_store");
  fs::create_directories(folder);
  std::ofstream(folder / "kf_7.jpg") << "an earlier run's image";
  std::ofstream(folder / "notes.txt") << "not the store's";
  {
    KeyFrameImageStore store(folder.string(), 3);
    EXPECT_FALSE(fs::exists(folder / "kf_7.jpg")) << "an earlier run's images mean other key frames";
    EXPECT_TRUE(fs::exists(folder / "notes.txt"));
    for (int id = 0; id < 50; ++id) store.put(id, bytesOf(id));
    const KeyFrameImageStoreStats s = store.stats();
    EXPECT_EQ(s.images, 50u);
    EXPECT_EQ(s.in_memory, 3u);
    EXPECT_EQ(s.bytes_in_memory, bytesOf(47).size() + bytesOf(48).size() + bytesOf(49).size());
    EXPECT_EQ(s.on_disk, 50u);
    EXPECT_EQ(s.lost, 0u);
    for (int id : {0, 13, 48, 49}) {
      ASSERT_TRUE(store.get(id)) << id;
      EXPECT_EQ(*store.get(id), bytesOf(id)) << id;
    }
    EXPECT_FALSE(store.get(50));
    store.put(13, bytesOf(99));  // replaced
    EXPECT_EQ(*store.get(13), bytesOf(99));
    // A file gone under the store: a clear error, no crash.
    fs::remove(store.pathOf(5));
    EXPECT_FALSE(store.get(5));
    EXPECT_NE(store.stats().last_error.find("kf_5.jpg"), std::string::npos) << store.stats().last_error;
  }
  EXPECT_FALSE(fs::exists(folder / "kf_0.jpg")) << "the store's files serve its run only";
  EXPECT_TRUE(fs::exists(folder / "notes.txt"));
  fs::remove_all(folder);
}

TEST(KeyFrameImageStore, WithoutAFolderEverythingStaysInMemory) {
  KeyFrameImageStore store("", 1);
  for (int id = 0; id < 20; ++id) store.put(id, bytesOf(id));
  EXPECT_EQ(store.stats().in_memory, 20u);
  EXPECT_EQ(*store.get(0), bytesOf(0));
}

TEST(KeyFrameImageStore, AnUnwritableFolderBoundsMemoryAndCountsTheLost) {
  const fs::path folder = freshFolder("exocet_test_image_store_unwritable");
  KeyFrameImageStore store(folder.string(), 4);
  // The folder goes away (a disk unmounted, a full disk): writes fail; memory still holds 4 at most.
  fs::remove_all(folder);
  for (int id = 0; id < 10; ++id) store.put(id, bytesOf(id));
  const KeyFrameImageStoreStats s = store.stats();
  EXPECT_EQ(s.in_memory, 4u);
  EXPECT_EQ(s.on_disk, 0u);
  EXPECT_GE(s.write_failures, 10u);
  EXPECT_EQ(s.lost, 6u);
  EXPECT_NE(s.last_error.find("cannot write"), std::string::npos) << s.last_error;
  EXPECT_EQ(*store.get(9), bytesOf(9));
  EXPECT_FALSE(store.get(0));
}

TEST(KeyFrameImageStore, BadArgumentsAreRefused) {
  EXPECT_THROW(KeyFrameImageStore("", 0), std::invalid_argument);
  EXPECT_THROW(KeyFrameImageStore("/proc/exocet_cannot_be_here", 4), std::runtime_error);
}

}  // namespace
}  // namespace graph
}  // namespace exocet_mosaic
