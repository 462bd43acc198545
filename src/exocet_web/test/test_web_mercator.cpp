// The XYZ tile grid: tile bounds, tiles covering a box, parents, the zoom level chosen from a gsd.
#include <cmath>

#include <gtest/gtest.h>

#include "exocet_web/tiles/web_mercator.h"

namespace et = exocet_web::tiles;

TEST(WebMercator, LevelZeroIsTheWholeSquare) {
  const et::MercatorBox b = et::tileBounds({0, 0, 0});
  EXPECT_DOUBLE_EQ(b.min_x_m, -et::kMercatorHalfSide_m);
  EXPECT_DOUBLE_EQ(b.max_x_m, et::kMercatorHalfSide_m);
  EXPECT_DOUBLE_EQ(b.min_y_m, -et::kMercatorHalfSide_m);
  EXPECT_DOUBLE_EQ(b.max_y_m, et::kMercatorHalfSide_m);
  const et::LatLonBox ll = et::tileLatLonBounds({0, 0, 0});
  EXPECT_NEAR(ll.north_deg, et::kMercatorMaxLatitude_deg, 1e-9);
  EXPECT_NEAR(ll.west_deg, -180.0, 1e-9);
}

TEST(WebMercator, KnownTileOfAKnownPlace) {
  // OpenStreetMap's tile of the dive's site (43.0712 N, 5.8790 E) at level 18: x = floor((lon + 180) / 360 * 2^z),
  // y = floor((1 - asinh(tan(lat)) / pi) / 2 * 2^z).
  const double lat = 43.0712, lon = 5.8790;
  const int z = 18;
  const double n = std::ldexp(1.0, z);
  const int x = int(std::floor((lon + 180.0) / 360.0 * n));
  const int y = int(std::floor((1.0 - std::asinh(std::tan(lat * M_PI / 180.0)) / M_PI) / 2.0 * n));
  const et::MercatorBox point{et::mercatorX_m(lon), et::mercatorY_m(lat), et::mercatorX_m(lon) + 1e-3,
                              et::mercatorY_m(lat) + 1e-3};
  const et::TileRange r = et::tilesCovering(point, z);
  EXPECT_EQ(r.min_x, x);
  EXPECT_EQ(r.max_x, x);
  EXPECT_EQ(r.min_y, y);
  EXPECT_EQ(r.max_y, y);
  const et::LatLonBox ll = et::tileLatLonBounds({z, x, y});
  EXPECT_LE(ll.west_deg, lon);
  EXPECT_GE(ll.east_deg, lon);
  EXPECT_LE(ll.south_deg, lat);
  EXPECT_GE(ll.north_deg, lat);
  EXPECT_NEAR(et::latitudeFromMercatorY_deg(et::mercatorY_m(lat)), lat, 1e-12);
  EXPECT_NEAR(et::longitudeFromMercatorX_deg(et::mercatorX_m(lon)), lon, 1e-12);
}

TEST(WebMercator, CoveringExcludesTilesOnlyTouched) {
  const et::MercatorBox t = et::tileBounds({10, 500, 300});
  et::TileRange r = et::tilesCovering(t, 10);  // exactly one tile: its neighbours only share an edge
  EXPECT_EQ(r.count(), 1);
  EXPECT_EQ(r.min_x, 500);
  EXPECT_EQ(r.min_y, 300);
  r = et::tilesCovering(t, 11);  // its four children
  EXPECT_EQ(r.count(), 4);
  EXPECT_EQ(r.min_x, 1000);
  EXPECT_EQ(r.max_y, 601);
  et::MercatorBox wider = t;
  wider.max_x_m += 1.0;  // one metre into the eastern neighbour
  EXPECT_EQ(et::tilesCovering(wider, 10).count(), 2);
  EXPECT_EQ(et::tilesCovering(et::MercatorBox{}, 10).count(), 0);
}

TEST(WebMercator, ParentsAndResolution) {
  EXPECT_EQ(et::parentOf({5, 13, 6}), (et::TileId{4, 6, 3}));
  EXPECT_EQ(et::parentOf({0, 0, 0}), (et::TileId{0, 0, 0}));
  EXPECT_NEAR(et::resolution_m_per_px(0), 156543.03392804097, 1e-6);
  EXPECT_NEAR(et::resolution_m_per_px(1), et::resolution_m_per_px(0) / 2.0, 1e-9);
  EXPECT_NEAR(et::groundResolution_m_per_px(0, 60.0), et::resolution_m_per_px(0) / 2.0, 1e-6);
  EXPECT_THROW(et::resolution_m_per_px(31), std::invalid_argument);
}

TEST(WebMercator, NativeZoomIsTheLevelNearestTheGsd) {
  // At 43 N the level-z pixel is 114 491 m / 2^z on the ground: 3.4 mm at 25, 6.8 mm at 24.
  const double lat = 43.0712;
  EXPECT_EQ(et::nativeZoom(0.0032, lat), 25);
  EXPECT_EQ(et::nativeZoom(0.0068, lat), 24);
  for (int z = 5; z <= 28; ++z) {
    const double pixel_m = et::groundResolution_m_per_px(z, lat);
    EXPECT_EQ(et::nativeZoom(pixel_m, lat), z);
    EXPECT_EQ(et::nativeZoom(pixel_m * 1.4, lat), z);  // within sqrt(2): still z
    EXPECT_EQ(et::nativeZoom(pixel_m * 1.42, lat), z - 1);
    EXPECT_EQ(et::nativeZoom(pixel_m / 1.42, lat), z + 1);
  }
  EXPECT_THROW(et::nativeZoom(0.0, lat), std::invalid_argument);
  EXPECT_THROW(et::nativeZoom(0.01, 90.0), std::invalid_argument);
}

TEST(WebMercator, ZoomFittingABox) {
  const et::MercatorBox tile = et::tileBounds({18, 1000, 1000});
  EXPECT_EQ(et::zoomFittingBox(tile, 25), 18);
  et::MercatorBox bigger = tile;
  bigger.max_x_m += 1.0;
  EXPECT_EQ(et::zoomFittingBox(bigger, 25), 17);
  EXPECT_EQ(et::zoomFittingBox(tile, 12), 12);  // never above max_zoom
}
