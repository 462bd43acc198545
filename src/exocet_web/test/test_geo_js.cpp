// The page's geodesy (site/geo.js: the UTM read-out under the cursor, the distance measure) run in a headless
// Chromium and checked against GeographicLib (exocet_common::UtmGrid, GeographicLib::Geodesic).
#include <cstdio>
#include <fstream>
#include <iomanip>
#include <memory>
#include <regex>
#include <sstream>
#include <vector>

#include <gtest/gtest.h>
#include <GeographicLib/Geodesic.hpp>
#include <nlohmann/json.hpp>

#include "exocet_common/testing/temp_dir.h"
#include "exocet_common/utm_grid.h"
#include "exocet_web/site/site_assets.h"

using exocet_common::testing::TempDir;

namespace {

struct Point {
  double lat, lon;
  int zone;  // the zone to project in (a point may be outside it, as a dive crossing a border)
  bool northern;
};

/// Runs `script` after geo.js in a headless Chromium; returns what it put in document.body (dumped DOM).
std::string runInChromium(const TempDir& dir, const std::string& script) {
  std::ofstream(dir.file("geo.js")) << exocet_web::site::pageAssets().at("geo.js");
  std::ofstream(dir.file("test.html")) << "<!DOCTYPE html><html><body><script src=\"geo.js\"></script><script>"
                                       << script << "</script></body></html>";
  const std::string command = "chromium --headless --no-sandbox --disable-gpu --user-data-dir=" + dir.file("profile") +
                              " --dump-dom file://" + dir.file("test.html") + " 2>/dev/null";
  std::unique_ptr<FILE, decltype(&pclose)> pipe(popen(command.c_str(), "r"), &pclose);
  if (!pipe) return "";
  std::string out;
  char buffer[4096];
  while (size_t n = fread(buffer, 1, sizeof(buffer), pipe.get())) out.append(buffer, n);
  return out;
}

}  // namespace

TEST(GeoJs, UtmAgreesWithGeographicLib) {
  std::vector<Point> points;
  for (double lat : {-79.5, -60.0, -33.9, -0.5, 0.5, 12.3, 43.0712, 60.0, 83.5})
    for (double offset_deg : {-2.99, -1.0, 0.0, 0.3, 2.5}) {
      const int zone = 31;
      const double lon = 3.0 + offset_deg;  // zone 31's central meridian is 3 E
      points.push_back({lat, lon, zone, lat >= 0});
    }
  points.push_back({43.0712, 5.879, 31, true});  // the sample dive
  points.push_back({43.0712, 7.0, 31, true});    // 1 deg past the zone's eastern border, extended
  points.push_back({-45.0, -170.5, 2, false});
  points.push_back({10.0, 179.9, 60, true});
  std::ostringstream list;
  list << "[";
  for (size_t i = 0; i < points.size(); ++i)
    list << (i ? "," : "") << "[" << std::setprecision(17) << points[i].lat << "," << points[i].lon << ","
         << points[i].zone << "," << (points[i].northern ? "true" : "false") << "]";
  list << "]";
  TempDir dir;
  const std::string dom = runInChromium(
      dir, "const out = " + list.str() +
               ".map(p => { const u = ExocetGeo.toUtm(p[0], p[1], p[2], p[3]); "
               "return [u.easting, u.northing, u.k, u.gammaDeg, u.zone]; });"
               "document.body.textContent = 'RESULT' + JSON.stringify(out) + 'END';"
               "const d = [ExocetGeo.distance(43.0712, 5.879, 43.0713, 5.8791), "
               "ExocetGeo.distance(43.0712, 5.879, 43.08, 5.87), ExocetGeo.distance(-33.9, 18.4, -33.9, 18.41), "
               "ExocetGeo.utmZone(5.879), ExocetGeo.utmZone(-0.1), ExocetGeo.utmZone(179.99), "
               "ExocetGeo.utmZone(-180)];"
               "document.body.textContent += 'DIST' + JSON.stringify(d) + 'END';");
  std::smatch m;
  ASSERT_TRUE(std::regex_search(dom, m, std::regex("RESULT(.*?)END"))) << "no output from Chromium:\n" << dom;
  const nlohmann::json results = nlohmann::json::parse(m[1].str());
  ASSERT_EQ(results.size(), points.size());
  for (size_t i = 0; i < points.size(); ++i) {
    const Point& p = points[i];
    const auto grid = exocet_common::UtmGrid::fromZone(p.zone, p.northern);
    const Eigen::Vector2d en = grid.toGrid(p.lat, p.lon);
    const auto& r = results[i];
    SCOPED_TRACE("lat " + std::to_string(p.lat) + " lon " + std::to_string(p.lon) + " zone " + std::to_string(p.zone));
    EXPECT_NEAR(r[0].get<double>(), en.x(), 1e-4);  // 0.1 mm
    EXPECT_NEAR(r[1].get<double>(), en.y(), 1e-4);
    EXPECT_NEAR(r[2].get<double>(), grid.scaleFactor(en.x(), en.y()), 1e-9);
    EXPECT_NEAR(r[3].get<double>(), grid.convergence_rad(en.x(), en.y()) * 180.0 / M_PI, 1e-7);
    EXPECT_EQ(r[4].get<int>(), p.zone);
  }

  ASSERT_TRUE(std::regex_search(dom, m, std::regex("DIST(.*?)END")));
  const nlohmann::json d = nlohmann::json::parse(m[1].str());
  const auto& geodesic = GeographicLib::Geodesic::WGS84();
  double s12 = 0;
  geodesic.Inverse(43.0712, 5.879, 43.0713, 5.8791, s12);
  EXPECT_NEAR(d[0].get<double>(), s12, 1e-4);  // 14 m: 0.1 mm
  geodesic.Inverse(43.0712, 5.879, 43.08, 5.87, s12);
  EXPECT_NEAR(d[1].get<double>(), s12, 1e-3);  // 1.2 km: 1 mm
  geodesic.Inverse(-33.9, 18.4, -33.9, 18.41, s12);
  EXPECT_NEAR(d[2].get<double>(), s12, 1e-3);
  EXPECT_EQ(d[3].get<int>(), 31);
  EXPECT_EQ(d[4].get<int>(), 30);
  EXPECT_EQ(d[5].get<int>(), 60);
  EXPECT_EQ(d[6].get<int>(), 1);
}
