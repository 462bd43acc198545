// Cutting GeoTIFF tiles into web tiles: geometry (a marked pixel lands where the projection says), no-data, the
// incremental re-cut, the compositing order, the parents, the MBTiles export, the GeoTIFFs that cannot be used.
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <set>

#include <gtest/gtest.h>
#include <sqlite3.h>

#include "exocet_common/testing/temp_dir.h"
#include "exocet_common/utm_grid.h"
#include "exocet_web/tiles/source_tile.h"
#include "exocet_web/tiles/tile_packages.h"
#include "exocet_web/tiles/web_tile_cutter.h"
#include "synthetic_geotiff.h"

namespace et = exocet_web::tiles;
using exocet_common::testing::TempDir;
using exocet_web::testing::SyntheticTile;
using exocet_web::testing::webPixel;
using exocet_web::testing::writeSyntheticGeoTiff;

namespace {

constexpr double kLat = 43.0712, kLon = 5.8790;  // the sample dive's origin, UTM 31 N

const exocet_common::UtmGrid& grid() {
  static const exocet_common::UtmGrid g = exocet_common::UtmGrid::fromZone(31, true);
  return g;
}

/// A tile whose top-left corner is `east_m`, `north_m` metres from the dive's origin.
SyntheticTile tileAt(double east_m, double north_m, double gsd_m, int width_px, int height_px) {
  const Eigen::Vector2d origin = grid().toGrid(kLat, kLon);
  SyntheticTile t;
  t.origin_easting_m = origin.x() + east_m;
  t.origin_northing_m = origin.y() + north_m;
  t.gsd_m = gsd_m;
  t.width_px = width_px;
  t.height_px = height_px;
  return t;
}

/// Latitude, longitude of the centre of pixel (col, row) of a synthetic tile.
Eigen::Vector2d pixelLatLon(const SyntheticTile& t, double col, double row) {
  return grid().toLatLon(t.origin_easting_m + (col + 0.5) * t.gsd_m, t.origin_northing_m - (row + 0.5) * t.gsd_m);
}

et::SourceTile source(const std::string& path) {
  et::SourceTile s;
  const std::string error = et::readSourceTile(path, &s);
  EXPECT_EQ(error, "");
  return s;
}

/// BGRA of the web pixel holding a WGS 84 point at level z; alpha 0 when the tile is missing.
cv::Vec4b webPixelAt(const et::WebTileCutter& cutter, const Eigen::Vector2d& lat_lon, int z) {
  const cv::Point2d p = webPixel(lat_lon.x(), lat_lon.y(), z);
  const et::TileId id{z, int(std::floor(p.x / 256)), int(std::floor(p.y / 256))};
  const cv::Mat tile = exocet_web::testing::readWebTile(cutter.tilePath(id));
  if (tile.empty()) return cv::Vec4b(0, 0, 0, 0);
  return tile.at<cv::Vec4b>(int(std::floor(p.y - id.y * 256.0)), int(std::floor(p.x - id.x * 256.0)));
}

std::map<std::string, std::string> readAll(const std::string& folder) {
  std::map<std::string, std::string> files;
  for (const auto& e : std::filesystem::recursive_directory_iterator(folder)) {
    if (!e.is_regular_file()) continue;
    std::ifstream in(e.path(), std::ios::binary);
    files[e.path().string()] = std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  }
  return files;
}

et::CutterConfig configFor(const TempDir& dir, int max_zoom = -1, int min_zoom = -1) {
  et::CutterConfig c;
  c.output_dir = dir.file("tiles");
  c.max_zoom = max_zoom;
  c.min_zoom = min_zoom;
  return c;
}

}  // namespace

TEST(WebTileCutter, AMarkedPixelLandsWhereTheProjectionPutsIt) {
  TempDir dir;
  // 3.4 mm: level 25's pixel at 43 N (3.41 mm); a red pixel at (200, 150) on grey; the left 50 columns no data.
  SyntheticTile t = tileAt(0.0, 0.0, 0.0034, 400, 300);
  t.pixel = [](int c, int r) {
    if (c < 50) return cv::Vec4b(0, 0, 0, 0);
    if (c == 200 && r == 150) return cv::Vec4b(0, 0, 255, 255);
    return cv::Vec4b(100, 100, 100, 255);
  };
  ASSERT_TRUE(writeSyntheticGeoTiff(dir.file("tile_0000.tif"), t));
  et::WebTileCutter cutter(configFor(dir));
  const et::CutReport report = cutter.update(source(dir.file("tile_0000.tif")));
  ASSERT_TRUE(report.ok) << report.error;
  const int z = cutter.maxZoom();
  EXPECT_EQ(z, 25);  // the native level of a 3.4 mm gsd at 43 N

  // The redness-weighted centroid of the web pixels around the mark, against where the mark's centre projects.
  const Eigen::Vector2d mark = pixelLatLon(t, 200, 150);
  const cv::Point2d expected = webPixel(mark.x(), mark.y(), z);
  double sum = 0, sx = 0, sy = 0;
  for (int dy = -6; dy <= 6; ++dy)
    for (int dx = -6; dx <= 6; ++dx) {
      // Global pixel indices pass 2^31 beyond level 23.
      const int64_t gx = int64_t(std::floor(expected.x)) + dx, gy = int64_t(std::floor(expected.y)) + dy;
      const et::TileId id{z, int(gx / 256), int(gy / 256)};
      const cv::Mat tile = exocet_web::testing::readWebTile(cutter.tilePath(id));
      ASSERT_FALSE(tile.empty()) << id.path();
      const cv::Vec4b p = tile.at<cv::Vec4b>(int(gy - int64_t(id.y) * 256), int(gx - int64_t(id.x) * 256));
      const double w = std::max(0, int(p[2]) - int(p[1]));
      sum += w;
      sx += w * (gx + 0.5);  // pixel centres
      sy += w * (gy + 0.5);
    }
  ASSERT_GT(sum, 0.0) << "the red mark is not in the web tiles";
  EXPECT_NEAR(sx / sum, expected.x, 1.0);
  EXPECT_NEAR(sy / sum, expected.y, 1.0);

  // No data stays no data; data is opaque.
  EXPECT_EQ(webPixelAt(cutter, pixelLatLon(t, 20, 150), z)[3], 0);
  const cv::Vec4b grey = webPixelAt(cutter, pixelLatLon(t, 300, 100), z);
  EXPECT_EQ(grey[3], 255);
  EXPECT_NEAR(grey[0], 100, 2);
  // Every level down to the one where the tile fits in one web tile.
  EXPECT_EQ(cutter.minZoom(), et::zoomFittingBox(cutter.surveyBounds(), z));
  EXPECT_LT(cutter.minZoom(), z);
  for (int level = cutter.minZoom(); level <= z; ++level)
    EXPECT_EQ(webPixelAt(cutter, pixelLatLon(t, 300, 100), level)[3], 255) << "level " << level;
}

TEST(WebTileCutter, ANewTileRecutsOnlyTheWebTilesItTouches) {
  TempDir dir;
  SyntheticTile a = tileAt(0.0, 0.0, 0.005, 400, 300);   // 2 x 1.5 m
  SyntheticTile b = tileAt(6.0, -1.0, 0.005, 400, 300);  // 4 m east of a's east edge
  b.pixel = [](int, int) { return cv::Vec4b(200, 60, 20, 255); };
  ASSERT_TRUE(writeSyntheticGeoTiff(dir.file("tile_0000.tif"), a));
  ASSERT_TRUE(writeSyntheticGeoTiff(dir.file("tile_0001.tif"), b));
  et::WebTileCutter cutter(configFor(dir, 24, 18));
  ASSERT_TRUE(cutter.update(source(dir.file("tile_0000.tif"))).ok);
  const auto before = readAll(dir.file("tiles"));
  const et::SourceTile sb = source(dir.file("tile_0001.tif"));
  const et::CutReport report = cutter.update(sb);
  ASSERT_TRUE(report.ok) << report.error;
  ASSERT_FALSE(report.written.empty());

  // Every tile written at every level intersects b's outline; the ones that do not are byte for byte as before.
  std::set<std::string> written;
  for (const auto& t : report.written) {
    EXPECT_TRUE(et::tileBounds(t).intersects(sb.bounds)) << t.path();
    written.insert(cutter.tilePath(t));
  }
  EXPECT_TRUE(report.removed.empty());
  const auto after = readAll(dir.file("tiles"));
  int untouched = 0;
  for (const auto& [path, bytes] : before) {
    if (written.count(path)) continue;
    ASSERT_TRUE(after.count(path)) << path;
    EXPECT_EQ(after.at(path), bytes) << path << " changed though b does not touch it";
    ++untouched;
  }
  EXPECT_GT(untouched, 10);
  // The finest tiles written are those of b's outline that hold some of b.
  const et::TileRange range = et::tilesCovering(sb.bounds, 24);
  int finest = 0;
  for (const auto& t : report.written) finest += t.z == 24;
  EXPECT_GE(finest, range.count() - 2 * (range.max_x - range.min_x + range.max_y - range.min_y + 2));
  EXPECT_LE(finest, range.count());
  // Its centre is on the map.
  const cv::Vec4b centre = webPixelAt(cutter, pixelLatLon(b, 200, 150), 24);
  EXPECT_EQ(centre[3], 255);
  EXPECT_NEAR(centre[0], 200, 2);
}

TEST(WebTileCutter, TheNewestTileIsOnTopAndNoDataShowsWhatIsUnder) {
  // a (red) and b (blue, no data on its left half) overlap on a's right half; b is written after a.
  SyntheticTile a = tileAt(0.0, 0.0, 0.005, 400, 300);
  a.pixel = [](int, int) { return cv::Vec4b(0, 0, 220, 255); };
  SyntheticTile b = tileAt(0.5, 0.0, 0.005, 400, 300);  // 100 columns east of a: its data from a's column 300
  b.pixel = [](int c, int) { return c < 200 ? cv::Vec4b(0, 0, 0, 0) : cv::Vec4b(220, 0, 0, 255); };
  SyntheticTile a2 = a;  // a drawn again (a new version): green
  a2.pixel = [](int, int) { return cv::Vec4b(0, 220, 0, 255); };
  const auto p_on_b = pixelLatLon(a, 350, 150);        // under b's data (b's column 250)
  const auto p_under_hole = pixelLatLon(a, 250, 150);  // under b's no-data half (b's column 150)
  const auto p_a_only = pixelLatLon(a, 50, 150);
  const auto blue = [](const cv::Vec4b& p) { return p[0] > 180 && p[2] < 40 && p[3] == 255; };
  const auto red = [](const cv::Vec4b& p) { return p[2] > 180 && p[0] < 40 && p[3] == 255; };
  const auto green = [](const cv::Vec4b& p) { return p[1] > 180 && p[2] < 40 && p[3] == 255; };

  TempDir dir;
  ASSERT_TRUE(writeSyntheticGeoTiff(dir.file("tile_0001.tif"), a));
  ASSERT_TRUE(writeSyntheticGeoTiff(dir.file("tile_0002.tif"), b));
  ASSERT_TRUE(writeSyntheticGeoTiff(dir.file("tile_0001_v2.tif"), a2));
  {
    et::WebTileCutter cutter(configFor(dir, 24, 20));
    ASSERT_TRUE(cutter.update(source(dir.file("tile_0001.tif"))).ok);
    ASSERT_TRUE(cutter.update(source(dir.file("tile_0002.tif"))).ok);  // drawn over the web tiles
    EXPECT_TRUE(blue(webPixelAt(cutter, p_on_b, 24)));
    EXPECT_TRUE(red(webPixelAt(cutter, p_under_hole, 24)));
    EXPECT_TRUE(red(webPixelAt(cutter, p_a_only, 24)));
    // a's new version stays under b: b's key comes later.
    ASSERT_TRUE(cutter.update(source(dir.file("tile_0001_v2.tif"))).ok);
    EXPECT_EQ(cutter.sources().size(), 2u);
    EXPECT_TRUE(blue(webPixelAt(cutter, p_on_b, 24)));
    EXPECT_TRUE(green(webPixelAt(cutter, p_under_hole, 24)));
    EXPECT_TRUE(green(webPixelAt(cutter, p_a_only, 24)));
    // The coarser levels follow.
    EXPECT_TRUE(green(webPixelAt(cutter, p_a_only, 21)));
  }
  {
    TempDir other;
    std::filesystem::copy_file(dir.file("tile_0001.tif"), other.file("tile_0001.tif"));
    std::filesystem::copy_file(dir.file("tile_0002.tif"), other.file("tile_0002.tif"));
    // Cut in the other order: a goes under b all the same.
    et::WebTileCutter cutter(configFor(other, 24, 20));
    ASSERT_TRUE(cutter.update(source(other.file("tile_0002.tif"))).ok);
    ASSERT_TRUE(cutter.update(source(other.file("tile_0001.tif"))).ok);
    EXPECT_TRUE(blue(webPixelAt(cutter, p_on_b, 24)));
    EXPECT_TRUE(red(webPixelAt(cutter, p_under_hole, 24)));
    // Removing b leaves a alone.
    ASSERT_TRUE(cutter.remove("tile_0002").ok);
    EXPECT_TRUE(red(webPixelAt(cutter, p_on_b, 24)));
  }
}

TEST(WebTileCutter, AParentIsTheAlphaWeightedMeanOfItsChildren) {
  TempDir dir;
  SyntheticTile t = tileAt(0.0, 0.0, 0.005, 600, 400);
  t.pixel = [](int c, int r) {
    return cv::Vec4b((c * 7) % 256, (r * 5) % 256, ((c + r) * 3) % 256, c < 100 ? 0 : 255);
  };
  ASSERT_TRUE(writeSyntheticGeoTiff(dir.file("tile_0000.tif"), t));
  et::WebTileCutter cutter(configFor(dir, 24, 19));
  ASSERT_TRUE(cutter.update(source(dir.file("tile_0000.tif"))).ok);
  int parents = 0;
  for (const et::TileId& p : cutter.tiles()) {
    if (p.z == 24) continue;
    ++parents;
    bool any_child = false;
    for (int j = 0; j < 2; ++j)
      for (int i = 0; i < 2; ++i) any_child |= cutter.tiles().count({p.z + 1, 2 * p.x + i, 2 * p.y + j}) > 0;
    EXPECT_TRUE(any_child) << p.path();
  }
  EXPECT_GT(parents, 0);
  for (const et::TileId& c : cutter.tiles())
    EXPECT_TRUE(c.z == 19 || cutter.tiles().count(et::parentOf(c))) << c.path();
  // One parent pixel against its four children's, where all four are opaque.
  const et::TileId child =
      *std::find_if(cutter.tiles().begin(), cutter.tiles().end(), [](const et::TileId& t) { return t.z == 24; });
  const et::TileId parent = et::parentOf(child);
  const cv::Mat pc = exocet_web::testing::readWebTile(cutter.tilePath(child));
  const cv::Mat pp = exocet_web::testing::readWebTile(cutter.tilePath(parent));
  int checked = 0;
  for (int r = 0; r < 256; r += 2)
    for (int c = 0; c < 256; c += 2) {
      const cv::Vec4b q[4] = {pc.at<cv::Vec4b>(r, c), pc.at<cv::Vec4b>(r, c + 1), pc.at<cv::Vec4b>(r + 1, c),
                              pc.at<cv::Vec4b>(r + 1, c + 1)};
      if (q[0][3] != 255 || q[1][3] != 255 || q[2][3] != 255 || q[3][3] != 255) continue;
      const cv::Vec4b m = pp.at<cv::Vec4b>((child.y % 2) * 128 + r / 2, (child.x % 2) * 128 + c / 2);
      for (int k = 0; k < 3; ++k) EXPECT_NEAR(m[k], (q[0][k] + q[1][k] + q[2][k] + q[3][k]) / 4.0, 1.0);
      EXPECT_EQ(m[3], 255);
      ++checked;
    }
  EXPECT_GT(checked, 100);
}

TEST(WebTileCutter, TheMinZoomFollowsTheSurveyAndThePackagesHoldEveryTile) {
  TempDir dir;
  ASSERT_TRUE(writeSyntheticGeoTiff(dir.file("tile_0000.tif"), tileAt(0.0, 0.0, 0.005, 200, 200)));
  ASSERT_TRUE(writeSyntheticGeoTiff(dir.file("tile_0001.tif"), tileAt(150.0, -90.0, 0.005, 200, 200)));
  et::WebTileCutter cutter(configFor(dir, 24));
  ASSERT_TRUE(cutter.update(source(dir.file("tile_0000.tif"))).ok);
  const int first_min = cutter.minZoom();
  ASSERT_TRUE(cutter.update(source(dir.file("tile_0001.tif"))).ok);
  EXPECT_LT(cutter.minZoom(), first_min);  // 150 m apart: coarser levels to see both
  EXPECT_EQ(cutter.minZoom(), et::zoomFittingBox(cutter.surveyBounds(), 24));
  int at_min = 0;
  for (const auto& t : cutter.tiles()) at_min += t.z == cutter.minZoom();
  EXPECT_GE(at_min, 1);
  EXPECT_LE(at_min, 4);

  const std::string mbtiles = dir.file("survey.mbtiles");
  et::TilePackageInfo info;
  info.name = "test survey";
  const et::TilePackageResult result = et::exportMbtiles(dir.file("tiles"), mbtiles, info);
  ASSERT_TRUE(result.ok) << result.error;
  EXPECT_EQ(result.tiles, int(cutter.tiles().size()));
  EXPECT_EQ(result.min_zoom, cutter.minZoom());
  EXPECT_EQ(result.max_zoom, 24);
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open_v2(mbtiles.c_str(), &db, SQLITE_OPEN_READONLY, nullptr), SQLITE_OK);
  const auto scalar = [db](const std::string& sql) {
    sqlite3_stmt* s = nullptr;
    std::string value;
    if (sqlite3_prepare_v2(db, sql.c_str(), -1, &s, nullptr) == SQLITE_OK && sqlite3_step(s) == SQLITE_ROW)
      value = reinterpret_cast<const char*>(sqlite3_column_text(s, 0));
    sqlite3_finalize(s);
    return value;
  };
  EXPECT_EQ(scalar("SELECT COUNT(*) FROM tiles"), std::to_string(cutter.tiles().size()));
  EXPECT_EQ(scalar("SELECT value FROM metadata WHERE name = 'format'"), "png");
  EXPECT_EQ(scalar("SELECT value FROM metadata WHERE name = 'maxzoom'"), "24");
  EXPECT_EQ(scalar("SELECT value FROM metadata WHERE name = 'name'"), "test survey");
  // Rows counted from the south (TMS); the blob is the PNG file.
  const et::TileId t = *cutter.tiles().rbegin();
  const int tms_row = (1 << t.z) - 1 - t.y;
  EXPECT_EQ(scalar("SELECT length(tile_data) FROM tiles WHERE zoom_level = " + std::to_string(t.z) +
                   " AND tile_column = " + std::to_string(t.x) + " AND tile_row = " + std::to_string(tms_row)),
            std::to_string(std::filesystem::file_size(cutter.tilePath(t))));
  sqlite3_close(db);

  // The GeoPackage: GDAL (hence QGIS) reads it as one raster in EPSG:3857 at the finest level, every level an
  // overview, and a pixel read from it is the web tile's.
  const std::string gpkg = dir.file("survey.gpkg");
  const et::TilePackageResult packed = et::exportGeoPackage(dir.file("tiles"), gpkg, info);
  ASSERT_TRUE(packed.ok) << packed.error;
  EXPECT_EQ(packed.tiles, int(cutter.tiles().size()));
  GDALDatasetH ds = GDALOpen(gpkg.c_str(), GA_ReadOnly);
  ASSERT_NE(ds, nullptr);
  double gt[6];
  ASSERT_EQ(GDALGetGeoTransform(ds, gt), CE_None);
  EXPECT_NEAR(gt[1], et::resolution_m_per_px(24), 1e-9);
  EXPECT_EQ(GDALGetRasterCount(ds), 4);
  EXPECT_EQ(GDALGetOverviewCount(GDALGetRasterBand(ds, 1)), 24 - cutter.minZoom());
  // The centre of the first tile, read through GDAL, against its web tile.
  const Eigen::Vector2d centre = pixelLatLon(tileAt(0.0, 0.0, 0.005, 200, 200), 100, 100);
  const double mx = et::mercatorX_m(centre.y()), my = et::mercatorY_m(centre.x());
  const int col = int(std::floor((mx - gt[0]) / gt[1])), row = int(std::floor((my - gt[3]) / gt[5]));
  uint8_t rgba[4];
  int bands[4] = {1, 2, 3, 4};
  ASSERT_EQ(GDALDatasetRasterIO(ds, GF_Read, col, row, 1, 1, rgba, 1, 1, GDT_Byte, 4, bands, 4, 4, 1), CE_None);
  const cv::Vec4b expected = webPixelAt(cutter, centre, 24);
  EXPECT_EQ(rgba[0], expected[2]);
  EXPECT_EQ(rgba[1], expected[1]);
  EXPECT_EQ(rgba[2], expected[0]);
  EXPECT_EQ(rgba[3], 255);
  GDALClose(ds);
}

TEST(SourceTile, NamesVersionsAndTheFilesThatCannotBeUsed) {
  std::string key;
  int index = 0, version = 0;
  EXPECT_TRUE(et::parseTileFileName("tile_0007.tif", &key, &index, &version));
  EXPECT_EQ(key, "tile_0007");
  EXPECT_EQ(index, 7);
  EXPECT_EQ(version, 1);
  EXPECT_TRUE(et::parseTileFileName("dive_42_0012_v3.tif", &key, &index, &version));
  EXPECT_EQ(key, "dive_42_0012");
  EXPECT_EQ(index, 12);
  EXPECT_EQ(version, 3);
  EXPECT_FALSE(et::parseTileFileName("tile_0007.cog.tif", &key, &index, &version));
  EXPECT_FALSE(et::parseTileFileName(".tile_0007.tif.partial", &key, &index, &version));
  EXPECT_FALSE(et::parseTileFileName("overview.tif", &key, &index, &version));

  TempDir dir;
  ASSERT_TRUE(writeSyntheticGeoTiff(dir.file("tile_0000.tif"), tileAt(0, 0, 0.01, 50, 50)));
  ASSERT_TRUE(writeSyntheticGeoTiff(dir.file("tile_0001.tif"), tileAt(0, 0, 0.01, 50, 50)));
  ASSERT_TRUE(writeSyntheticGeoTiff(dir.file("tile_0001_v2.tif"), tileAt(0, 0, 0.01, 50, 50)));
  std::ofstream(dir.file("tile_0002.tif")) << "not a GeoTIFF";
  SyntheticTile local = tileAt(0, 0, 0.01, 50, 50);
  local.local_frame = true;
  ASSERT_TRUE(writeSyntheticGeoTiff(dir.file("tile_0003.tif"), local));
  std::ofstream(dir.file("tile_0000.cog.tif")) << "a copy";
  const auto paths = et::listSourceTiles(dir.path());
  ASSERT_EQ(paths.size(), 4u);
  EXPECT_EQ(std::filesystem::path(paths[1]).filename(), "tile_0001_v2.tif");

  et::SourceTile s;
  EXPECT_EQ(et::readSourceTile(dir.file("tile_0001_v2.tif"), &s), "");
  EXPECT_EQ(s.version, 2);
  EXPECT_EQ(s.epsg, 32631);
  EXPECT_EQ(s.metadata.at("frames_composed"), "42");
  EXPECT_NEAR(s.latlon_box.north_deg, kLat, 1e-4);
  const std::string garbage = et::readSourceTile(dir.file("tile_0002.tif"), &s);
  EXPECT_NE(garbage.find("GDAL cannot open"), std::string::npos) << garbage;
  const std::string in_local = et::readSourceTile(dir.file("tile_0003.tif"), &s);
  EXPECT_NE(in_local.find("local frame"), std::string::npos) << in_local;
}
