#include "exocet_common/geo_reference.h"

namespace exocet_common {

GeoReference makeGeoReference(double latitude_deg, double longitude_deg) {
  const UtmGrid grid = UtmGrid::forLatLon(latitude_deg, longitude_deg);  // validates both, naming the bad one
  const Eigen::Vector2d origin = grid.toGrid(latitude_deg, longitude_deg);
  GeoReference ref;
  ref.utm_zone = grid.zone();
  ref.northern_hemisphere = grid.northern();
  ref.epsg = grid.epsg();
  ref.origin_latitude_deg = latitude_deg;
  ref.origin_longitude_deg = longitude_deg;
  ref.origin_easting_m = origin.x();
  ref.origin_northing_m = origin.y();
  return ref;
}

}  // namespace exocet_common
