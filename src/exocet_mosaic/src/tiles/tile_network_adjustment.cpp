#include "exocet_mosaic/tiles/tile_network_adjustment.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <memory>
#include <sstream>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <Eigen/Sparse>
#include <cpl_conv.h>
#include <cpl_error.h>
#include <gdal_priv.h>
#include <ogr_spatialref.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

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

/// The offset of b's content from a's in their overlap (b minus a), or false when it cannot be measured.
bool measurePair(const AdjustedTile& a, const AdjustedTile& b, const TileAdjustmentConfig& config,
                 TilePairOffset* pair) {
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
  if (!readWindow(a, window_a, &grey_a, &alpha_a) || !readWindow(b, window_b, &grey_b, &alpha_b)) return false;

  // Band-passed: the lamp's shading differs between passes, the seabed's texture does not.
  for (cv::Mat* grey : {&grey_a, &grey_b}) {
    cv::Mat low;
    cv::GaussianBlur(*grey, low, cv::Size(0, 0), 12.0);
    *grey -= low;
  }
  // Phase correlation of the patches wholly inside both masks (a mask edge pulls the shift to zero); the shifts of
  // the patches that agree with their median.
  auto measurePatches = [&](const cv::Mat& b_grey, int p, std::vector<cv::Point2d>* shifts) {
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
        if (response >= config.min_response) shifts->push_back(s);
      }
    }
  };
  auto median = [](std::vector<double> v) {
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    return v[v.size() / 2];
  };
  auto agreeingMean = [&](const std::vector<cv::Point2d>& shifts, cv::Point2d* mean, int* count, double* spread) {
    if (static_cast<int>(shifts.size()) < config.min_patches) return false;
    std::vector<double> xs, ys, distances;
    for (const auto& s : shifts) xs.push_back(s.x), ys.push_back(s.y);
    const cv::Point2d m(median(xs), median(ys));
    *mean = cv::Point2d(0, 0);
    *count = 0;
    for (const auto& s : shifts) {
      distances.push_back(cv::norm(s - m));
      if (cv::norm(s - m) <= config.max_patch_spread_px) *mean += s, ++*count;
    }
    if (*count < config.min_patches) return false;
    *mean *= 1.0 / *count;
    *spread = median(distances);
    return true;
  };
  // Overlaps of adjacent lines are strips: smaller patches there (a patch holds shifts up to a quarter of its side).
  std::vector<cv::Point2d> shifts;
  int patch = 0;
  for (int p = config.patch_px; p >= 64 || p == config.patch_px; p /= 2) {
    if (width < p || height < p) continue;
    measurePatches(grey_b, p, &shifts);
    patch = p;
    if (static_cast<int>(shifts.size()) >= config.min_patches) break;
  }
  cv::Point2d mean;
  int count = 0;
  double spread = 0;
  if (!agreeingMean(shifts, &mean, &count, &spread)) return false;
  // The sub-pixel peak of a phase correlation is biased away from whole pixels (up to ~0.3 px): b resampled by the
  // estimate, the residual shift is near zero, where the peak is unbiased.
  for (int iteration = 0; iteration < 2; ++iteration) {
    const cv::Matx23d back(1, 0, mean.x, 0, 1, mean.y);  // b's window sampled at (x + dx, y + dy)
    cv::Mat shifted;
    cv::warpAffine(grey_b, shifted, back, grey_b.size(), cv::INTER_CUBIC | cv::WARP_INVERSE_MAP, cv::BORDER_REFLECT);
    measurePatches(shifted, patch, &shifts);
    cv::Point2d residual;
    int residual_count = 0;
    double residual_spread = 0;
    // A residual beyond the bias means the resampled patches no longer agree (a small overlap): keep the estimate.
    if (!agreeingMean(shifts, &residual, &residual_count, &residual_spread) || cv::norm(residual) > 0.5) break;
    mean += residual;
    count = residual_count;
  }
  // A feature at window pixel (x, y) of a is at (x + dx, y + dy) of b's window; b's window starts at its own UTM corner.
  const double window_b_e = b.origin_easting_m + col_b * g, window_b_n = b.origin_northing_m - row_b * g;
  pair->offset_en_m = Eigen::Vector2d(window_b_e - window_e + mean.x * g, window_b_n - window_n - mean.y * g);
  pair->patches = count;
  pair->patch_px = patch;
  pair->spread_px = spread;
  return true;
}

bool linkNoReplace(const std::string& from, const std::string& to) {
  if (::link(from.c_str(), to.c_str()) != 0) return false;
  ::unlink(from.c_str());
  return true;
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
  if (!(pair_sigma_px > 0.0 && pair_sigma_px <= 100.0))
    bad.push_back("pair_sigma_px must be in (0, 100], got " + std::to_string(pair_sigma_px));
  if (!(default_position_sigma_m > 0.0 && default_position_sigma_m <= 1000.0))
    bad.push_back("default_position_sigma_m must be in (0, 1000], got " + std::to_string(default_position_sigma_m));
  std::string out;
  for (const auto& b : bad) out += (out.empty() ? "" : "; ") + b;
  return out;
}

TileAdjustmentResult measureAndSolve(const std::vector<std::string>& paths, const TileAdjustmentConfig& config) {
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
  for (int i = 0; i < n; ++i) {
    for (int j = i + 1; j < n; ++j) {
      const AdjustedTile &a = result.tiles[i], &b = result.tiles[j];
      if (a.epsg != b.epsg || std::abs(a.gsd_m - b.gsd_m) > 1e-9 * a.gsd_m) continue;
      TilePairOffset pair;
      pair.a = i;
      pair.b = j;
      if (measurePair(a, b, config, &pair)) result.pairs.push_back(pair);
    }
  }
  // Least squares, each axis alike: sum over pairs of w (t_b - t_a + offset)^2 plus sum over tiles of (t_i / sigma_i)^2.
  if (n > 0) {
    Eigen::SparseMatrix<double> h(n, n);
    std::vector<Eigen::Triplet<double>> entries;
    Eigen::MatrixXd rhs = Eigen::MatrixXd::Zero(n, 2);
    for (int i = 0; i < n; ++i) {
      const double s = result.tiles[i].position_sigma_m;
      entries.emplace_back(i, i, 1.0 / (s * s));
    }
    for (const TilePairOffset& p : result.pairs) {
      // pair_sigma_px is the offset's 1-sigma from the overlap of two patch_px patches; a phase correlation's
      // variance falls with the area correlated, so a strip of small patches weighs less than a long overlap.
      const double sigma_m = config.pair_sigma_px * result.tiles[p.a].gsd_m;
      const double area = static_cast<double>(p.patches) * p.patch_px * p.patch_px /
                           (2.0 * config.patch_px * config.patch_px);
      const double w = area / (sigma_m * sigma_m);
      entries.emplace_back(p.a, p.a, w);
      entries.emplace_back(p.b, p.b, w);
      entries.emplace_back(p.a, p.b, -w);
      entries.emplace_back(p.b, p.a, -w);
      rhs.row(p.b) -= w * p.offset_en_m.transpose();
      rhs.row(p.a) += w * p.offset_en_m.transpose();
    }
    h.setFromTriplets(entries.begin(), entries.end());
    Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver(h);
    if (solver.info() != Eigen::Success) {
      result.error = "the tile network's normal equations cannot be factored";
      return result;
    }
    const Eigen::MatrixXd t = solver.solve(rhs);
    for (int i = 0; i < n; ++i) result.tiles[i].shift_en_m = t.row(i).transpose();
    for (TilePairOffset& p : result.pairs)
      p.residual_en_m = p.offset_en_m + result.tiles[p.b].shift_en_m - result.tiles[p.a].shift_en_m;
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
  for (const AdjustedTile& tile : result->tiles) {
    const std::string name = baseName(tile.path);
    const std::string final_path = output_dir + "/" + name;
    const std::string temporary = output_dir + "/." + name + ".partial";
    auto fail = [&](const std::string& why) {
      ::unlink(temporary.c_str());
      result->ok = false;
      result->error = why;
    };
    if (::stat(final_path.c_str(), &st) == 0) return fail("'" + final_path + "' exists: not overwritten");
    if (final_path == tile.path) return fail("the output folder is the tiles' own: '" + output_dir + "'");
    {
      std::ifstream in(tile.path, std::ios::binary);
      std::ofstream out(temporary, std::ios::binary | std::ios::trunc);
      out << in.rdbuf();
      out.flush();
      if (!in || !out) return fail("cannot copy '" + tile.path + "' to '" + temporary + "': " + std::strerror(errno));
    }
    {
      CPLErrorReset();
      DatasetPtr dataset = openTile(temporary, true);
      if (!dataset) return fail("cannot open '" + temporary + "' for update: " + CPLGetLastErrorMsg());
      double gt[6];
      dataset->GetGeoTransform(gt);
      gt[0] += tile.shift_en_m.x();
      gt[3] += tile.shift_en_m.y();
      dataset->SetGeoTransform(gt);
      dataset->SetMetadataItem("EXOCET_ADJUSTMENT_E_M", jsonNumber(tile.shift_en_m.x()).c_str());
      dataset->SetMetadataItem("EXOCET_ADJUSTMENT_N_M", jsonNumber(tile.shift_en_m.y()).c_str());
      dataset.reset();
      if (CPLGetLastErrorType() >= CE_Failure) return fail("cannot update '" + temporary + "': " + CPLGetLastErrorMsg());
    }
    const int fd = ::open(temporary.c_str(), O_RDONLY);
    if (fd >= 0) {
      ::fsync(fd);
      ::close(fd);
    }
    // The world file locates the centre of the top-left pixel.
    const double g = tile.gsd_m;
    std::string world;
    for (const double v : {g, 0.0, 0.0, -g, tile.origin_easting_m + tile.shift_en_m.x() + 0.5 * g,
                           tile.origin_northing_m + tile.shift_en_m.y() - 0.5 * g})
      world += jsonNumber(v) + "\n";
    const std::string world_name = name.substr(0, name.rfind('.')) + ".tfw";
    const std::string world_temporary = output_dir + "/." + world_name + ".partial";
    {
      std::ofstream out(world_temporary, std::ios::trunc);
      out << world;
      out.flush();
      if (!out) {
        ::unlink(world_temporary.c_str());
        return fail("cannot write '" + world_temporary + "': " + std::strerror(errno));
      }
    }
    if (!linkNoReplace(world_temporary, output_dir + "/" + world_name)) {
      ::unlink(world_temporary.c_str());
      return fail("cannot rename '" + world_temporary + "': " + std::strerror(errno));
    }
    if (!linkNoReplace(temporary, final_path))
      return fail("cannot rename '" + temporary + "' to '" + final_path + "': " + std::strerror(errno));
    result->written.push_back(final_path);
  }
}

}  // namespace tiles
}  // namespace exocet_mosaic
