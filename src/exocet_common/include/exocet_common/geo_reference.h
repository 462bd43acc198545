/**
 * @file geo_reference.h
 * @brief The geodetic reference of a dive's metric world frame: its UTM zone (or UPS pole), EPSG code and origin,
 * with WGS 84 <-> grid conversions done by UtmGrid.
 */
#pragma once

#include <Eigen/Core>

#include "exocet_common/utm_grid.h"

namespace exocet_common {

/// Geodetic reference of a dive's world frame (UTM easting, northing, up).
struct GeoReference {
  int utm_zone = 31;  ///< 1..60, or 0 for UPS
  bool northern_hemisphere = true;
  int epsg = 32631;
  double origin_latitude_deg = 0.0;
  double origin_longitude_deg = 0.0;
  double origin_easting_m = 0.0;
  double origin_northing_m = 0.0;

  /// The grid of the reference. @throws std::invalid_argument if utm_zone is outside 0..60.
  UtmGrid grid() const { return UtmGrid::fromZone(utm_zone, northern_hemisphere); }
};

/**
 * @brief The geo-reference of a dive whose origin is (latitude, longitude): the standard UTM zone of the origin
 * (or UPS near the poles), its hemisphere, EPSG code (326zz / 327zz; 32661 / 32761 for UPS) and the origin's
 * easting/northing. Throws std::invalid_argument naming the field if latitude is outside [-90, 90] or longitude
 * outside [-180, 360).
 */
GeoReference makeGeoReference(double latitude_deg, double longitude_deg);

/// Easting/northing (metres) of a WGS 84 point in the zone of `ref` (extended beyond the zone's border if needed).
inline Eigen::Vector2d latLonToGrid(const GeoReference& ref, double latitude_deg, double longitude_deg) {
  return ref.grid().toGrid(latitude_deg, longitude_deg);
}

/// Latitude/longitude (degrees) of a grid point (easting, northing) of the zone of `ref`.
inline Eigen::Vector2d gridToLatLon(const GeoReference& ref, double easting_m, double northing_m) {
  return ref.grid().toLatLon(easting_m, northing_m);
}

/// Meridian convergence (radians) at a grid point: the bearing of grid north clockwise from true north
/// (GeographicLib's gamma), so a true heading converts to a grid heading as heading_grid = heading_true - gamma.
inline double gridConvergence_rad(const GeoReference& ref, double easting_m, double northing_m) {
  return ref.grid().convergence_rad(easting_m, northing_m);
}

}  // namespace exocet_common
