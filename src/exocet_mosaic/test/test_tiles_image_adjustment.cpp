// The image network adjustment: two passes of images cut from a known ortho-image, the return pass placed off by a
// planted shift or turn, are measured pair by pair (patches, SIFT) and moved back into agreement, each pass kept whole.
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <string>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "compose_fixtures.h"
#include "exocet_mosaic/tiles/image_network_adjustment.h"

namespace et = exocet_mosaic::tiles;

namespace {

constexpr double kGsd = 0.005;
const cv::Size kImage(400, 300);

struct Scene {
  compose_test::TruthOrtho truth = compose_test::TruthOrtho::make(6.0, 3.0, kGsd, 500000.0, 4800000.0);
  cv::Mat grey;
  std::vector<et::AdjustableImage> images;
  std::vector<Eigen::Vector2d> planted_m;  // where an image's placement puts a point, minus where it truly is
  std::map<std::string, cv::Rect> crop_of;

  Scene() { cv::cvtColor(truth.image, grey, cv::COLOR_BGR2GRAY); }

  /// A pass of images whose top-left corners run along row y0_px, from x = first_px by step_px, every second.
  void addPass(const std::string& name, int y0_px, int first_px, int step_px, int count, double first_stamp_s,
               const Eigen::Vector2d& error_m) {
    for (int k = 0; k < count; ++k) {
      const int x0 = first_px + k * step_px;
      et::AdjustableImage image;
      image.id = name + std::to_string(k);
      image.stamp_s = first_stamp_s + k;
      image.size_px = kImage;
      image.gsd_m = kGsd;
      image.en_from_px = cv::Matx33d(kGsd, 0, truth.origin_e_m + x0 * kGsd + error_m.x(),  //
                                     0, -kGsd, truth.origin_n_m - y0_px * kGsd + error_m.y(), 0, 0, 1);
      images.push_back(image);
      planted_m.push_back(error_m);
      crop_of[image.id] = cv::Rect(x0, y0_px, kImage.width, kImage.height);
    }
  }

  cv::Mat load(const std::string& id) const {
    const auto c = crop_of.find(id);
    return c == crop_of.end() ? cv::Mat() : grey(c->second).clone();
  }
};

}  // namespace

TEST(ImageNetworkAdjustment, AReturnPassPlacedOffIsMovedOntoTheOutboundOne) {
  Scene scene;
  scene.addPass("out", 40, 0, 80, 11, 0.0, Eigen::Vector2d::Zero());
  const Eigen::Vector2d planted(0.008, -0.006);  // 1.6 px east, 1.2 px south
  scene.addPass("back", 180, 800, -80, 11, 100.0, planted);
  const et::ImageAdjustment result =
      et::adjustImages(scene.images, [&scene](const std::string& id) { return scene.load(id); });
  ASSERT_TRUE(result.problem.empty()) << result.problem;
  EXPECT_EQ(result.images_with_features, 22);
  int cross = 0;
  for (const et::ImagePairTies& p : result.pairs) cross += p.cross_pass ? 1 : 0;
  EXPECT_GT(cross, 20);
  // A 48 px patch's phase correlation reads the 2 px short (1.6 px): the second pass measures what the first left.
  EXPECT_GT(result.cross_before_max_px, 1.4);
  EXPECT_LT(result.cross_before_max_px, 2.3);
  EXPECT_LT(result.cross_after_max_px, 0.2);
  // Every image ends where it belongs up to a move common to the whole map, which the overlaps cannot see: a shift (the
  // priors keep it between the two passes' placements) and a turn of the whole small enough to stay within 0.5 px.
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (std::size_t i = 0; i < scene.images.size(); ++i) mean += scene.planted_m[i] + result.shift_en_m[i];
  mean /= scene.images.size();
  for (std::size_t i = 0; i < scene.images.size(); ++i) {
    const Eigen::Vector2d left = scene.planted_m[i] + result.shift_en_m[i] - mean;
    EXPECT_LT(left.norm() / kGsd, 0.5) << scene.images[i].id;
  }
  EXPECT_LT((mean - 0.5 * planted).norm() / kGsd, 0.3);
}

TEST(ImageNetworkAdjustment, AnImageThatCannotBeReadStaysWhereItIs) {
  Scene scene;
  scene.addPass("out", 40, 0, 80, 8, 0.0, Eigen::Vector2d::Zero());
  scene.addPass("back", 180, 560, -80, 8, 100.0, Eigen::Vector2d(0.005, 0.0));
  scene.crop_of.erase("back5");
  const et::ImageAdjustment result =
      et::adjustImages(scene.images, [&scene](const std::string& id) { return scene.load(id); });
  ASSERT_TRUE(result.problem.empty()) << result.problem;
  EXPECT_EQ(result.images_with_features, 15);
  for (std::size_t i = 0; i < scene.images.size(); ++i) {
    if (scene.images[i].id == "back5") {
      EXPECT_EQ(result.shift_en_m[i].norm(), 0.0);
    }
  }
  EXPECT_LT(result.cross_after_max_px, 0.2);
}

TEST(ImageNetworkAdjustment, TheTwoDrawingsOfAnImageSharedByTwoTilesAreBroughtTogether) {
  // The last image of one tile drawn again as the first of the next, which places it 1.5 px further east and turned by
  // 4 mrad, as do the rest of that tile's images: both drawings end where one image would.
  Scene scene;
  scene.addPass("first", 40, 0, 80, 6, 0.0, Eigen::Vector2d::Zero());
  scene.addPass("second", 40, 400, 80, 6, 5.0, Eigen::Vector2d(0.0075, 0.0));
  for (std::size_t i = 6; i < scene.images.size(); ++i) {
    et::AdjustableImage& image = scene.images[i];
    const cv::Vec3d c = image.en_from_px * cv::Vec3d(200, 150, 1);
    const double co = std::cos(0.004), si = std::sin(0.004);
    image.en_from_px = cv::Matx33d(co, -si, c[0] - co * c[0] + si * c[1], si, co, c[1] - si * c[0] - co * c[1], 0, 0,
                                   1) * image.en_from_px;
  }
  scene.images[6].id = "shared in the second tile";  // the same pixels as first5
  scene.images[6].source = "first5";
  scene.crop_of["shared in the second tile"] = scene.crop_of["first5"];
  const et::ImageAdjustment result =
      et::adjustImages(scene.images, [&scene](const std::string& id) { return scene.load(id); });
  ASSERT_TRUE(result.problem.empty()) << result.problem;
  bool found = false;
  for (const et::ImagePairTies& p : result.pairs)
    if (p.same_image) {
      found = true;
      EXPECT_GT(p.before_px, 1.4);
      EXPECT_LT(p.after_px, 0.05);
    }
  EXPECT_TRUE(found);
}

TEST(ImageNetworkAdjustment, ImagesThatDoNotOverlapAreLeftAsTheyAre) {
  Scene scene;
  scene.addPass("out", 0, 0, 420, 2, 0.0, Eigen::Vector2d::Zero());
  const et::ImageAdjustment result =
      et::adjustImages(scene.images, [&scene](const std::string& id) { return scene.load(id); });
  EXPECT_EQ(result.problem, "no overlapping images");
  for (const Eigen::Vector2d& s : result.shift_en_m) EXPECT_EQ(s.norm(), 0.0);
}

TEST(ImageNetworkAdjustment, ABadConfigurationNamesEachFieldWithItsRange) {
  et::ImageAdjustmentConfig config;
  config.search_radius_px = 0;
  config.min_ties = 2;
  const std::string why = config.validate();
  EXPECT_NE(why.find("search_radius_px must be in (0, 200]"), std::string::npos) << why;
  EXPECT_NE(why.find("min_ties must be in [3, 100000]"), std::string::npos) << why;
  Scene scene;
  scene.addPass("out", 100, 0, 40, 3, 0.0, Eigen::Vector2d::Zero());
  const et::ImageAdjustment result =
      et::adjustImages(scene.images, [&scene](const std::string& id) { return scene.load(id); }, config);
  EXPECT_EQ(result.problem, why);
}

TEST(ImageNetworkAdjustment, FeatureTiesMoveTheReturnPassToo) {
  Scene scene;
  scene.addPass("out", 40, 0, 80, 11, 0.0, Eigen::Vector2d::Zero());
  const Eigen::Vector2d planted(-0.006, 0.008);
  scene.addPass("back", 180, 800, -80, 11, 100.0, planted);
  et::ImageAdjustmentConfig config;
  config.tie_method = "sift";
  const et::ImageAdjustment result =
      et::adjustImages(scene.images, [&scene](const std::string& id) { return scene.load(id); }, config);
  ASSERT_TRUE(result.problem.empty()) << result.problem;
  EXPECT_EQ(result.images_with_features, 22);
  EXPECT_NEAR(result.cross_before_max_px, planted.norm() / kGsd, 0.5);
  EXPECT_LT(result.cross_after_max_px, 0.3);
}

TEST(ImageNetworkAdjustment, AReturnPassTurnedAboutItsImagesIsTurnedBack) {
  // Each image of the return pass placed turned by 6 mrad about its centre (1.5 px at its corners) and shifted: the
  // adjustment turns them back relative to the outbound pass.
  Scene scene;
  scene.addPass("out", 40, 0, 80, 11, 0.0, Eigen::Vector2d::Zero());
  scene.addPass("back", 180, 800, -80, 11, 100.0, Eigen::Vector2d(0.004, 0.0));
  const double turned_rad = 0.006;
  for (std::size_t i = 11; i < scene.images.size(); ++i) {
    et::AdjustableImage& image = scene.images[i];
    const cv::Vec3d c = image.en_from_px * cv::Vec3d(200, 150, 1);
    const double co = std::cos(turned_rad), si = std::sin(turned_rad);
    const cv::Matx33d turn(co, -si, c[0] - co * c[0] + si * c[1], si, co, c[1] - si * c[0] - co * c[1], 0, 0, 1);
    image.en_from_px = turn * image.en_from_px;
  }
  const et::ImageAdjustment result =
      et::adjustImages(scene.images, [&scene](const std::string& id) { return scene.load(id); });
  ASSERT_TRUE(result.problem.empty()) << result.problem;
  EXPECT_LT(result.cross_after_max_px, 0.25);
  // Most of the turn comes back as the images' rotation; the rest as moves of their centres (a narrow overlap tells a
  // turn from a shear along it only so well), and the ties agree either way (above).
  for (std::size_t i = 0; i < 11; ++i)
    EXPECT_NEAR(result.rotation_rad[11 + i] - result.rotation_rad[i], -turned_rad, 0.0025) << scene.images[11 + i].id;
}

TEST(ImageNetworkAdjustment, AMovedPlacementMovesTheGroundPointsInItsFrame) {
  const cv::Matx33d frame_from_px(0.01, 0.002, 10, -0.002, 0.01, 20, 0, 0, 1);
  const Eigen::Vector2d origin(500000, 4800000);
  // A turn of 0.01 rad about (500010, 4800020) and a shift of (0.5, -0.25) m, in absolute E, N.
  const double co = std::cos(0.01), si = std::sin(0.01);
  const cv::Matx33d move(co, -si, 500010 - co * 500010 + si * 4800020 + 0.5,  //
                         si, co, 4800020 - si * 500010 - co * 4800020 - 0.25, 0, 0, 1);
  const cv::Matx33d moved = et::movedPlacement(frame_from_px, move, origin);
  const cv::Vec3d p = frame_from_px * cv::Vec3d(30, 40, 1), q = moved * cv::Vec3d(30, 40, 1);
  const cv::Vec3d expected = move * cv::Vec3d(p[0] + origin.x(), p[1] + origin.y(), 1);
  EXPECT_NEAR(q[0] + origin.x(), expected[0], 1e-6);
  EXPECT_NEAR(q[1] + origin.y(), expected[1], 1e-6);
}
