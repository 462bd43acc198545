// Tests of the simulator's debris field: objects of the named heights with sides no steeper than the bound the ray
// marcher relies on, the same objects in every area, and a texture that shows them.
#include <gtest/gtest.h>

#include <cmath>
#include <memory>

#include "exocet_mosaic/sim/debris_field.h"
#include "exocet_mosaic/sim/dive_description.h"
#include "exocet_mosaic/sim/procedural_seabed.h"

using namespace exocet_mosaic::sim;

namespace {

DebrisRelief wreckRelief(uint64_t seed) {
  return DebrisRelief(DebrisFieldConfig::fromPreset("wreck", seed), std::make_unique<FlatRelief>());
}

}  // namespace

TEST(DebrisField, ObjectsAreTallerThanTwentyCentimetresAndAtMostSixtyWithStrongRelief) {
  DebrisRelief relief = wreckRelief(7);
  const std::vector<DebrisObject> objects = relief.objects(WorldRect{0, 0, 20, 20});
  ASSERT_GT(objects.size(), 50u);  // 0.5 per square metre on average over 400 m^2
  double highest = 0.0;
  for (const DebrisObject& o : objects) {
    EXPECT_GE(o.top_height_m, 0.2 - 0.03 - 1e-9);  // drawn in [0.2, 0.6], minus the embedding
    EXPECT_LE(o.top_height_m, 0.6);
    EXPECT_NEAR(relief.heightAt_m(o.x_m, o.y_m), o.foot_m + o.profileHeight_m(o.x_m, o.y_m), 0.3);
    highest = std::max(highest, relief.heightAt_m(o.x_m, o.y_m));
  }
  EXPECT_GT(highest, 0.45);
}

TEST(DebrisField, NoSideIsSteeperThanTheBoundTheRayMarcherUses) {
  DebrisRelief relief = wreckRelief(11);
  const double bound = relief.maxSlope();
  EXPECT_GE(bound, 3.0);
  const double step = 0.002;
  double steepest = 0.0;
  for (double y = 0.0; y < 6.0; y += 0.013)
    for (double x = 0.0; x < 6.0; x += 0.013) {
      const double h = relief.heightAt_m(x, y);
      const double gx = (relief.heightAt_m(x + step, y) - h) / step;
      const double gy = (relief.heightAt_m(x, y + step) - h) / step;
      steepest = std::max(steepest, std::hypot(gx, gy));
    }
  EXPECT_LE(steepest, bound);
  EXPECT_GT(steepest, 2.0);  // the sides are steep indeed
}

TEST(DebrisField, PatchesAgreeWithThePointHeightsWhateverTheArea) {
  DebrisRelief relief = wreckRelief(3);
  const TexturePatch<float> big = relief.heightPatch(WorldRect{-2, -2, 4, 4});
  const TexturePatch<float> small = relief.heightPatch(WorldRect{1.0, 0.5, 1.8, 1.4});
  for (double y = 0.6; y < 1.3; y += 0.05)
    for (double x = 1.1; x < 1.7; x += 0.05) {
      const double exact = relief.heightAt_m(std::round(x / 0.01) * 0.01, std::round(y / 0.01) * 0.01);
      EXPECT_NEAR(big.sample(std::round(x / 0.01) * 0.01, std::round(y / 0.01) * 0.01), exact, 1e-5);
      EXPECT_NEAR(small.sample(std::round(x / 0.01) * 0.01, std::round(y / 0.01) * 0.01), exact, 1e-5);
    }
}

TEST(DebrisField, TheTextureShowsTheObjectsAndTheDescriptionNamesThePresets) {
  Seabed seabed;
  SeabedSpec spec;
  spec.objects = "wreck";
  seabed = makeSeabed(spec, 5);
  auto* relief = dynamic_cast<DebrisRelief*>(seabed.relief.get());
  ASSERT_NE(relief, nullptr);
  const std::vector<DebrisObject> objects = relief->objects(WorldRect{0, 0, 10, 10});
  ASSERT_FALSE(objects.empty());
  const DebrisObject& o = objects.front();
  ProceduralSeabedConfig plain;
  plain.seed = 5;
  ProceduralSeabedTexture sand(plain);
  const WorldRect area{o.x_m - 0.05, o.y_m - 0.05, o.x_m + 0.05, o.y_m + 0.05};
  const TexturePatch<cv::Vec3f> with = seabed.texture->albedoPatch(0, area);
  const TexturePatch<cv::Vec3f> without = sand.albedoPatch(0, area);
  ASSERT_EQ(with.texels.size(), without.texels.size());
  EXPECT_GT(cv::norm(with.texels, without.texels, cv::NORM_L1) / with.texels.total(), 0.05);

  EXPECT_THROW(parseDiveDescription("seabed: {objects: reef}", {}, "."), std::invalid_argument);
  const DiveDescription d = parseDiveDescription("seabed: {objects: boulders}", {}, ".");
  EXPECT_EQ(d.seabed.objects, "boulders");
  EXPECT_NE(toYaml(d).find("objects: boulders"), std::string::npos);
}
