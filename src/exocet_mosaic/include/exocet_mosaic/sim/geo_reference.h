/**
 * @file geo_reference.h
 * @brief WGS 84 <-> UTM/UPS conversions for a dive (GeographicLib), with the EPSG code of the zone.
 */
#pragma once

#include "exocet_mosaic/sim/dive_records.h"

namespace exocet_mosaic {
namespace sim {

/**
 * @brief The geo-reference of a dive whose origin is (latitude, longitude): the standard UTM zone of the origin
 * (or UPS near the poles), its hemisphere, EPSG code (326zz / 327zz; 32661 / 32761 for UPS) and the origin's
 * easting/northing. Throws std::invalid_argument naming the field if latitude is outside [-90, 90] or longitude
 * outside [-180, 360).
 */
GeoReference makeGeoReference(double latitude_deg, double longitude_deg);

/// Easting/northing (metres) of a WGS 84 point in the zone of `ref` (extended beyond the zone's border if needed).
Eigen::Vector2d latLonToGrid(const GeoReference& ref, double latitude_deg, double longitude_deg);

/// Latitude/longitude (degrees) of a grid point (easting, northing) of the zone of `ref`.
Eigen::Vector2d gridToLatLon(const GeoReference& ref, double easting_m, double northing_m);

/// Meridian convergence (radians) at a grid point: the bearing of grid north clockwise from true north
/// (GeographicLib's gamma), so a true heading converts to a grid heading as heading_grid = heading_true - gamma.
double gridConvergence_rad(const GeoReference& ref, double easting_m, double northing_m);

}  // namespace sim
}  // namespace exocet_mosaic
