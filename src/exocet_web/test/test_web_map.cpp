// The web map's site folder: the page and state files written, the events announced, a restart that cuts only what
// changed, a GeoTIFF that cannot be read counted and skipped, the exports at shutdown, the GeoTIFFs found in the tiles
// folder without a message (a restarted node's missed ones) and those left out at start staying out.
#include <chrono>
#include <filesystem>
#include <fstream>
#include <iterator>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "exocet_common/testing/temp_dir.h"
#include "exocet_common/utm_grid.h"
#include "exocet_web/site/web_map.h"
#include "synthetic_geotiff.h"

namespace ew = exocet_web;
using exocet_common::testing::TempDir;

namespace {

constexpr double kLat = 43.0712, kLon = 5.8790;

ew::testing::SyntheticTile tileAt(double east_m) {
  const Eigen::Vector2d origin = exocet_common::UtmGrid::fromZone(31, true).toGrid(kLat, kLon);
  ew::testing::SyntheticTile t;
  t.origin_easting_m = origin.x() + east_m;
  t.origin_northing_m = origin.y();
  t.gsd_m = 0.005;
  t.width_px = 300;
  t.height_px = 200;
  return t;
}

std::string readText(const std::string& path) {
  std::ifstream in(path);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

ew::site::WebMapConfig configFor(const TempDir& dir) {
  ew::site::WebMapConfig c;
  c.tiles_dir = dir.file("tiles");
  c.site_dir = dir.file("site");
  c.dive_name = "test dive";
  c.state_period_s = 0.1;
  c.vehicle_event_period_s = 0.0;
  c.worker_nice = 0;
  c.cutter.max_zoom = 23;
  c.gpkg_path = dir.file("site/mosaic.gpkg");
  return c;
}

/// Every event published so far, by type.
std::map<std::string, std::vector<nlohmann::json>> eventsOf(ew::server::EventStream& events) {
  bool gap = false;
  std::map<std::string, std::vector<nlohmann::json>> by_type;
  for (const auto& e : events.waitAfter(0, std::chrono::milliseconds(0), &gap))
    by_type[e.type].push_back(nlohmann::json::parse(e.data));
  return by_type;
}

constexpr auto kPatience = std::chrono::seconds(120);  // a slow machine only waits longer

}  // namespace

TEST(WebMap, BuildsTheSiteAnnouncesTilesAndRestartsWithoutCuttingAgain) {
  TempDir dir;
  std::filesystem::create_directories(dir.file("tiles"));
  ASSERT_TRUE(ew::testing::writeSyntheticGeoTiff(dir.file("tiles/tile_0000.tif"), tileAt(0.0)));
  std::ofstream(dir.file("tiles/fused_track.csv")) << "stamp_s,easting_m,northing_m\n";
  size_t web_tiles = 0;
  {
    ew::site::WebMap map(configFor(dir));
    map.start();
    ASSERT_TRUE(map.waitIdle(kPatience));
    for (const char* name : {"index.html", "web_map.js", "geo.js", "web_map.css", "leaflet/leaflet.js",
                             "leaflet/leaflet.css", "state.json", "state.js", "tiles.json", "track.json"})
      EXPECT_TRUE(std::filesystem::exists(dir.file("site/") + name)) << name;
    auto events = eventsOf(map.events());
    ASSERT_EQ(events["tile"].size(), 1u);
    EXPECT_EQ(events["tile"][0]["key"], "tile_0000");
    EXPECT_EQ(events["tile"][0]["metadata"]["frames_composed"], 42);
    // The finest level announced first, then the coarser levels built from it.
    ASSERT_EQ(events["webtiles"].size(), 2u);
    EXPECT_EQ(events["webtiles"][0]["levels"], "finest");
    EXPECT_FALSE(events["webtiles"][0]["written"].empty());
    EXPECT_EQ(events["webtiles"][0]["zoom"]["max"], 23);
    for (const auto& t : events["webtiles"][0]["written"]) EXPECT_EQ(t[0], 23);
    EXPECT_EQ(events["webtiles"][1]["levels"], "coarser");  // none here: the one tile fits in a web tile of z 23
    for (const auto& t : events["webtiles"][1]["written"]) EXPECT_LT(t[0], 23);

    // A tile written during the dive, and the vehicle moving.
    ASSERT_TRUE(ew::testing::writeSyntheticGeoTiff(dir.file("tiles/tile_0001.tif"), tileAt(1.0)));
    map.enqueueGeoTiff(dir.file("tiles/tile_0001.tif"));
    ASSERT_TRUE(map.waitIdle(kPatience));
    for (int i = 0; i < 20; ++i) map.addVehiclePose(1000.0 + i, kLat + i * 1e-6, kLon, 75.0);
    map.addUsblFix(1001.0, kLat, kLon, 0.5);
    map.setDatum(31, true, 32631);
    map.flushVehicleEvents();
    events = eventsOf(map.events());
    ASSERT_EQ(events["tile"].size(), 2u);
    EXPECT_EQ(events["tile"][1]["key"], "tile_0001");
    ASSERT_EQ(events["webtiles"].size(), 4u);
    for (const int e : {2, 3})
      for (const auto& t : events["webtiles"][e]["written"]) {
        const std::string path = dir.file("site/tiles/") + std::to_string(int(t[0])) + "/" + std::to_string(int(t[1])) +
                                 "/" + std::to_string(int(t[2])) + ".png";
        EXPECT_TRUE(std::filesystem::exists(path)) << path;
      }
    size_t points = 0;
    for (const auto& e : events["track"]) points += e["points"].size();
    EXPECT_EQ(points, 20u);  // 0.11 m apart: none thinned at 0.1 m
    EXPECT_EQ(events["track"].back()["vehicle"]["heading_deg"], 75.0);
    EXPECT_EQ(events["usbl"].size(), 1u);
    EXPECT_EQ(events["datum"].size(), 1u);

    const nlohmann::json state = nlohmann::json::parse(map.snapshotJson());
    EXPECT_EQ(state["tiles"].size(), 2u);
    EXPECT_EQ(state["track"].size(), 20u);
    EXPECT_EQ(state["web_tiles"]["z"], 23);
    EXPECT_FALSE(state["web_tiles"]["xy"].empty());
    EXPECT_EQ(state["event_id"], map.events().idText(map.events().lastId()));
    EXPECT_EQ(state["datum"]["utm_zone"], 31);
    web_tiles = map.stats().web_tiles;
    EXPECT_EQ(map.stats().geotiffs_cut, 2u);
    EXPECT_EQ(map.shutdown(), "");
    EXPECT_TRUE(std::filesystem::exists(dir.file("site/mosaic.gpkg")));
    // The files hold the final state; state.js is the same for a page opened from disk.
    const nlohmann::json saved = nlohmann::json::parse(readText(dir.file("site/state.json")));
    EXPECT_EQ(saved["tiles"].size(), 2u);
    EXPECT_EQ(saved["track"].size(), 20u);
    const std::string script = readText(dir.file("site/state.js"));
    const size_t start = script.find("window.EXOCET_STATE = ");
    ASSERT_NE(start, std::string::npos);
    EXPECT_EQ(nlohmann::json::parse(script.substr(start + 22, script.rfind(';') - start - 22)), saved);
  }
  {
    // A restart: nothing changed, nothing is cut; the track comes back.
    ew::site::WebMap map(configFor(dir));
    map.start();
    ASSERT_TRUE(map.waitIdle(kPatience));
    EXPECT_EQ(map.stats().geotiffs_cut, 0u);
    EXPECT_EQ(size_t(map.stats().web_tiles), web_tiles);
    EXPECT_EQ(map.stats().track_points, 20u);
    EXPECT_EQ(nlohmann::json::parse(map.snapshotJson())["tiles"].size(), 2u);
    map.shutdown();
  }
  {
    // Tile 1 drawn again while the node was down: only it is cut.
    ASSERT_TRUE(ew::testing::writeSyntheticGeoTiff(dir.file("tiles/tile_0001_v2.tif"), tileAt(1.5)));
    std::filesystem::remove(dir.file("tiles/tile_0001.tif"));
    ew::site::WebMap map(configFor(dir));
    map.start();
    ASSERT_TRUE(map.waitIdle(kPatience));
    EXPECT_EQ(map.stats().geotiffs_cut, 1u);
    const nlohmann::json state = nlohmann::json::parse(map.snapshotJson());
    ASSERT_EQ(state["tiles"].size(), 2u);
    EXPECT_EQ(state["tiles"][1]["version"], 2);
    map.shutdown();
  }
}

TEST(WebMap, AGeoTiffThatCannotBeReadIsCountedAndTheMapGoesOn) {
  TempDir dir;
  std::filesystem::create_directories(dir.file("tiles"));
  std::ofstream(dir.file("tiles/tile_0003.tif")) << "truncated";
  std::vector<std::string> warnings;
  ew::site::WebMap map(configFor(dir), [&](ew::site::WebMap::Severity s, const std::string&, const std::string& m) {
    if (s == ew::site::WebMap::Severity::kWarning) warnings.push_back(m);
  });
  map.start();
  ASSERT_TRUE(map.waitIdle(kPatience));
  EXPECT_EQ(map.stats().errors, 1u);
  EXPECT_NE(map.stats().last_error.find("tile_0003.tif"), std::string::npos) << map.stats().last_error;
  ASSERT_EQ(warnings.size(), 1u);
  ASSERT_TRUE(ew::testing::writeSyntheticGeoTiff(dir.file("tiles/tile_0004.tif"), tileAt(0.0)));
  map.enqueueGeoTiff(dir.file("tiles/tile_0004.tif"));
  map.enqueueGeoTiff(dir.file("tiles/no_such_tile_0009.tif"));  // gone before it was cut: skipped, not an error
  ASSERT_TRUE(map.waitIdle(kPatience));
  EXPECT_EQ(map.stats().geotiffs_cut, 1u);
  EXPECT_EQ(map.stats().errors, 1u);
  EXPECT_GT(map.stats().web_tiles, 0);
  map.shutdown();
}

TEST(WebMap, FindsTheGeoTiffsWrittenWithoutAMessage) {
  TempDir dir;
  std::filesystem::create_directories(dir.file("tiles"));
  ASSERT_TRUE(ew::testing::writeSyntheticGeoTiff(dir.file("tiles/tile_0000.tif"), tileAt(0.0)));
  ew::site::WebMap map(configFor(dir));
  EXPECT_EQ(map.queueUnseenGeoTiffs(), 0);  // not started: nothing
  map.start();
  ASSERT_TRUE(map.waitIdle(kPatience));
  EXPECT_EQ(map.queueUnseenGeoTiffs(), 0);  // cut at start already

  // Written while the node was down or not yet subscribed: no message. Just written, its message may be on the way.
  ASSERT_TRUE(ew::testing::writeSyntheticGeoTiff(dir.file("tiles/tile_0001.tif"), tileAt(1.0)));
  EXPECT_EQ(map.queueUnseenGeoTiffs(std::chrono::seconds(600)), 0);
  EXPECT_EQ(map.queueUnseenGeoTiffs(), 1);
  ASSERT_TRUE(map.waitIdle(kPatience));
  EXPECT_EQ(map.queueUnseenGeoTiffs(), 0);
  // With its message: not queued a second time by a look at the folder.
  ASSERT_TRUE(ew::testing::writeSyntheticGeoTiff(dir.file("tiles/tile_0002.tif"), tileAt(2.0)));
  map.enqueueGeoTiff(dir.file("tiles/tile_0002.tif"));
  EXPECT_EQ(map.queueUnseenGeoTiffs(), 0);
  ASSERT_TRUE(map.waitIdle(kPatience));
  // A tile drawn again without its message: the new version.
  ASSERT_TRUE(ew::testing::writeSyntheticGeoTiff(dir.file("tiles/tile_0001_v2.tif"), tileAt(1.5)));
  std::filesystem::remove(dir.file("tiles/tile_0001.tif"));
  EXPECT_EQ(map.queueUnseenGeoTiffs(), 1);
  ASSERT_TRUE(map.waitIdle(kPatience));
  // One that cannot be read: one error, not one per look.
  std::ofstream(dir.file("tiles/tile_0003.tif")) << "truncated";
  EXPECT_EQ(map.queueUnseenGeoTiffs(), 1);
  ASSERT_TRUE(map.waitIdle(kPatience));
  EXPECT_EQ(map.queueUnseenGeoTiffs(), 0);
  EXPECT_EQ(map.stats().errors, 1u);

  EXPECT_EQ(map.stats().geotiffs_cut, 4u);
  const nlohmann::json state = nlohmann::json::parse(map.snapshotJson());
  ASSERT_EQ(state["tiles"].size(), 3u);
  EXPECT_EQ(state["tiles"][1]["key"], "tile_0001");
  EXPECT_EQ(state["tiles"][1]["version"], 2);
  map.shutdown();
  ASSERT_TRUE(ew::testing::writeSyntheticGeoTiff(dir.file("tiles/tile_0004.tif"), tileAt(3.0)));
  EXPECT_EQ(map.queueUnseenGeoTiffs(), 0);  // shut down: nothing
}

TEST(WebMap, TheGeoTiffsLeftOutAtStartStayOut) {
  TempDir dir;
  std::filesystem::create_directories(dir.file("tiles"));
  ASSERT_TRUE(ew::testing::writeSyntheticGeoTiff(dir.file("tiles/tile_0000.tif"), tileAt(0.0)));
  ew::site::WebMapConfig config = configFor(dir);
  config.load_existing = false;
  ew::site::WebMap map(config);
  map.start();
  EXPECT_EQ(map.queueUnseenGeoTiffs(), 0);
  ASSERT_TRUE(ew::testing::writeSyntheticGeoTiff(dir.file("tiles/tile_0001.tif"), tileAt(1.0)));
  EXPECT_EQ(map.queueUnseenGeoTiffs(), 1);
  ASSERT_TRUE(map.waitIdle(kPatience));
  const nlohmann::json state = nlohmann::json::parse(map.snapshotJson());
  ASSERT_EQ(state["tiles"].size(), 1u);
  EXPECT_EQ(state["tiles"][0]["key"], "tile_0001");
  map.shutdown();
}
