#include "exocet_web/tiles/web_mercator.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace exocet_web {
namespace tiles {

namespace {

constexpr double kEarthRadius_m = 6378137.0;  // the sphere of EPSG:3857 (WGS 84's semi-major axis)
constexpr double kDegPerRad = 180.0 / M_PI;

void checkZoom(int z) {
  if (z < 0 || z > kMaxZoom)
    throw std::invalid_argument("zoom level " + std::to_string(z) + " outside [0, " + std::to_string(kMaxZoom) + "]");
}

}  // namespace

std::string TileId::path() const { return std::to_string(z) + "/" + std::to_string(x) + "/" + std::to_string(y); }

MercatorBox MercatorBox::unitedWith(const MercatorBox& other) const {
  if (other.empty()) return *this;
  if (empty()) return other;
  return {std::min(min_x_m, other.min_x_m), std::min(min_y_m, other.min_y_m), std::max(max_x_m, other.max_x_m),
          std::max(max_y_m, other.max_y_m)};
}

bool MercatorBox::intersects(const MercatorBox& other) const { return !intersection(other).empty(); }

MercatorBox MercatorBox::intersection(const MercatorBox& other) const {
  return {std::max(min_x_m, other.min_x_m), std::max(min_y_m, other.min_y_m), std::min(max_x_m, other.max_x_m),
          std::min(max_y_m, other.max_y_m)};
}

std::vector<TileId> TileRange::tiles() const {
  std::vector<TileId> out;
  if (empty()) return out;
  out.reserve(static_cast<size_t>(count()));
  for (int y = min_y; y <= max_y; ++y)
    for (int x = min_x; x <= max_x; ++x) out.push_back({z, x, y});
  return out;
}

double mercatorX_m(double longitude_deg) { return kEarthRadius_m * longitude_deg / kDegPerRad; }

double mercatorY_m(double latitude_deg) {
  const double lat = std::clamp(latitude_deg, -kMercatorMaxLatitude_deg, kMercatorMaxLatitude_deg) / kDegPerRad;
  return kEarthRadius_m * std::log(std::tan(M_PI / 4.0 + lat / 2.0));
}

double longitudeFromMercatorX_deg(double x_m) { return x_m / kEarthRadius_m * kDegPerRad; }

double latitudeFromMercatorY_deg(double y_m) {
  return (2.0 * std::atan(std::exp(y_m / kEarthRadius_m)) - M_PI / 2.0) * kDegPerRad;
}

double resolution_m_per_px(int z) {
  checkZoom(z);
  return 2.0 * kMercatorHalfSide_m / (kTileSize_px * std::ldexp(1.0, z));
}

double groundResolution_m_per_px(int z, double latitude_deg) {
  return resolution_m_per_px(z) * std::cos(latitude_deg / kDegPerRad);
}

MercatorBox tileBounds(const TileId& tile) {
  checkZoom(tile.z);
  const double side_m = 2.0 * kMercatorHalfSide_m / std::ldexp(1.0, tile.z);
  MercatorBox box;
  box.min_x_m = -kMercatorHalfSide_m + tile.x * side_m;
  box.max_x_m = box.min_x_m + side_m;
  box.max_y_m = kMercatorHalfSide_m - tile.y * side_m;
  box.min_y_m = box.max_y_m - side_m;
  return box;
}

LatLonBox tileLatLonBounds(const TileId& tile) {
  const MercatorBox b = tileBounds(tile);
  return {longitudeFromMercatorX_deg(b.min_x_m), latitudeFromMercatorY_deg(b.min_y_m),
          longitudeFromMercatorX_deg(b.max_x_m), latitudeFromMercatorY_deg(b.max_y_m)};
}

TileRange tilesCovering(const MercatorBox& box, int z) {
  checkZoom(z);
  TileRange range;
  range.z = z;
  if (box.empty()) return range;
  const double n = std::ldexp(1.0, z);
  const double side_m = 2.0 * kMercatorHalfSide_m / n;
  const int last = static_cast<int>(n) - 1;
  // A box edge exactly on a tile edge does not take the next tile: ceil - 1 on the far side.
  const auto clampIndex = [last](double v) { return static_cast<int>(std::clamp(v, 0.0, double(last))); };
  range.min_x = clampIndex(std::floor((box.min_x_m + kMercatorHalfSide_m) / side_m));
  range.max_x = clampIndex(std::ceil((box.max_x_m + kMercatorHalfSide_m) / side_m) - 1.0);
  range.min_y = clampIndex(std::floor((kMercatorHalfSide_m - box.max_y_m) / side_m));
  range.max_y = clampIndex(std::ceil((kMercatorHalfSide_m - box.min_y_m) / side_m) - 1.0);
  return range;
}

TileId parentOf(const TileId& tile) {
  if (tile.z == 0) return tile;
  return {tile.z - 1, tile.x >> 1, tile.y >> 1};
}

int nativeZoom(double gsd_m, double latitude_deg) {
  if (!(gsd_m > 0.0) || !std::isfinite(gsd_m))
    throw std::invalid_argument("ground sample distance " + std::to_string(gsd_m) + " m: must be > 0");
  if (!(std::abs(latitude_deg) < 90.0))
    throw std::invalid_argument("latitude " + std::to_string(latitude_deg) + " deg outside (-90, 90)");
  const double level0_m = resolution_m_per_px(0) * std::cos(latitude_deg / kDegPerRad);
  const int z = static_cast<int>(std::lround(std::log2(level0_m / gsd_m)));
  return std::clamp(z, 0, kMaxZoom);
}

int zoomFittingBox(const MercatorBox& box, int max_zoom) {
  max_zoom = std::clamp(max_zoom, 0, kMaxZoom);
  if (box.empty()) return max_zoom;
  const double extent_m = std::max(box.max_x_m - box.min_x_m, box.max_y_m - box.min_y_m);
  for (int z = max_zoom; z > 0; --z)
    if (extent_m <= 2.0 * kMercatorHalfSide_m / std::ldexp(1.0, z)) return z;
  return 0;
}

}  // namespace tiles
}  // namespace exocet_web
