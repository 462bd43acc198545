// GeoReference: the zone, EPSG code and origin of a dive, and its conversions (those of its UtmGrid).
#include <cmath>
#include <stdexcept>

#include <gtest/gtest.h>

#include "exocet_common/geo_reference.h"

TEST(GeoReference, ZoneEpsgAndOriginOfTheOrigin) {
  const exocet_common::GeoReference toulon = exocet_common::makeGeoReference(43.0, 5.9);
  EXPECT_EQ(toulon.utm_zone, 31);
  EXPECT_TRUE(toulon.northern_hemisphere);
  EXPECT_EQ(toulon.epsg, 32631);
  const Eigen::Vector2d back = exocet_common::gridToLatLon(toulon, toulon.origin_easting_m, toulon.origin_northing_m);
  EXPECT_NEAR(back.x(), 43.0, 1e-9);
  EXPECT_NEAR(back.y(), 5.9, 1e-9);

  const exocet_common::GeoReference south = exocet_common::makeGeoReference(-33.9, 151.3);
  EXPECT_EQ(south.utm_zone, 56);
  EXPECT_FALSE(south.northern_hemisphere);
  EXPECT_EQ(south.epsg, 32756);
  EXPECT_EQ(exocet_common::makeGeoReference(85.0, 10.0).epsg, 32661) << "UPS north";
}

TEST(GeoReference, ConversionsRoundTripAndConvergenceHasTheGridSign) {
  const exocet_common::GeoReference ref = exocet_common::makeGeoReference(43.0, 5.9);
  const Eigen::Vector2d en = exocet_common::latLonToGrid(ref, 43.01, 5.91);
  EXPECT_NEAR((en - Eigen::Vector2d(ref.origin_easting_m, ref.origin_northing_m)).norm(), 1377.0, 20.0);
  const Eigen::Vector2d ll = exocet_common::gridToLatLon(ref, en.x(), en.y());
  EXPECT_NEAR(ll.x(), 43.01, 1e-9);
  EXPECT_NEAR(ll.y(), 5.91, 1e-9);
  // East of the central meridian (3 deg E) grid north points east of true north: positive convergence.
  EXPECT_GT(exocet_common::gridConvergence_rad(ref, en.x(), en.y()), 0.0);
}

TEST(GeoReference, RefusesAnOriginOutOfRangeNamingIt) {
  try {
    exocet_common::makeGeoReference(95.0, 5.0);
    FAIL() << "latitude 95 accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("latitude"), std::string::npos) << e.what();
  }
  EXPECT_THROW(exocet_common::makeGeoReference(43.0, std::nan("")), std::invalid_argument);
}
