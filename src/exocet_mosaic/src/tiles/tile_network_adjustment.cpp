#include "exocet_mosaic/tiles/tile_network_adjustment.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <map>
#include <regex>
#include <sstream>

#include <climits>
#include <cstdlib>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <Eigen/LU>
#include <Eigen/Sparse>
#include <cpl_conv.h>
#include <cpl_error.h>
#include <gdal_priv.h>
#include <ogr_spatialref.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "exocet_mosaic/tiles/geotiff_tile_writer.h"
#include "exocet_mosaic/tiles/tile_json.h"

namespace exocet_mosaic {
namespace tiles {

namespace {

struct DatasetCloser {
  void operator()(GDALDataset* d) const { GDALClose(GDALDataset::ToHandle(d)); }
};
using DatasetPtr = std::unique_ptr<GDALDataset, DatasetCloser>;

DatasetPtr openTile(const std::string& path, bool update) {
  GDALAllRegister();
  const char* const drivers[] = {"GTiff", nullptr};
  return DatasetPtr(GDALDataset::FromHandle(GDALOpenEx(
      path.c_str(), GDAL_OF_RASTER | (update ? GDAL_OF_UPDATE : GDAL_OF_READONLY), drivers, nullptr, nullptr)));
}

std::string baseName(const std::string& path) {
  const auto slash = path.find_last_of('/');
  return slash == std::string::npos ? path : path.substr(slash + 1);
}

/// Reads one tile's georeference; an empty string if usable, otherwise why not.
std::string readTile(const std::string& path, const TileAdjustmentConfig& config, AdjustedTile* tile) {
  DatasetPtr dataset = openTile(path, false);
  if (!dataset) return "cannot open '" + path + "' as a GeoTIFF: " + CPLGetLastErrorMsg();
  double gt[6];
  if (dataset->GetGeoTransform(gt) != CE_None) return "'" + path + "' has no geotransform";
  if (gt[2] != 0.0 || gt[4] != 0.0 || !(gt[1] > 0.0) || std::abs(gt[1] + gt[5]) > 1e-9 * gt[1])
    return "'" + path + "' is not a north-up tile with square pixels";
  if (dataset->GetRasterCount() < 2) return "'" + path + "' has no alpha band (bands: colour or grey, then alpha)";
  const OGRSpatialReference* srs = dataset->GetSpatialRef();
  const char* code = srs ? srs->GetAuthorityCode(nullptr) : nullptr;
  if (!code) return "'" + path + "' has no EPSG code";
  tile->path = path;
  tile->epsg = std::atoi(code);
  tile->gsd_m = gt[1];
  tile->origin_easting_m = gt[0];
  tile->origin_northing_m = gt[3];
  tile->width_px = dataset->GetRasterXSize();
  tile->height_px = dataset->GetRasterYSize();
  const char* sigma = dataset->GetMetadataItem("EXOCET_POSITION_SIGMA_M");
  tile->position_sigma_m = sigma ? std::atof(sigma) : 0.0;
  if (!(tile->position_sigma_m > 0.0)) tile->position_sigma_m = config.default_position_sigma_m;
  return "";
}

/// Grey level (mean of the colour bands) and alpha of a window of a tile.
bool readWindow(const AdjustedTile& tile, const cv::Rect& window, cv::Mat* grey, cv::Mat* alpha) {
  DatasetPtr dataset = openTile(tile.path, false);
  if (!dataset) return false;
  const int bands = dataset->GetRasterCount();
  cv::Mat pixels(window.height, window.width, CV_8UC(bands));
  if (dataset->RasterIO(GF_Read, window.x, window.y, window.width, window.height, pixels.data, window.width,
                        window.height, GDT_Byte, bands, nullptr, bands, static_cast<GSpacing>(pixels.step), 1,
                        nullptr) != CE_None)
    return false;
  std::vector<cv::Mat> planes;
  cv::split(pixels, planes);
  *alpha = planes.back();
  planes.pop_back();
  cv::Mat sum(window.size(), CV_32F, cv::Scalar(0));
  for (const cv::Mat& p : planes) cv::accumulate(p, sum);
  sum.convertTo(*grey, CV_32F, 1.0 / static_cast<double>(planes.size()));
  return true;
}

/// The offset of b's content from a's in their overlap (b minus a), or false when it cannot be measured (*read_failed
/// set when a file could not be read, which the next attempt may).
bool measurePair(const AdjustedTile& a, const AdjustedTile& b, const TileAdjustmentConfig& config,
                 TilePairOffset* pair, bool* read_failed) {
  *read_failed = false;
  const double g = a.gsd_m;
  const double e0 = std::max(a.origin_easting_m, b.origin_easting_m);
  const double e1 = std::min(a.origin_easting_m + a.width_px * g, b.origin_easting_m + b.width_px * g);
  const double n1 = std::min(a.origin_northing_m, b.origin_northing_m);
  const double n0 = std::max(a.origin_northing_m - a.height_px * g, b.origin_northing_m - b.height_px * g);
  const int width = static_cast<int>(std::floor((e1 - e0) / g)) - 2;
  const int height = static_cast<int>(std::floor((n1 - n0) / g)) - 2;
  if (width < 64 || height < 64) return false;
  // The same UTM rectangle in both: whole pixels in a; in b the nearest whole pixels, the rest added to the offset.
  const int col_a = static_cast<int>(std::ceil((e0 - a.origin_easting_m) / g)) + 1;
  const int row_a = static_cast<int>(std::ceil((a.origin_northing_m - n1) / g)) + 1;
  const double window_e = a.origin_easting_m + col_a * g, window_n = a.origin_northing_m - row_a * g;
  const int col_b = static_cast<int>(std::lround((window_e - b.origin_easting_m) / g));
  const int row_b = static_cast<int>(std::lround((b.origin_northing_m - window_n) / g));
  const cv::Rect window_a(col_a, row_a, width, height), window_b(col_b, row_b, width, height);
  if ((window_a & cv::Rect(0, 0, a.width_px, a.height_px)) != window_a ||
      (window_b & cv::Rect(0, 0, b.width_px, b.height_px)) != window_b)
    return false;
  cv::Mat grey_a, alpha_a, grey_b, alpha_b;
  if (!readWindow(a, window_a, &grey_a, &alpha_a) || !readWindow(b, window_b, &grey_b, &alpha_b)) {
    *read_failed = true;
    return false;
  }

  // Band-passed: the lamp's shading differs between passes, the seabed's texture does not.
  for (cv::Mat* grey : {&grey_a, &grey_b}) {
    cv::Mat low;
    cv::GaussianBlur(*grey, low, cv::Size(0, 0), 12.0);
    *grey -= low;
  }
  // Phase correlation of the patches wholly inside both masks (a mask edge pulls the shift to zero).
  struct PatchShift {
    cv::Point2d centre_px, shift_px;
  };
  auto measurePatches = [&](const cv::Mat& b_grey, int p, std::vector<PatchShift>* shifts) {
    cv::Mat hann;
    cv::createHanningWindow(hann, cv::Size(p, p), CV_32F);
    shifts->clear();
    double min_a, min_b;
    for (int y = 0; y + p <= height; y += p / 2) {
      for (int x = 0; x + p <= width; x += p / 2) {
        const cv::Rect r(x, y, p, p);
        cv::minMaxLoc(alpha_a(r), &min_a);
        cv::minMaxLoc(alpha_b(r), &min_b);
        if (min_a < 255 || min_b < 255) continue;
        double response = 0;
        const cv::Point2d s = cv::phaseCorrelate(grey_a(r), b_grey(r), hann, &response);
        if (response >= config.min_response) shifts->push_back({cv::Point2d(x + 0.5 * p, y + 0.5 * p), s});
      }
    }
  };
  auto median = [](std::vector<double> v) {
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    return v[v.size() / 2];
  };
  // The patches that agree with the median shift (a patch on a moving fish or a featureless patch does not), their
  // mean, and the median distance from the median.
  auto agreeing = [&](const std::vector<PatchShift>& shifts, std::vector<PatchShift>* kept, cv::Point2d* mean,
                      double* spread) {
    kept->clear();
    if (static_cast<int>(shifts.size()) < config.min_patches) return false;
    std::vector<double> xs, ys, distances;
    for (const auto& s : shifts) xs.push_back(s.shift_px.x), ys.push_back(s.shift_px.y);
    const cv::Point2d m(median(xs), median(ys));
    *mean = cv::Point2d(0, 0);
    for (const auto& s : shifts) {
      distances.push_back(cv::norm(s.shift_px - m));
      if (cv::norm(s.shift_px - m) <= config.max_patch_spread_px) kept->push_back(s), *mean += s.shift_px;
    }
    if (static_cast<int>(kept->size()) < config.min_patches) return false;
    *mean *= 1.0 / kept->size();
    *spread = median(distances);
    return true;
  };
  // Overlaps of adjacent lines are strips: smaller patches there (a patch holds shifts up to a quarter of its side).
  // Too few patches, or patches that disagree (a small shared footprint, mostly mask edge): smaller ones.
  std::vector<PatchShift> shifts, kept;
  int patch = 0;
  cv::Point2d mean;
  double spread = 0;
  bool measured = false;
  for (int p = config.patch_px; (p >= 64 || p == config.patch_px) && !measured; p /= 2) {
    if (width < p || height < p) continue;
    measurePatches(grey_b, p, &shifts);
    patch = p;
    measured = agreeing(shifts, &kept, &mean, &spread);
  }
  if (!measured) return false;
  // The sub-pixel peak of a phase correlation is biased away from whole pixels (up to ~0.3 px): with b resampled by
  // the mean shift the patches' residual shifts are near zero, where the peak is unbiased.
  for (int iteration = 0; iteration < 2; ++iteration) {
    const cv::Matx23d back(1, 0, mean.x, 0, 1, mean.y);  // b's window sampled at (x + dx, y + dy)
    cv::Mat shifted;
    cv::warpAffine(grey_b, shifted, back, grey_b.size(), cv::INTER_CUBIC | cv::WARP_INVERSE_MAP, cv::BORDER_REFLECT);
    std::vector<PatchShift> residuals, residuals_kept;
    measurePatches(shifted, patch, &residuals);
    cv::Point2d residual;
    double residual_spread = 0;
    // A residual beyond the bias means the resampled patches no longer agree (a small overlap): keep the estimate.
    if (!agreeing(residuals, &residuals_kept, &residual, &residual_spread) || cv::norm(residual) > 0.5) break;
    for (auto& r : residuals_kept) r.shift_px += mean;
    kept = residuals_kept;
    mean += residual;
  }
  // A feature at window pixel (x, y) of a is at (x + dx, y + dy) of b's window; b's window starts at its own UTM corner.
  const double window_b_e = b.origin_easting_m + col_b * g, window_b_n = b.origin_northing_m - row_b * g;
  auto offsetOf = [&](const cv::Point2d& s) {
    return Eigen::Vector2d(window_b_e - window_e + s.x * g, window_b_n - window_n - s.y * g);
  };
  pair->offset_en_m = offsetOf(mean);
  pair->patches = static_cast<int>(kept.size());
  pair->patch_px = patch;
  pair->spread_px = spread;
  for (const auto& k : kept) {
    PatchOffset o;
    o.centre_en_m = Eigen::Vector2d(window_e + k.centre_px.x * g, window_n - k.centre_px.y * g);
    o.offset_en_m = offsetOf(k.shift_px);
    o.patch_px = patch;
    pair->patch_offsets.push_back(o);
  }
  return true;
}


/// The UTM zone and hemisphere of a WGS 84 UTM / UPS EPSG code (326zz, 327zz, 32661, 32761), or false.
bool zoneOfEpsg(int epsg, int* zone, bool* northern) {
  if (epsg == 32661 || epsg == 32761) {
    *zone = 0;
    *northern = epsg == 32661;
    return true;
  }
  if (epsg > 32600 && epsg <= 32660) return *zone = epsg - 32600, *northern = true, true;
  if (epsg > 32700 && epsg <= 32760) return *zone = epsg - 32700, *northern = false, true;
  return false;
}

/// The tile resampled north-up after its adjustment, on a grid of the same GSD holding every moved pixel. Colour is
/// interpolated premultiplied by alpha (no dark fringe at the no-data edge); alpha >= 128 is data.
std::string resampleTile(const AdjustedTile& tile, GDALDataset* dataset, TileRaster* raster) {
  const int bands = dataset->GetRasterCount();
  const int colour_bands = bands - 1;
  if (colour_bands != 1 && colour_bands != 3) return "'" + tile.path + "' has " + std::to_string(bands) + " bands";
  cv::Mat pixels(tile.height_px, tile.width_px, CV_8UC(bands));
  if (dataset->RasterIO(GF_Read, 0, 0, tile.width_px, tile.height_px, pixels.data, tile.width_px, tile.height_px,
                        GDT_Byte, bands, nullptr, bands, static_cast<GSpacing>(pixels.step), 1, nullptr) != CE_None)
    return "cannot read the pixels of '" + tile.path + "': " + CPLGetLastErrorMsg();
  for (int y = 0; y < pixels.rows; ++y) {
    uchar* p = pixels.ptr<uchar>(y);
    for (int x = 0; x < pixels.cols; ++x, p += bands)
      for (int c = 0; c < colour_bands; ++c) p[c] = static_cast<uchar>((p[c] * p[colour_bands] + 127) / 255);
  }
  const double g = tile.gsd_m;
  // Source pixel (x, y) has its centre at (E0 + (x + 0.5) g, N0 - (y + 0.5) g).
  double e_min = 1e300, e_max = -1e300, n_min = 1e300, n_max = -1e300;
  for (const double x : {0.0, static_cast<double>(tile.width_px)}) {
    for (const double y : {0.0, static_cast<double>(tile.height_px)}) {
      const Eigen::Vector2d q = tile.moved(Eigen::Vector2d(tile.origin_easting_m + x * g, tile.origin_northing_m - y * g));
      e_min = std::min(e_min, q.x()), e_max = std::max(e_max, q.x());
      n_min = std::min(n_min, q.y()), n_max = std::max(n_max, q.y());
    }
  }
  // The new grid: the old one moved by the shift, widened to whole pixels around the moved corners.
  const double grid_e = tile.origin_easting_m + tile.shift_en_m.x(), grid_n = tile.origin_northing_m + tile.shift_en_m.y();
  const double origin_e = grid_e + g * std::floor((e_min - grid_e) / g);
  const double origin_n = grid_n + g * std::ceil((n_max - grid_n) / g);
  const cv::Size size(static_cast<int>(std::ceil((e_max - origin_e) / g - 1e-6)),
                      static_cast<int>(std::ceil((origin_n - n_min) / g - 1e-6)));
  // Output pixel (u, v) -> its UTM centre -> back through the adjustment (a similarity: its inverse is affine) ->
  // source pixel. Three points give the affine map.
  const Eigen::Matrix2d m = (Eigen::Matrix2d() << 1.0 + tile.scale_change, -tile.rotation_rad, tile.rotation_rad,
                             1.0 + tile.scale_change).finished();
  const Eigen::Matrix2d m_inverse = m.inverse();
  auto sourceOf = [&](double u, double v) {
    const Eigen::Vector2d q(origin_e + (u + 0.5) * g, origin_n - (v + 0.5) * g);
    const Eigen::Vector2d p = tile.centre_en_m + m_inverse * (q - tile.shift_en_m - tile.centre_en_m);
    return Eigen::Vector2d((p.x() - tile.origin_easting_m) / g - 0.5, (tile.origin_northing_m - p.y()) / g - 0.5);
  };
  const Eigen::Vector2d s0 = sourceOf(0, 0), su = sourceOf(1, 0) - s0, sv = sourceOf(0, 1) - s0;
  const cv::Matx23d map(su.x(), sv.x(), s0.x(), su.y(), sv.y(), s0.y());
  cv::Mat warped;
  cv::warpAffine(pixels, warped, map, size, cv::INTER_LINEAR | cv::WARP_INVERSE_MAP, cv::BORDER_CONSTANT,
                 cv::Scalar::all(0));
  cv::Mat colour(size, CV_8UC(colour_bands)), mask(size, CV_8UC1);
  for (int y = 0; y < size.height; ++y) {
    const uchar* w = warped.ptr<uchar>(y);
    uchar* c = colour.ptr<uchar>(y);
    uchar* k = mask.ptr<uchar>(y);
    for (int x = 0; x < size.width; ++x, w += bands, c += colour_bands) {
      const int alpha = w[colour_bands];
      k[x] = alpha >= 128 ? 255 : 0;
      for (int b = 0; b < colour_bands; ++b) {
        // The file's R, G, B to OpenCV's B, G, R.
        const int value = alpha > 0 ? std::min(255, (w[b] * 255 + alpha / 2) / alpha) : 0;
        c[colour_bands == 3 ? 2 - b : b] = static_cast<uchar>(alpha >= 128 ? value : 0);
      }
    }
  }
  raster->image = colour;
  raster->mask = mask;
  raster->origin_easting_m = origin_e;
  raster->origin_northing_m = origin_n;
  raster->gsd_m = g;
  if (!zoneOfEpsg(tile.epsg, &raster->utm_zone, &raster->northern_hemisphere))
    return "'" + tile.path + "' is in EPSG:" + std::to_string(tile.epsg) + ", not a WGS 84 UTM / UPS zone";
  return "";
}

}  // namespace

std::string TileAdjustmentConfig::validate() const {
  std::vector<std::string> bad;
  if (patch_px < 32 || patch_px > 1024 || (patch_px & (patch_px - 1)) != 0)
    bad.push_back("patch_px must be a power of two in [32, 1024], got " + std::to_string(patch_px));
  if (min_patches < 1 || min_patches > 1000)
    bad.push_back("min_patches must be in [1, 1000], got " + std::to_string(min_patches));
  if (!(min_response >= 0.0 && min_response <= 1.0))
    bad.push_back("min_response must be in [0, 1], got " + std::to_string(min_response));
  if (!(max_patch_spread_px > 0.0 && max_patch_spread_px <= 100.0))
    bad.push_back("max_patch_spread_px must be in (0, 100], got " + std::to_string(max_patch_spread_px));
  if (!(patch_sigma_px > 0.0 && patch_sigma_px <= 100.0))
    bad.push_back("patch_sigma_px must be in (0, 100], got " + std::to_string(patch_sigma_px));
  if (!(rotation_scale_sigma > 0.0 && rotation_scale_sigma <= 1.0))
    bad.push_back("rotation_scale_sigma must be in (0, 1], got " + std::to_string(rotation_scale_sigma));
  if (!(default_position_sigma_m > 0.0 && default_position_sigma_m <= 1000.0))
    bad.push_back("default_position_sigma_m must be in (0, 1000], got " + std::to_string(default_position_sigma_m));
  std::string out;
  for (const auto& b : bad) out += (out.empty() ? "" : "; ") + b;
  return out;
}

std::vector<std::string> listTiles(const std::string& folder, std::string* error) {
  // <prefix>_<NNNN>.tif, or <prefix>_<NNNN>_v<K>.tif for a tile drawn again: the highest version of each tile.
  std::map<std::string, std::pair<int, std::string>> newest;  // "<prefix>_<NNNN>" -> (version, path)
  std::error_code ec;
  const std::regex tile_name(R"(([A-Za-z0-9_.\-]+_[0-9]{4,})(_v([0-9]+))?\.tif)");
  for (const auto& entry : std::filesystem::directory_iterator(folder, ec)) {
    const std::string name = entry.path().filename().string();
    std::smatch match;
    if (!entry.is_regular_file() || name[0] == '.' || name.find(".cog.tif") != std::string::npos ||
        !std::regex_match(name, match, tile_name))
      continue;
    const int version = match[3].matched ? std::stoi(match[3].str()) : 1;
    auto& best = newest[match[1].str()];
    if (best.second.empty() || version > best.first) best = {version, entry.path().string()};
  }
  if (ec && error) *error = "cannot list '" + folder + "': " + ec.message();
  std::vector<std::string> paths;
  for (const auto& [base, tile] : newest) paths.push_back(tile.second);
  std::sort(paths.begin(), paths.end());
  return paths;
}

TileAdjustmentResult measureAndSolve(const std::vector<std::string>& paths, const TileAdjustmentConfig& config,
                                     TilePairCache* cache) {
  TileAdjustmentResult result;
  const std::string invalid = config.validate();
  if (!invalid.empty()) {
    result.error = "invalid tile adjustment configuration: " + invalid;
    return result;
  }
  for (const std::string& path : paths) {
    AdjustedTile tile;
    const std::string why = readTile(path, config, &tile);
    if (!why.empty()) {
      result.error = why;
      return result;
    }
    result.tiles.push_back(tile);
  }
  const int n = static_cast<int>(result.tiles.size());
  decltype(TilePairCache::pairs_) kept;  // this call's pairs: what the cache holds next
  for (int i = 0; i < n; ++i) {
    for (int j = i + 1; j < n; ++j) {
      const AdjustedTile &a = result.tiles[i], &b = result.tiles[j];
      if (a.epsg != b.epsg || std::abs(a.gsd_m - b.gsd_m) > 1e-9 * a.gsd_m) continue;
      const std::pair<std::string, std::string> key(a.path, b.path);
      std::optional<TilePairOffset> measured;
      const auto known = cache ? cache->pairs_.find(key) : kept.end();
      if (cache && known != cache->pairs_.end()) {
        measured = known->second;
        ++cache->reused_;
      } else {
        TilePairOffset pair;
        bool read_failed = false;
        if (measurePair(a, b, config, &pair, &read_failed)) measured = pair;
        if (cache) ++cache->measured_;
        if (read_failed) continue;  // not kept: measured again next time
      }
      if (cache) kept.emplace(key, measured);
      if (!measured) continue;
      measured->a = i;
      measured->b = j;
      result.pairs.push_back(*measured);
    }
  }
  if (cache) cache->pairs_.swap(kept);
  // Least squares over the 4 unknowns of each tile (shift E, N, scale, rotation): every patch's offset, after the
  // adjustment, is zero (weighed by the patch's area: a phase correlation's variance falls with it); the shifts within
  // the navigation's 1-sigma; rotation and scale within rotation_scale_sigma.
  for (AdjustedTile& t : result.tiles)
    t.centre_en_m = Eigen::Vector2d(t.origin_easting_m + 0.5 * t.width_px * t.gsd_m,
                                    t.origin_northing_m - 0.5 * t.height_px * t.gsd_m);
  if (n > 0) {
    std::vector<Eigen::Triplet<double>> entries;
    Eigen::VectorXd rhs = Eigen::VectorXd::Zero(4 * n);
    const double rs_weight = 1.0 / (config.rotation_scale_sigma * config.rotation_scale_sigma);
    for (int i = 0; i < n; ++i) {
      const double s = result.tiles[i].position_sigma_m;
      entries.emplace_back(4 * i, 4 * i, 1.0 / (s * s));
      entries.emplace_back(4 * i + 1, 4 * i + 1, 1.0 / (s * s));
      entries.emplace_back(4 * i + 2, 4 * i + 2, rs_weight);
      entries.emplace_back(4 * i + 3, 4 * i + 3, rs_weight);
    }
    // d(moved p) / d(shift E, shift N, scale, rotation) at p.
    auto jacobian = [&](int tile, const Eigen::Vector2d& p) {
      const Eigen::Vector2d d = p - result.tiles[tile].centre_en_m;
      Eigen::Matrix<double, 2, 4> j;
      j << 1, 0, d.x(), -d.y(), 0, 1, d.y(), d.x();
      return j;
    };
    for (const TilePairOffset& p : result.pairs) {
      const double g = result.tiles[p.a].gsd_m;
      for (const PatchOffset& o : p.patch_offsets) {
        const double sigma_m = config.patch_sigma_px * g * config.patch_px / o.patch_px;
        const double w = 1.0 / (sigma_m * sigma_m);
        Eigen::Matrix<double, 2, 8> jac;  // residual = offset + J_b q_b - J_a q_a
        jac << -jacobian(p.a, o.centre_en_m), jacobian(p.b, o.centre_en_m);
        const Eigen::Matrix<double, 8, 8> jtj = w * jac.transpose() * jac;
        const Eigen::Matrix<double, 8, 1> jtr = w * jac.transpose() * o.offset_en_m;
        const int base[2] = {4 * p.a, 4 * p.b};
        for (int r = 0; r < 8; ++r) {
          rhs(base[r / 4] + r % 4) -= jtr(r);
          for (int c = 0; c < 8; ++c) entries.emplace_back(base[r / 4] + r % 4, base[c / 4] + c % 4, jtj(r, c));
        }
      }
    }
    Eigen::SparseMatrix<double> h(4 * n, 4 * n);
    h.setFromTriplets(entries.begin(), entries.end());
    Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver(h);
    if (solver.info() != Eigen::Success) {
      result.error = "the tile network's normal equations cannot be factored";
      return result;
    }
    const Eigen::VectorXd q = solver.solve(rhs);
    for (int i = 0; i < n; ++i) {
      result.tiles[i].shift_en_m = q.segment<2>(4 * i);
      result.tiles[i].scale_change = q(4 * i + 2);
      result.tiles[i].rotation_rad = q(4 * i + 3);
    }
    for (TilePairOffset& p : result.pairs) {
      p.residual_en_m.setZero();
      for (const PatchOffset& o : p.patch_offsets) {
        const Eigen::Vector2d r = o.offset_en_m + (result.tiles[p.b].moved(o.centre_en_m) - o.centre_en_m) -
                                  (result.tiles[p.a].moved(o.centre_en_m) - o.centre_en_m);
        if (r.norm() > p.residual_en_m.norm()) p.residual_en_m = r;
      }
    }
  }
  result.ok = true;
  return result;
}

void writeAdjustedTiles(const std::string& output_dir, TileAdjustmentResult* result) {
  struct stat st;
  if (::stat(output_dir.c_str(), &st) != 0 || !S_ISDIR(st.st_mode)) {
    result->ok = false;
    result->error = "output folder '" + output_dir + "' is not an existing folder";
    return;
  }
  // A tile drawn again (<prefix>_<NNNN>_v<K>.tif) is adjusted into <prefix>_<NNNN>.tif: the adjusted folder holds one
  // version of each tile.
  const std::regex tile_name(R"((.+)_([0-9]{4,})(_v[0-9]+)?\.tif)");
  for (const AdjustedTile& tile : result->tiles) {
    auto fail = [&](const std::string& why) {
      result->ok = false;
      result->error = why;
    };
    const std::string name = baseName(tile.path);
    std::smatch match;
    if (!std::regex_match(name, match, tile_name)) return fail("'" + tile.path + "' is not named <prefix>_NNNN[_vK].tif");
    const std::string folder = tile.path.substr(0, tile.path.size() - name.size());
    char resolved_in[PATH_MAX], resolved_out[PATH_MAX];
    if (::realpath((folder.empty() ? "." : folder).c_str(), resolved_in) &&
        ::realpath(output_dir.c_str(), resolved_out) && std::string(resolved_in) == resolved_out)
      return fail("the output folder is the tiles' own: '" + output_dir + "'");
    DatasetPtr dataset = openTile(tile.path, false);
    if (!dataset) return fail("cannot open '" + tile.path + "': " + CPLGetLastErrorMsg());
    TileRaster raster;
    const std::string why = resampleTile(tile, dataset.get(), &raster);
    if (!why.empty()) return fail(why);
    // The live tile's metadata, but what the writer sets itself, and the adjustment.
    TileMetadata metadata;
    char** items = dataset->GetMetadata();
    for (int i = 0; items && items[i]; ++i) {
      const std::string item = items[i];
      const auto eq = item.find('=');
      if (eq == std::string::npos) continue;
      const std::string key = item.substr(0, eq);
      if (key == "TIFFTAG_DATETIME" || key == "TIFFTAG_SOFTWARE" || key == "AREA_OR_POINT" || key == "EXOCET_GSD_M")
        continue;
      metadata.extra[key] = item.substr(eq + 1);
    }
    metadata.extra["EXOCET_ADJUSTMENT_E_M"] = jsonNumber(tile.shift_en_m.x());
    metadata.extra["EXOCET_ADJUSTMENT_N_M"] = jsonNumber(tile.shift_en_m.y());
    metadata.extra["EXOCET_ADJUSTMENT_ROTATION_RAD"] = jsonNumber(tile.rotation_rad);
    metadata.extra["EXOCET_ADJUSTMENT_SCALE"] = jsonNumber(tile.scale_change);
    TileWriterConfig config;
    config.output_dir = output_dir;
    config.prefix = match[1].str();
    const char* compression = dataset->GetMetadataItem("COMPRESSION", "IMAGE_STRUCTURE");
    const std::string c = compression ? compression : "NONE";
    config.compression = c == "YCbCr JPEG" ? "JPEG" : (c == "DEFLATE" || c == "LZW" || c == "JPEG") ? c : "DEFLATE";
    dataset.reset();
    GeoTiffTileWriter writer(config);
    const WrittenTile written = writer.writeAt(raster, metadata, std::stoi(match[2].str()));
    if (!written.ok) return fail(written.error);
    result->written.push_back(written.geotiff_path);
  }
}

}  // namespace tiles
}  // namespace exocet_mosaic
