#include "exocet_mosaic/sim/geo_reference.h"

#include <cmath>
#include <stdexcept>
#include <string>

#include <GeographicLib/UTMUPS.hpp>

namespace exocet_mosaic {
namespace sim {

GeoReference makeGeoReference(double latitude_deg, double longitude_deg) {
  if (!(latitude_deg >= -90.0 && latitude_deg <= 90.0))
    throw std::invalid_argument("origin latitude " + std::to_string(latitude_deg) + " deg out of range [-90, 90]");
  if (!(longitude_deg >= -180.0 && longitude_deg < 360.0))
    throw std::invalid_argument("origin longitude " + std::to_string(longitude_deg) +
                                " deg out of range [-180, 360)");
  GeoReference ref;
  ref.origin_latitude_deg = latitude_deg;
  ref.origin_longitude_deg = longitude_deg;
  int zone = 0;
  bool north = true;
  double x = 0, y = 0;
  GeographicLib::UTMUPS::Forward(latitude_deg, longitude_deg, zone, north, x, y);
  ref.utm_zone = zone;
  ref.northern_hemisphere = north;
  ref.origin_easting_m = x;
  ref.origin_northing_m = y;
  if (zone == GeographicLib::UTMUPS::UPS)
    ref.epsg = north ? 32661 : 32761;
  else
    ref.epsg = (north ? 32600 : 32700) + zone;
  return ref;
}

Eigen::Vector2d latLonToGrid(const GeoReference& ref, double latitude_deg, double longitude_deg) {
  int zone = 0;
  bool north = true;
  double x = 0, y = 0, gamma = 0, k = 0;
  GeographicLib::UTMUPS::Forward(latitude_deg, longitude_deg, zone, north, x, y, gamma, k, ref.utm_zone);
  if (north != ref.northern_hemisphere) {
    // Same zone, other hemisphere's false northing: express in the dive's hemisphere convention.
    y += north ? 10000000.0 : -10000000.0;  // north of the equator seen from the south: +10000 km
  }
  return {x, y};
}

Eigen::Vector2d gridToLatLon(const GeoReference& ref, double easting_m, double northing_m) {
  double lat = 0, lon = 0;
  GeographicLib::UTMUPS::Reverse(ref.utm_zone, ref.northern_hemisphere, easting_m, northing_m, lat, lon);
  return {lat, lon};
}

double gridConvergence_rad(const GeoReference& ref, double easting_m, double northing_m) {
  double lat = 0, lon = 0, gamma = 0, k = 0;
  GeographicLib::UTMUPS::Reverse(ref.utm_zone, ref.northern_hemisphere, easting_m, northing_m, lat, lon, gamma, k);
  return gamma * M_PI / 180.0;
}

}  // namespace sim
}  // namespace exocet_mosaic
