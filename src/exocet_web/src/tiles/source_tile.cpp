#include "exocet_web/tiles/source_tile.h"

#include <sys/stat.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <memory>
#include <regex>

#include <gdal.h>
#include <ogr_srs_api.h>

#include "gdal_support.h"

namespace exocet_web {
namespace tiles {

namespace {

using detail::DatasetPtr;

struct SrsDeleter {
  void operator()(OGRSpatialReferenceH srs) const { OSRDestroySpatialReference(srs); }
};
struct TransformDeleter {
  void operator()(OGRCoordinateTransformationH t) const { OCTDestroyCoordinateTransformation(t); }
};
using SrsPtr = std::unique_ptr<std::remove_pointer_t<OGRSpatialReferenceH>, SrsDeleter>;
using TransformPtr = std::unique_ptr<std::remove_pointer_t<OGRCoordinateTransformationH>, TransformDeleter>;

SrsPtr srsFromEpsg(int epsg) {
  SrsPtr srs(OSRNewSpatialReference(nullptr));
  if (OSRImportFromEPSG(srs.get(), epsg) != OGRERR_NONE) return nullptr;
  OSRSetAxisMappingStrategy(srs.get(), OAMS_TRADITIONAL_GIS_ORDER);  // x = longitude / easting
  return srs;
}

}  // namespace

bool parseTileFileName(const std::string& file_name, std::string* key, int* index, int* version) {
  static const std::regex kName(R"(([A-Za-z0-9_.\-]*?_([0-9]{4,}))(_v([0-9]+))?\.tif)");
  std::smatch match;
  if (file_name.empty() || file_name[0] == '.' || file_name.find(".cog.tif") != std::string::npos ||
      !std::regex_match(file_name, match, kName))
    return false;
  try {
    if (key) *key = match[1].str();
    if (index) *index = std::stoi(match[2].str());
    if (version) *version = match[4].matched ? std::stoi(match[4].str()) : 1;
  } catch (const std::exception&) {
    return false;  // digits beyond int
  }
  return true;
}

std::vector<std::string> listSourceTiles(const std::string& folder, std::string* error) {
  std::map<std::string, std::pair<int, std::string>> newest;  // key -> (version, path)
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(folder, ec)) {
    std::string key;
    int index = 0, version = 0;
    std::error_code type_error;
    if (!entry.is_regular_file(type_error) ||
        !parseTileFileName(entry.path().filename().string(), &key, &index, &version))
      continue;
    auto& best = newest[key];
    if (best.second.empty() || version > best.first) best = {version, entry.path().string()};
  }
  if (ec && error) *error = "cannot list '" + folder + "': " + ec.message();
  std::vector<std::string> paths;
  for (const auto& item : newest) paths.push_back(item.second.second);
  return paths;
}

std::string readSourceTile(const std::string& path, SourceTile* tile) {
  detail::registerGdalOnce();
  detail::GdalErrors errors;
  SourceTile t;
  std::error_code ec;
  t.path = std::filesystem::absolute(path, ec).string();
  if (ec) t.path = path;
  const std::string name = std::filesystem::path(path).filename().string();
  if (!parseTileFileName(name, &t.key, &t.index, &t.version))
    return "'" + path + "' is not named as a mosaic tile (<prefix>_<NNNN>[_v<K>].tif)";
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return "cannot read '" + path + "': " + std::strerror(errno);
  t.file_size_bytes = st.st_size;
  t.mtime_ns = int64_t(st.st_mtim.tv_sec) * 1000000000 + st.st_mtim.tv_nsec;

  DatasetPtr dataset(GDALOpen(path.c_str(), GA_ReadOnly));
  if (!dataset) {
    const std::string why = errors.take();
    return "GDAL cannot open '" + path + "'" + (why.empty() ? "" : ": " + why);
  }
  GDALDatasetH ds = dataset.get();
  t.width_px = GDALGetRasterXSize(ds);
  t.height_px = GDALGetRasterYSize(ds);
  const int bands = GDALGetRasterCount(ds);
  if (t.width_px <= 0 || t.height_px <= 0 || bands < 1 || bands > 4)
    return "'" + path + "': " + std::to_string(bands) + " bands of " + std::to_string(t.width_px) + " x " +
           std::to_string(t.height_px) + " px, expected 1 to 4 bands (grey or colour, and alpha)";
  double gt[6];
  if (GDALGetGeoTransform(ds, gt) != CE_None) return "'" + path + "' has no geotransform";
  if (gt[2] != 0.0 || gt[4] != 0.0 || !(gt[1] > 0.0) || !(gt[5] < 0.0))
    return "'" + path + "' is not a north-up raster (geotransform rotated or flipped)";
  t.gsd_m = gt[1];

  SrsPtr source_srs(OSRNewSpatialReference(nullptr));
  const char* wkt = GDALGetProjectionRef(ds);
  if (!wkt || !*wkt || OSRImportFromWkt(source_srs.get(), const_cast<char**>(&wkt)) != OGRERR_NONE)
    return "'" + path + "' has no coordinate reference system";
  OSRSetAxisMappingStrategy(source_srs.get(), OAMS_TRADITIONAL_GIS_ORDER);
  if (!OSRIsProjected(source_srs.get()) && !OSRIsGeographic(source_srs.get()))
    return "'" + path + "' is in a local frame (no geodetic datum): it cannot be placed on a web map";
  const char* authority = OSRGetAuthorityName(source_srs.get(), nullptr);
  const char* code = OSRGetAuthorityCode(source_srs.get(), nullptr);
  if (authority && code && std::string(authority) == "EPSG") t.epsg = std::atoi(code);

  SrsPtr mercator = srsFromEpsg(3857);
  SrsPtr wgs84 = srsFromEpsg(4326);
  if (!mercator || !wgs84) return "PROJ cannot make EPSG:3857 or EPSG:4326 (proj.db missing?): " + errors.take();
  TransformPtr to_mercator(OCTNewCoordinateTransformation(source_srs.get(), mercator.get()));
  TransformPtr to_wgs84(OCTNewCoordinateTransformation(source_srs.get(), wgs84.get()));
  if (!to_mercator || !to_wgs84) return "'" + path + "': no transformation to EPSG:3857: " + errors.take();

  // The outline, densified: in Mercator the raster's straight edges bend a little (grid convergence, scale).
  constexpr int kPointsPerEdge = 16;
  std::vector<double> xs, ys;
  const double x0 = gt[0], y0 = gt[3], x1 = gt[0] + t.width_px * gt[1], y1 = gt[3] + t.height_px * gt[5];
  for (int i = 0; i < kPointsPerEdge; ++i) {
    const double f = double(i) / kPointsPerEdge;
    xs.insert(xs.end(), {x0 + f * (x1 - x0), x1, x1 - f * (x1 - x0), x0});
    ys.insert(ys.end(), {y0, y0 + f * (y1 - y0), y1, y1 - f * (y1 - y0)});
  }
  std::vector<double> mx = xs, my = ys, lon = xs, lat = ys;
  if (!OCTTransform(to_mercator.get(), int(mx.size()), mx.data(), my.data(), nullptr) ||
      !OCTTransform(to_wgs84.get(), int(lon.size()), lon.data(), lat.data(), nullptr))
    return "'" + path + "': its outline cannot be transformed to EPSG:3857 / WGS 84: " + errors.take();
  t.bounds = {*std::min_element(mx.begin(), mx.end()), *std::min_element(my.begin(), my.end()),
              *std::max_element(mx.begin(), mx.end()), *std::max_element(my.begin(), my.end())};
  t.latlon_box = {*std::min_element(lon.begin(), lon.end()), *std::min_element(lat.begin(), lat.end()),
                  *std::max_element(lon.begin(), lon.end()), *std::max_element(lat.begin(), lat.end())};
  for (double v : {t.bounds.min_x_m, t.bounds.min_y_m, t.bounds.max_x_m, t.bounds.max_y_m})
    if (!std::isfinite(v)) return "'" + path + "': its outline is not finite in EPSG:3857";
  // Corners: the first point of each edge (top-left, top-right, bottom-right, bottom-left).
  for (int c = 0; c < 4; ++c) t.corners_deg[c] = {lat[c], lon[c]};
  t.centre_latitude_deg = 0.5 * (t.latlon_box.south_deg + t.latlon_box.north_deg);

  char** items = GDALGetMetadata(ds, nullptr);
  for (char** item = items; item && *item; ++item) {
    const std::string kv = *item;
    const size_t eq = kv.find('=');
    if (eq == std::string::npos || kv.compare(0, 7, "EXOCET_") != 0) continue;
    std::string key = kv.substr(7, eq - 7);
    std::transform(key.begin(), key.end(), key.begin(), [](unsigned char c) { return std::tolower(c); });
    t.metadata[key] = kv.substr(eq + 1);
  }
  *tile = std::move(t);
  return "";
}

}  // namespace tiles
}  // namespace exocet_web
