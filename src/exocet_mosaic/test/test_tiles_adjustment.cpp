// The tile network adjustment: tiles cut from a known ortho-image and written with known georeference errors are
// measured pair by pair and moved back into agreement; the adjusted copies carry the moved georeference.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include <gdal_priv.h>
#include <sys/stat.h>

#include "compose_fixtures.h"
#include "exocet_common/testing/temp_dir.h"
#include "exocet_mosaic/tiles/geotiff_tile_writer.h"
#include "exocet_mosaic/tiles/tile_network_adjustment.h"

namespace et = exocet_mosaic::tiles;
using TempDir = exocet_common::testing::TempDir;

namespace {

constexpr double kGsd = 0.005;

struct PlantedTile {
  cv::Rect truth_px;        // the tile's pixels in the truth ortho-image
  Eigen::Vector2d error_m;  // written georeference minus the true one
  double rotation_rad = 0;  // the tile's content turned about its centre (counter-clockwise on the map)

  /// Where the tile shows the seabed point that truly is at p (UTM), minus p.
  Eigen::Vector2d errorAt(const Eigen::Vector2d& p, const compose_test::TruthOrtho& truth) const {
    const Eigen::Vector2d centre(truth.origin_e_m + (truth_px.x + 0.5 * truth_px.width) * kGsd,
                                 truth.origin_n_m - (truth_px.y + 0.5 * truth_px.height) * kGsd);
    const Eigen::Vector2d d = p - centre;
    const double c = std::cos(rotation_rad), s = std::sin(rotation_rad);
    return error_m + Eigen::Vector2d(c * d.x() - s * d.y(), s * d.x() + c * d.y()) - d;
  }
};

/// Writes the tiles: crops of the truth, their origins off by error_m, the left 20 columns no data.
std::vector<std::string> writeTiles(const compose_test::TruthOrtho& truth, const std::vector<PlantedTile>& planted,
                                    const std::string& folder) {
  et::TileWriterConfig config;
  config.output_dir = folder;
  et::GeoTiffTileWriter writer(config);
  std::vector<std::string> paths;
  for (const PlantedTile& p : planted) {
    et::TileRaster raster;
    if (p.rotation_rad == 0) {
      raster.image = truth.image(p.truth_px).clone();
    } else {
      // Content turned by +rotation on the map (north up, rows down): the tile pixel (u, v) shows the truth at the
      // centre plus the inverse rotation of (u, v) - centre.
      const cv::Point2d centre(p.truth_px.x + 0.5 * p.truth_px.width - 0.5,
                               p.truth_px.y + 0.5 * p.truth_px.height - 0.5);
      const double c = std::cos(p.rotation_rad), s = std::sin(p.rotation_rad);
      const double cu = 0.5 * p.truth_px.width - 0.5, cv_ = 0.5 * p.truth_px.height - 0.5;
      // map: truth (x, y) from tile (u, v): x - cx = c du - s dv' with dv' in map axes (y down flips the sign).
      const cv::Matx23d map(c, -s, centre.x - c * cu + s * cv_, s, c, centre.y - s * cu - c * cv_);
      cv::warpAffine(truth.image, raster.image, map, p.truth_px.size(), cv::INTER_LINEAR | cv::WARP_INVERSE_MAP);
    }
    raster.mask = cv::Mat(raster.image.size(), CV_8UC1, cv::Scalar(255));
    raster.mask.colRange(0, 20).setTo(0);
    raster.gsd_m = kGsd;
    raster.origin_easting_m = truth.origin_e_m + p.truth_px.x * kGsd + p.error_m.x();
    raster.origin_northing_m = truth.origin_n_m - p.truth_px.y * kGsd + p.error_m.y();
    raster.utm_zone = 31;
    et::TileMetadata metadata;
    metadata.extra["position_sigma_m"] = "0.05";
    const et::WrittenTile tile = writer.write(raster, metadata);
    EXPECT_TRUE(tile.ok) << tile.error;
    paths.push_back(tile.geotiff_path);
  }
  return paths;
}

std::vector<PlantedTile> fourTilesTwoLines() {
  // Two "lines" of two tiles; the second line (a return pass) off by 2-4 cm from the first, as a USBL would put it,
  // and its second tile turned by 4 mrad (1.4 px across it).
  return {{cv::Rect(0, 0, 700, 450), Eigen::Vector2d(0.004, -0.002)},
          {cv::Rect(450, 0, 700, 450), Eigen::Vector2d(0.006, 0.001)},
          {cv::Rect(0, 300, 700, 450), Eigen::Vector2d(-0.021, 0.030)},
          {cv::Rect(450, 300, 700, 450), Eigen::Vector2d(-0.018, 0.033), 0.004}};
}

}  // namespace

TEST(TilesAdjustment, OverlappingTilesAreMovedBackIntoAgreement) {
  const compose_test::TruthOrtho truth =
      compose_test::TruthOrtho::make(1150 * kGsd, 750 * kGsd, kGsd, 500000.0, 4800000.0);
  TempDir live, adjusted;
  const std::vector<PlantedTile> planted = fourTilesTwoLines();
  const std::vector<std::string> paths = writeTiles(truth, planted, live.path());
  ASSERT_EQ(paths.size(), 4u);

  et::TileAdjustmentResult result = et::measureAndSolve(paths, et::TileAdjustmentConfig());
  ASSERT_TRUE(result.ok) << result.error;
  ASSERT_EQ(result.tiles.size(), 4u);
  EXPECT_EQ(result.pairs.size(), 6u);  // every pair overlaps (the diagonal ones by 250 x 150 px)
  Eigen::Vector2d mean_shift = Eigen::Vector2d::Zero();
  for (const auto& t : result.tiles) {
    EXPECT_NEAR(t.position_sigma_m, 0.05, 1e-9);
    mean_shift += t.shift_en_m / 4.0;
  }
  for (const auto& p : result.pairs) {
    const Eigen::Vector2d centre = 0.5 * (result.tiles[p.a].centre_en_m + result.tiles[p.b].centre_en_m);
    const Eigen::Vector2d planted_offset = planted[p.b].errorAt(centre, truth) - planted[p.a].errorAt(centre, truth);
    // Whole 256 px patches measure a translation to a tenth of a pixel; the small overlaps of the diagonal pairs, and
    // pairs with the turned tile (their offset varies across the overlap), are only printed.
    if (p.patch_px >= 256 && planted[p.a].rotation_rad == 0 && planted[p.b].rotation_rad == 0) {
      EXPECT_LT((p.offset_en_m - planted_offset).norm(), 0.2 * kGsd)
          << "pair " << p.a << "-" << p.b << ": measured " << p.offset_en_m.transpose() << ", planted "
          << planted_offset.transpose();
    }
    // After the adjustment the tiles agree everywhere in their overlap (the small overlaps weigh less): what remains
    // is the measurement noise.
    double worst_after = 0;
    for (const auto& o : p.patch_offsets) {
      const Eigen::Vector2d x = o.centre_en_m;
      const Eigen::Vector2d after = planted[p.b].errorAt(x, truth) - planted[p.a].errorAt(x, truth) +
                                    (result.tiles[p.b].moved(x) - x) - (result.tiles[p.a].moved(x) - x);
      worst_after = std::max(worst_after, after.norm());
    }
    EXPECT_LT(worst_after, 1.0 * kGsd) << "pair " << p.a << "-" << p.b;  // planted: ~8 px
    std::printf("pair %d-%d: planted %.2f px apart, measured to %.3f px, at most %.3f px after (%d patches)\n", p.a,
                p.b, planted_offset.norm() / kGsd, (p.offset_en_m - planted_offset).norm() / kGsd, worst_after / kGsd,
                p.patches);
  }
  // Equal navigation sigmas: the network as a whole stays where the navigation put it.
  EXPECT_LT(mean_shift.norm(), 1e-3);

  et::writeAdjustedTiles(adjusted.path(), &result);
  ASSERT_TRUE(result.ok) << result.error;
  ASSERT_EQ(result.written.size(), 4u);
  GDALAllRegister();
  for (size_t i = 0; i < 4; ++i) {
    EXPECT_EQ(result.written[i], adjusted.path() + paths[i].substr(paths[i].rfind('/')));  // the same name
    std::unique_ptr<GDALDataset> moved(GDALDataset::Open(result.written[i].c_str(), GDAL_OF_RASTER));
    std::unique_ptr<GDALDataset> original(GDALDataset::Open(paths[i].c_str(), GDAL_OF_RASTER));
    ASSERT_TRUE(moved && original);
    double gt[6];
    moved->GetGeoTransform(gt);
    EXPECT_DOUBLE_EQ(gt[1], kGsd);
    EXPECT_EQ(moved->GetRasterCount(), 4);
    ASSERT_NE(moved->GetMetadataItem("EXOCET_ADJUSTMENT_E_M"), nullptr);
    EXPECT_NEAR(std::stod(moved->GetMetadataItem("EXOCET_ADJUSTMENT_E_M")), result.tiles[i].shift_en_m.x(), 1e-9);
    ASSERT_NE(moved->GetMetadataItem("EXOCET_ADJUSTMENT_ROTATION_RAD"), nullptr);
    EXPECT_STREQ(moved->GetMetadataItem("EXOCET_POSITION_SIGMA_M"),
                 original->GetMetadataItem("EXOCET_POSITION_SIGMA_M"));
    EXPECT_STREQ(moved->GetMetadataItem("EXOCET_TILE_INDEX"), original->GetMetadataItem("EXOCET_TILE_INDEX"));
    // The world file beside it locates the centre of the top-left pixel.
    const std::string world = result.written[i].substr(0, result.written[i].size() - 4) + ".tfw";
    std::ifstream in(world);
    double w[6];
    for (double& v : w) in >> v;
    ASSERT_TRUE(in) << world;
    EXPECT_NEAR(w[4], gt[0] + 0.5 * kGsd, 1e-6);
    EXPECT_NEAR(w[5], gt[3] - 0.5 * kGsd, 1e-6);
  }
  // End to end: the adjusted tiles, measured again, agree.
  const et::TileAdjustmentResult check = et::measureAndSolve(result.written, et::TileAdjustmentConfig());
  ASSERT_TRUE(check.ok) << check.error;
  EXPECT_EQ(check.pairs.size(), 6u);
  for (const auto& p : check.pairs) {
    std::printf("adjusted pair %d-%d: %.3f px apart\n", p.a, p.b, p.offset_en_m.norm() / kGsd);
    EXPECT_LT(p.offset_en_m.norm(), (p.patch_px >= 256 ? 0.5 : 1.0) * kGsd) << "pair " << p.a << "-" << p.b;
  }
  // Nothing is overwritten: a second run into the same folder fails and says so.
  et::TileAdjustmentResult again = et::measureAndSolve(paths, et::TileAdjustmentConfig());
  et::writeAdjustedTiles(adjusted.path(), &again);
  EXPECT_FALSE(again.ok);
  EXPECT_NE(again.error.find("exists"), std::string::npos) << again.error;
}

TEST(TilesAdjustment, BadInputIsNamed) {
  TempDir dir;
  const std::string not_a_tile = dir.path() + "/tile_0000.tif";
  std::ofstream(not_a_tile) << "not a GeoTIFF";
  const et::TileAdjustmentResult result = et::measureAndSolve({not_a_tile}, et::TileAdjustmentConfig());
  EXPECT_FALSE(result.ok);
  EXPECT_NE(result.error.find(not_a_tile), std::string::npos) << result.error;

  et::TileAdjustmentConfig config;
  config.patch_px = 100;
  const et::TileAdjustmentResult invalid = et::measureAndSolve({}, config);
  EXPECT_FALSE(invalid.ok);
  EXPECT_NE(invalid.error.find("patch_px must be a power of two in [32, 1024], got 100"), std::string::npos)
      << invalid.error;
}

TEST(TilesAdjustment, ACacheMeasuresOnlyThePairsOfANewFileAndSolvesTheSame) {
  const compose_test::TruthOrtho truth =
      compose_test::TruthOrtho::make(1150 * kGsd, 750 * kGsd, kGsd, 500000.0, 4800000.0);
  TempDir live;
  const std::vector<std::string> paths = writeTiles(truth, fourTilesTwoLines(), live.path());
  ASSERT_EQ(paths.size(), 4u);
  const et::TileAdjustmentResult plain = et::measureAndSolve(paths, et::TileAdjustmentConfig());
  ASSERT_TRUE(plain.ok) << plain.error;

  et::TilePairCache cache;
  const et::TileAdjustmentResult first = et::measureAndSolve(paths, et::TileAdjustmentConfig(), &cache);
  ASSERT_TRUE(first.ok) << first.error;
  EXPECT_EQ(cache.measured(), 6);  // every pair of the same EPSG and GSD, overlapping or not
  EXPECT_EQ(cache.reused(), 0);
  const et::TileAdjustmentResult second = et::measureAndSolve(paths, et::TileAdjustmentConfig(), &cache);
  ASSERT_TRUE(second.ok) << second.error;
  EXPECT_EQ(cache.measured(), 6);  // nothing read again
  EXPECT_EQ(cache.reused(), 6);
  for (const et::TileAdjustmentResult* r : {&first, &second}) {
    ASSERT_EQ(r->pairs.size(), plain.pairs.size());
    for (std::size_t i = 0; i < plain.pairs.size(); ++i) {
      EXPECT_EQ(r->pairs[i].a, plain.pairs[i].a);
      EXPECT_EQ(r->pairs[i].b, plain.pairs[i].b);
      EXPECT_NEAR((r->pairs[i].offset_en_m - plain.pairs[i].offset_en_m).norm(), 0.0, 1e-12);
    }
    for (std::size_t i = 0; i < plain.tiles.size(); ++i)
      EXPECT_NEAR((r->tiles[i].shift_en_m - plain.tiles[i].shift_en_m).norm(), 0.0, 1e-12);
  }

  // Tile 3 drawn again (a new version, a new name) with its error removed: only its three pairs are measured, and
  // the solution is that of a full measurement.
  std::vector<PlantedTile> redrawn = fourTilesTwoLines();
  redrawn[3].error_m = Eigen::Vector2d(0.0, 0.0);
  TempDir other;
  const std::vector<std::string> again = writeTiles(truth, redrawn, other.path());
  std::vector<std::string> now = paths;
  now[3] = live.path() + "/tile_0003_v2.tif";
  ASSERT_EQ(std::rename(again[3].c_str(), now[3].c_str()), 0);
  const et::TileAdjustmentResult third = et::measureAndSolve(now, et::TileAdjustmentConfig(), &cache);
  ASSERT_TRUE(third.ok) << third.error;
  EXPECT_EQ(cache.measured(), 9);
  EXPECT_EQ(cache.reused(), 9);
  EXPECT_EQ(cache.size(), 6u);  // the pairs of the old version are let go
  const et::TileAdjustmentResult full = et::measureAndSolve(now, et::TileAdjustmentConfig());
  ASSERT_TRUE(full.ok) << full.error;
  ASSERT_EQ(third.pairs.size(), full.pairs.size());
  for (std::size_t i = 0; i < full.tiles.size(); ++i)
    EXPECT_NEAR((third.tiles[i].shift_en_m - full.tiles[i].shift_en_m).norm(), 0.0, 1e-12);
  // And the new version did change what tile 3 needs: its shift differs from the first solution's.
  EXPECT_GT((third.tiles[3].shift_en_m - first.tiles[3].shift_en_m).norm(), 0.005);
}
