#include "exocet_common/utm_grid.h"

#include <cmath>
#include <sstream>
#include <stdexcept>

#include <GeographicLib/Constants.hpp>
#include <GeographicLib/UTMUPS.hpp>

namespace exocet_common {
namespace {

constexpr double kDegToRad = M_PI / 180.0;
/// UTM false northing of the southern hemisphere (GeographicLib's UTMShift()).
const double kUtmShift_m = GeographicLib::UTMUPS::UTMShift();

void checkLatLon(double latitude_deg, double longitude_deg) {
  if (!(latitude_deg >= -90.0 && latitude_deg <= 90.0)) {
    std::ostringstream s;
    s << "latitude " << latitude_deg << " deg is NaN or out of range [-90, 90] deg";
    throw std::invalid_argument(s.str());
  }
  if (!(longitude_deg >= -180.0 && longitude_deg < 360.0)) {
    std::ostringstream s;
    s << "longitude " << longitude_deg << " deg is NaN or out of range [-180, 360) deg";
    throw std::invalid_argument(s.str());
  }
}

}  // namespace

UtmGrid UtmGrid::forLatLon(double latitude_deg, double longitude_deg) {
  checkLatLon(latitude_deg, longitude_deg);
  const int zone = GeographicLib::UTMUPS::StandardZone(latitude_deg, longitude_deg);
  return UtmGrid(zone, latitude_deg >= 0.0);
}

UtmGrid UtmGrid::fromZone(int zone, bool northern) {
  if (zone < 0 || zone > 60)
    throw std::invalid_argument("UTM zone " + std::to_string(zone) + " out of range [0, 60] (1..60 UTM, 0 UPS)");
  return UtmGrid(zone, northern);
}

int UtmGrid::epsg() const {
  if (zone_ == 0) return northern_ ? 32661 : 32761;
  return (northern_ ? 32600 : 32700) + zone_;
}

std::string UtmGrid::name() const {
  if (zone_ == 0) return northern_ ? "UPS N" : "UPS S";
  return std::to_string(zone_) + (northern_ ? "N" : "S");
}

Eigen::Vector2d UtmGrid::toGrid(double latitude_deg, double longitude_deg) const {
  checkLatLon(latitude_deg, longitude_deg);
  if (zone_ == 0 && (latitude_deg >= 0.0) != northern_) {
    std::ostringstream s;
    s << "latitude " << latitude_deg << " deg is in the other hemisphere than grid " << name();
    throw std::invalid_argument(s.str());
  }
  int zone = 0;
  bool north = true;
  double x = 0.0, y = 0.0, gamma = 0.0, k = 0.0;
  try {
    GeographicLib::UTMUPS::Forward(latitude_deg, longitude_deg, zone, north, x, y, gamma, k, zone_);
  } catch (const GeographicLib::GeographicErr& e) {
    std::ostringstream s;
    s << "latitude " << latitude_deg << " deg, longitude " << longitude_deg << " deg cannot be expressed in grid "
      << name() << ": " << e.what();
    throw std::invalid_argument(s.str());
  }
  // GeographicLib returns the point's own hemisphere convention (false northing 10 000 km in the south): continue
  // the northing across the equator in this grid's convention.
  if (zone_ != 0 && north != northern_) y += north ? kUtmShift_m : -kUtmShift_m;
  return {x, y};
}

void UtmGrid::reverse(double easting_m, double northing_m, double* latitude_deg, double* longitude_deg,
                      double* gamma_deg, double* scale) const {
  if (!std::isfinite(easting_m) || !std::isfinite(northing_m)) {
    std::ostringstream s;
    s << "grid point easting " << easting_m << " m, northing " << northing_m << " m is not finite";
    throw std::invalid_argument(s.str());
  }
  try {
    GeographicLib::UTMUPS::Reverse(zone_, northern_, easting_m, northing_m, *latitude_deg, *longitude_deg, *gamma_deg,
                                   *scale);
  } catch (const GeographicLib::GeographicErr& e) {
    std::ostringstream s;
    s << "grid point easting " << easting_m << " m, northing " << northing_m << " m is outside the limits of grid "
      << name() << ": " << e.what();
    throw std::invalid_argument(s.str());
  }
}

Eigen::Vector2d UtmGrid::toLatLon(double easting_m, double northing_m) const {
  double lat = 0.0, lon = 0.0, gamma = 0.0, k = 0.0;
  reverse(easting_m, northing_m, &lat, &lon, &gamma, &k);
  return {lat, lon};
}

double UtmGrid::convergence_rad(double easting_m, double northing_m) const {
  double lat = 0.0, lon = 0.0, gamma = 0.0, k = 0.0;
  reverse(easting_m, northing_m, &lat, &lon, &gamma, &k);
  return gamma * kDegToRad;
}

double UtmGrid::scaleFactor(double easting_m, double northing_m) const {
  double lat = 0.0, lon = 0.0, gamma = 0.0, k = 0.0;
  reverse(easting_m, northing_m, &lat, &lon, &gamma, &k);
  return k;
}

}  // namespace exocet_common
