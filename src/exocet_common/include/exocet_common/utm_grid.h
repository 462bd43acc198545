/**
 * @file utm_grid.h
 * @brief One UTM zone (or UPS) used as the metric world frame of a whole dive, whatever zone border the dive
 * crosses: WGS 84 <-> easting/northing in that zone (GeographicLib UTMUPS), its EPSG code and the meridian
 * convergence. No ROS in it.
 */
#pragma once

#include <string>

#include <Eigen/Core>

namespace exocet_common {

/**
 * @brief A fixed UTM zone and hemisphere, or one UPS pole.
 *
 * Points outside the zone are converted in this zone (transverse Mercator continued past the zone's border, as
 * GeographicLib allows: eastings [0, 1000] km), so that a dive straddling a border keeps one straight metric frame.
 * Northings of a UTM grid are continued across the equator (a northern grid gives negative northings south of the
 * equator; a southern grid gives northings above 10 000 km north of it).
 */
class UtmGrid {
 public:
  /// The standard zone of a point (UTM, or UPS above 84 N / below 80 S) and the point's hemisphere.
  /// @throws std::invalid_argument naming latitude (allowed [-90, 90] deg) or longitude ([-180, 360) deg) when it is
  ///         NaN or out of range.
  static UtmGrid forLatLon(double latitude_deg, double longitude_deg);
  /// A given zone: 1..60 for UTM, 0 for UPS (`northern` selects the pole). @throws std::invalid_argument otherwise.
  static UtmGrid fromZone(int zone, bool northern);

  /// UTM zone 1..60, or 0 for UPS.
  int zone() const { return zone_; }
  bool northern() const { return northern_; }
  bool isUps() const { return zone_ == 0; }
  /// EPSG code of the grid: 326zz (north) / 327zz (south) for UTM, 32661 / 32761 for UPS north / south.
  int epsg() const;
  /// "31N", "7S", "UPS N", "UPS S".
  std::string name() const;

  /**
   * @brief Easting, northing (metres) of a WGS 84 point in THIS grid (extended past the zone's border).
   * @throws std::invalid_argument for NaN or out-of-range latitude/longitude, a point too far from the zone for
   *         GeographicLib's extended limits, or (UPS) a point of the other hemisphere.
   */
  Eigen::Vector2d toGrid(double latitude_deg, double longitude_deg) const;
  /// Latitude, longitude (degrees; longitude in [-180, 180)) of a grid point. @throws std::invalid_argument naming
  /// easting/northing when non-finite or outside GeographicLib's limits for the grid.
  Eigen::Vector2d toLatLon(double easting_m, double northing_m) const;
  /// Meridian convergence at a grid point (radians): the bearing of grid north clockwise from true north
  /// (GeographicLib's gamma), so heading_grid = heading_true - convergence. @throws like toLatLon.
  double convergence_rad(double easting_m, double northing_m) const;
  /// Point scale factor of the projection at a grid point (grid distance / true distance).
  double scaleFactor(double easting_m, double northing_m) const;

  bool operator==(const UtmGrid& other) const { return zone_ == other.zone_ && northern_ == other.northern_; }
  bool operator!=(const UtmGrid& other) const { return !(*this == other); }

 private:
  UtmGrid(int zone, bool northern) : zone_(zone), northern_(northern) {}
  /// Reverse projection with convergence (degrees) and scale.
  void reverse(double easting_m, double northing_m, double* latitude_deg, double* longitude_deg, double* gamma_deg,
               double* scale) const;

  int zone_ = 31;
  bool northern_ = true;
};

}  // namespace exocet_common
