// UtmGrid: one UTM zone (or UPS) for a whole dive, checked against GeographicLib's own projections.
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include <GeographicLib/PolarStereographic.hpp>
#include <GeographicLib/TransverseMercator.hpp>
#include <GeographicLib/UTMUPS.hpp>
#include <gtest/gtest.h>

#include "exocet_common/utm_grid.h"

using exocet_common::UtmGrid;

namespace {

/// UTM by hand from GeographicLib's transverse Mercator (central meridian 6 zone - 183, k0 0.9996, false easting
/// 500 km, false northing 10 000 km in the south): independent of UTMUPS' zone logic.
Eigen::Vector2d utmByHand(int zone, bool northern, double lat, double lon) {
  double x = 0, y = 0;
  GeographicLib::TransverseMercator::UTM().Forward(6.0 * zone - 183.0, lat, lon, x, y);
  return {x + 500000.0, y + (northern ? 0.0 : 10000000.0)};
}

/// Distance (m) between two latitude/longitude points a few mm apart (local flat approximation).
double groundDistance_m(const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  const double m_per_deg = 111320.0;
  return std::hypot((a.x() - b.x()) * m_per_deg, (a.y() - b.y()) * m_per_deg * std::cos(a.x() * M_PI / 180.0));
}

std::string messageOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST(UtmGrid, StandardZoneAndNames) {
  const UtmGrid g = UtmGrid::forLatLon(43.0712, 5.8790);  // off La Seyne-sur-Mer
  EXPECT_EQ(g.zone(), 31);
  EXPECT_TRUE(g.northern());
  EXPECT_EQ(g.epsg(), 32631);
  EXPECT_EQ(g.name(), "31N");
  const UtmGrid east = UtmGrid::forLatLon(43.0712, 6.05);
  EXPECT_EQ(east.zone(), 32);
  EXPECT_EQ(east.epsg(), 32632);
  // Norway's exception (32V) comes from GeographicLib's standard zone rules.
  EXPECT_EQ(UtmGrid::forLatLon(60.0, 5.0).zone(), 32);
}

TEST(UtmGrid, PointEastOfTheBorderInTheWesternZone) {
  const UtmGrid grid = UtmGrid::fromZone(31, true);
  const double lat = 43.5, lon = 6.35;  // 0.35 deg into zone 32
  const Eigen::Vector2d en = grid.toGrid(lat, lon);
  // GeographicLib's own result for the forced zone.
  int zone = 0;
  bool north = true;
  double x = 0, y = 0;
  GeographicLib::UTMUPS::Forward(lat, lon, zone, north, x, y, 31);
  EXPECT_EQ(zone, 31);
  EXPECT_NEAR(en.x(), x, 1e-6);
  EXPECT_NEAR(en.y(), y, 1e-6);
  // And the transverse Mercator by hand on zone 31's central meridian (3 E).
  const Eigen::Vector2d by_hand = utmByHand(31, true, lat, lon);
  EXPECT_NEAR(en.x(), by_hand.x(), 1e-3);
  EXPECT_NEAR(en.y(), by_hand.y(), 1e-3);
  EXPECT_GT(en.x(), 760000.0);  // past the zone's usual eastern edge: extended, not re-zoned
  // Its own zone gives a different easting: the dive keeps one frame.
  EXPECT_GT(std::abs(UtmGrid::forLatLon(lat, lon).toGrid(lat, lon).x() - en.x()), 100000.0);
  // Round trip below 1 mm.
  const Eigen::Vector2d back = grid.toLatLon(en.x(), en.y());
  EXPECT_LT(groundDistance_m(back, Eigen::Vector2d(lat, lon)), 1e-3);
  EXPECT_NEAR(back.y(), lon, 1e-9);
  // Convergence: GeographicLib's gamma; east of the central meridian in the north it is positive.
  double lat2 = 0, lon2 = 0, gamma = 0, k = 0;
  GeographicLib::UTMUPS::Reverse(31, true, en.x(), en.y(), lat2, lon2, gamma, k);
  EXPECT_NEAR(grid.convergence_rad(en.x(), en.y()), gamma * M_PI / 180.0, 1e-12);
  EXPECT_GT(gamma, 2.0);
  EXPECT_NEAR(grid.scaleFactor(en.x(), en.y()), k, 1e-12);
  EXPECT_NEAR(grid.convergence_rad(500000.0, en.y()), 0.0, 1e-12);
}

TEST(UtmGrid, SouthernHemisphereWithFalseNorthing) {
  const double lat = -33.92, lon = 18.42;  // Cape Town
  const UtmGrid grid = UtmGrid::forLatLon(lat, lon);
  EXPECT_EQ(grid.zone(), 34);
  EXPECT_FALSE(grid.northern());
  EXPECT_EQ(grid.epsg(), 32734);
  EXPECT_EQ(grid.name(), "34S");
  const Eigen::Vector2d en = grid.toGrid(lat, lon);
  const Eigen::Vector2d by_hand = utmByHand(34, false, lat, lon);
  EXPECT_NEAR(en.x(), by_hand.x(), 1e-3);
  EXPECT_NEAR(en.y(), by_hand.y(), 1e-3);
  EXPECT_GT(en.y(), 6.0e6);  // 10 000 km false northing minus ~3 750 km
  EXPECT_LT(en.y(), 6.5e6);
  EXPECT_LT(groundDistance_m(grid.toLatLon(en.x(), en.y()), Eigen::Vector2d(lat, lon)), 1e-3);
  // A point just north of the equator in this southern grid: northing continued above 10 000 km.
  const Eigen::Vector2d north_of_equator = grid.toGrid(0.05, 21.0);
  EXPECT_GT(north_of_equator.y(), 10000000.0);
  EXPECT_LT(groundDistance_m(grid.toLatLon(north_of_equator.x(), north_of_equator.y()), Eigen::Vector2d(0.05, 21.0)),
            1e-3);
}

TEST(UtmGrid, NorthernGridContinuedSouthOfTheEquator) {
  const UtmGrid grid = UtmGrid::forLatLon(0.05, 9.0);
  ASSERT_TRUE(grid.northern());
  const Eigen::Vector2d en = grid.toGrid(-0.05, 9.0);
  EXPECT_NEAR(en.y(), -5528.0, 5.0);  // 0.05 deg of latitude south of the equator
  EXPECT_LT(groundDistance_m(grid.toLatLon(en.x(), en.y()), Eigen::Vector2d(-0.05, 9.0)), 1e-3);
}

TEST(UtmGrid, UpsNearThePoles) {
  const UtmGrid north = UtmGrid::forLatLon(85.0, 30.0);
  EXPECT_EQ(north.zone(), 0);
  EXPECT_TRUE(north.isUps());
  EXPECT_EQ(north.epsg(), 32661);
  EXPECT_EQ(north.name(), "UPS N");
  const Eigen::Vector2d en = north.toGrid(85.0, 30.0);
  double x = 0, y = 0, gamma = 0, k = 0;
  GeographicLib::PolarStereographic::UPS().Forward(true, 85.0, 30.0, x, y, gamma, k);
  EXPECT_NEAR(en.x(), x + 2000000.0, 1e-3);
  EXPECT_NEAR(en.y(), y + 2000000.0, 1e-3);
  EXPECT_LT(groundDistance_m(north.toLatLon(en.x(), en.y()), Eigen::Vector2d(85.0, 30.0)), 1e-3);

  const UtmGrid south = UtmGrid::forLatLon(-82.0, -60.0);
  EXPECT_EQ(south.zone(), 0);
  EXPECT_EQ(south.epsg(), 32761);
  EXPECT_EQ(south.name(), "UPS S");
  const Eigen::Vector2d s = south.toGrid(-82.0, -60.0);
  EXPECT_LT(groundDistance_m(south.toLatLon(s.x(), s.y()), Eigen::Vector2d(-82.0, -60.0)), 1e-3);
  // The other pole's hemisphere cannot be expressed in a UPS grid.
  EXPECT_NE(messageOf([&] { north.toGrid(-10.0, 0.0); }).find("latitude"), std::string::npos);
}

TEST(UtmGrid, RejectsInvalidInputWithAMessage) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  EXPECT_NE(messageOf([&] { UtmGrid::forLatLon(nan, 5.0); }).find("latitude"), std::string::npos);
  EXPECT_NE(messageOf([&] { UtmGrid::forLatLon(91.0, 5.0); }).find("latitude"), std::string::npos);
  EXPECT_NE(messageOf([&] { UtmGrid::forLatLon(-90.5, 5.0); }).find("latitude"), std::string::npos);
  EXPECT_NE(messageOf([&] { UtmGrid::forLatLon(43.0, nan); }).find("longitude"), std::string::npos);
  EXPECT_NE(messageOf([&] { UtmGrid::forLatLon(43.0, 400.0); }).find("longitude"), std::string::npos);
  EXPECT_NE(messageOf([&] { UtmGrid::forLatLon(43.0, -181.0); }).find("longitude"), std::string::npos);
  const UtmGrid grid = UtmGrid::fromZone(31, true);
  EXPECT_NE(messageOf([&] { grid.toGrid(nan, 5.0); }).find("latitude"), std::string::npos);
  EXPECT_NE(messageOf([&] { grid.toGrid(43.0, std::numeric_limits<double>::infinity()); }).find("longitude"),
            std::string::npos);
  EXPECT_NE(messageOf([&] { grid.toLatLon(nan, 4.7e6); }).find("easting"), std::string::npos);
  EXPECT_NE(messageOf([&] { grid.toLatLon(5.0e6, 4.7e6); }).find("easting"), std::string::npos);  // out of limits
  EXPECT_NE(messageOf([&] { UtmGrid::fromZone(61, true); }).find("zone"), std::string::npos);
  EXPECT_NE(messageOf([&] { UtmGrid::fromZone(-1, false); }).find("zone"), std::string::npos);
  // A point far outside the zone (beyond GeographicLib's extended limits) is refused, not silently wrapped.
  EXPECT_NE(messageOf([&] { grid.toGrid(43.0, 60.0); }).find("cannot be expressed"), std::string::npos);
}
