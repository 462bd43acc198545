#include "exocet_web/tiles/web_tile_cutter.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <stdexcept>

#include <gdal.h>
#include <gdal_utils.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "gdal_support.h"

namespace exocet_web {
namespace tiles {

namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

double msSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

std::string number(double v) {
  char buffer[40];
  std::snprintf(buffer, sizeof(buffer), "%.17g", v);
  return buffer;
}

/// Writes `bytes` to `path` under a temporary name in the same folder, then renames it into place (no fsync: a web
/// tile lost in a crash is cut again at the next start).
void writeFileReplacing(const std::string& path, const std::vector<uchar>& bytes) {
  const fs::path final_path(path);
  const std::string temporary =
      (final_path.parent_path() / ("." + final_path.filename().string() + ".partial")).string();
  const int fd = ::open(temporary.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) throw std::runtime_error("cannot create '" + temporary + "': " + std::strerror(errno));
  size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const std::string why = n < 0 ? std::strerror(errno) : "nothing written";
      ::close(fd);
      std::remove(temporary.c_str());
      throw std::runtime_error("cannot write '" + temporary + "': " + why);
    }
    done += static_cast<size_t>(n);
  }
  if (::close(fd) != 0 || std::rename(temporary.c_str(), path.c_str()) != 0) {
    const std::string why = std::strerror(errno);
    std::remove(temporary.c_str());
    throw std::runtime_error("cannot write '" + path + "': " + why);
  }
}

/// `src` over `dst`, straight (not premultiplied) BGRA.
void compositeOver(const cv::Mat& src, cv::Mat dst) {
  for (int r = 0; r < src.rows; ++r) {
    const uchar* s = src.ptr<uchar>(r);
    uchar* d = dst.ptr<uchar>(r);
    for (int c = 0; c < src.cols; ++c, s += 4, d += 4) {
      const int sa = s[3];
      if (sa == 0) continue;
      if (sa == 255 || d[3] == 0) {
        std::memcpy(d, s, 4);
        continue;
      }
      const double a_s = sa / 255.0, a_d = d[3] / 255.0 * (1.0 - a_s);
      const double a = a_s + a_d;
      for (int k = 0; k < 3; ++k) d[k] = static_cast<uchar>(std::lround((s[k] * a_s + d[k] * a_d) / a));
      d[3] = static_cast<uchar>(std::lround(a * 255.0));
    }
  }
}

bool hasData(const cv::Mat& bgra) {
  for (int r = 0; r < bgra.rows; ++r) {
    const uchar* p = bgra.ptr<uchar>(r);
    for (int c = 0; c < bgra.cols; ++c)
      if (p[4 * c + 3] != 0) return true;
  }
  return false;
}

/// A tile's pixels as BGRA, from a PNG of 1 to 4 channels; empty when unreadable.
cv::Mat readTile(const std::string& path) {
  cv::Mat image = cv::imread(path, cv::IMREAD_UNCHANGED);
  if (image.empty() || image.depth() != CV_8U) return cv::Mat();
  cv::Mat bgra;
  switch (image.channels()) {
    case 4:
      bgra = image;
      break;
    case 3:
      cv::cvtColor(image, bgra, cv::COLOR_BGR2BGRA);
      break;
    case 1:
      cv::cvtColor(image, bgra, cv::COLOR_GRAY2BGRA);
      break;
    default:
      return cv::Mat();
  }
  return bgra;
}

}  // namespace

std::string CutterConfig::validate() const {
  std::vector<std::string> errors;
  if (output_dir.empty()) errors.push_back("output_dir is empty");
  if (max_zoom != -1 && (max_zoom < 1 || max_zoom > kMaxZoom))
    errors.push_back("max_zoom " + std::to_string(max_zoom) + " outside [1, 30] (or -1: automatic)");
  if (min_zoom != -1 && (min_zoom < 0 || min_zoom > kMaxZoom || (max_zoom >= 0 && min_zoom > max_zoom)))
    errors.push_back("min_zoom " + std::to_string(min_zoom) + " outside [0, max_zoom] (or -1: automatic)");
  if (png_compression < 0 || png_compression > 9)
    errors.push_back("png_compression " + std::to_string(png_compression) + " outside [0, 9]");
  if (block_tiles < 1 || block_tiles > 64)
    errors.push_back("block_tiles " + std::to_string(block_tiles) + " outside [1, 64]");
  static const std::vector<std::string> kResampling = {"near", "bilinear", "cubic", "lanczos", "average"};
  if (std::find(kResampling.begin(), kResampling.end(), resampling) == kResampling.end())
    errors.push_back("resampling '" + resampling + "' is not one of near, bilinear, cubic, lanczos, average");
  std::string joined;
  for (const auto& e : errors) joined += (joined.empty() ? "" : "; ") + e;
  return joined;
}

WebTileCutter::WebTileCutter(const CutterConfig& config) : config_(config) {
  const std::string error = config_.validate();
  if (!error.empty()) throw std::invalid_argument("web tile cutter: " + error);
  detail::registerGdalOnce();
}

std::string WebTileCutter::tilePath(const TileId& tile) const {
  return config_.output_dir + "/" + tile.path() + ".png";
}

std::vector<SourceTile> WebTileCutter::sources() const {
  std::vector<SourceTile> out;
  for (const auto& item : sources_) out.push_back(item.second);
  return out;
}

const SourceTile* WebTileCutter::source(const std::string& key) const {
  const auto it = sources_.find(key);
  return it == sources_.end() ? nullptr : &it->second;
}

MercatorBox WebTileCutter::surveyBounds() const {
  MercatorBox box;
  for (const auto& item : sources_) box = box.unitedWith(item.second.bounds);
  return box;
}

void WebTileCutter::adopt(const std::vector<SourceTile>& sources, int min_zoom, int max_zoom) {
  sources_.clear();
  tiles_.clear();
  for (const auto& s : sources) sources_[s.key] = s;
  max_zoom_ = max_zoom;
  min_zoom_ = min_zoom;
  std::error_code ec;
  for (int z = std::max(0, min_zoom); z <= max_zoom; ++z) {
    for (const auto& column : fs::directory_iterator(config_.output_dir + "/" + std::to_string(z), ec)) {
      int x = 0;
      try {
        x = std::stoi(column.path().filename().string());
      } catch (const std::exception&) {
        continue;
      }
      std::error_code ignored;
      for (const auto& file : fs::directory_iterator(column.path(), ignored)) {
        const std::string name = file.path().filename().string();
        if (name.size() < 5 || name[0] == '.' || name.compare(name.size() - 4, 4, ".png") != 0) continue;
        try {
          tiles_.insert({z, x, std::stoi(name.substr(0, name.size() - 4))});
        } catch (const std::exception&) {
        }
      }
    }
  }
}

CutReport WebTileCutter::update(const SourceTile& source, const FinestLevelCallback& on_finest_level) {
  MercatorBox dirty = source.bounds;
  const auto previous = sources_.find(source.key);
  if (previous != sources_.end()) dirty = dirty.unitedWith(previous->second.bounds);
  // A new tile above every other (the usual case during a dive: tiles come in index order) is drawn over the web
  // tiles as they are; otherwise everything under the dirty area is composited again from the GeoTIFFs.
  const bool on_top = previous == sources_.end() && (sources_.empty() || sources_.rbegin()->first < source.key);
  sources_[source.key] = source;
  if (max_zoom_ < 0) {
    try {
      max_zoom_ = config_.max_zoom >= 0 ? config_.max_zoom : nativeZoom(source.gsd_m, source.centre_latitude_deg);
    } catch (const std::exception& e) {
      sources_.erase(source.key);
      CutReport report;
      report.error = "'" + source.path + "': " + e.what();
      return report;
    }
    max_zoom_ = std::max(max_zoom_, 1);
    min_zoom_ = config_.min_zoom >= 0 ? std::min(config_.min_zoom, max_zoom_) : max_zoom_;
  }
  return recut(dirty, on_top ? source.key : std::string(), on_finest_level);
}

CutReport WebTileCutter::remove(const std::string& key) {
  const auto it = sources_.find(key);
  if (it == sources_.end()) {
    CutReport report;
    report.ok = true;
    return report;
  }
  const MercatorBox dirty = it->second.bounds;
  sources_.erase(it);
  return recut(dirty);
}

CutReport WebTileCutter::recut(const MercatorBox& dirty, const std::string& only_key,
                               const FinestLevelCallback& on_finest_level) {
  const auto start = Clock::now();
  CutReport report;
  try {
    const TileRange range = tilesCovering(dirty, max_zoom_);
    cutFinestLevel(range, only_key, &report);
    if (on_finest_level) {
      report.ok = report.error.empty();
      report.total_ms = msSince(start);
      on_finest_level(report);
    }
    std::set<TileId> level;
    for (const TileId& t : range.tiles()) level.insert(t);
    buildParents(std::move(level), min_zoom_, &report);
    lowerMinZoom(&report);
    report.ok = report.error.empty();
  } catch (const std::exception& e) {
    report.ok = false;
    report.error = e.what();
  }
  fresh_.clear();
  report.total_ms = msSince(start);
  return report;
}

void WebTileCutter::cutFinestLevel(const TileRange& range, const std::string& only_key, CutReport* report) {
  if (range.empty()) return;
  const double res_m = resolution_m_per_px(max_zoom_);
  const int n = config_.block_tiles;
  std::map<std::string, detail::DatasetPtr> opened;  // each GeoTIFF opened once per update
  detail::GdalErrors errors;
  for (int by = range.min_y; by <= range.max_y; by += n) {
    for (int bx = range.min_x; bx <= range.max_x; bx += n) {
      const int nx = std::min(n, range.max_x - bx + 1), ny = std::min(n, range.max_y - by + 1);
      const MercatorBox top_left = tileBounds({max_zoom_, bx, by});
      const MercatorBox bottom_right = tileBounds({max_zoom_, bx + nx - 1, by + ny - 1});
      const MercatorBox block{top_left.min_x_m, bottom_right.min_y_m, bottom_right.max_x_m, top_left.max_y_m};
      cv::Mat canvas(ny * kTileSize_px, nx * kTileSize_px, CV_8UC4, cv::Scalar::all(0));
      if (!only_key.empty()) {
        // What is under the new tile: the web tiles as they are.
        for (int ty = 0; ty < ny; ++ty)
          for (int tx = 0; tx < nx; ++tx) {
            const TileId id{max_zoom_, bx + tx, by + ty};
            if (!tiles_.count(id)) continue;
            const cv::Mat pixels = readTile(tilePath(id));
            if (pixels.rows != kTileSize_px || pixels.cols != kTileSize_px)
              throw std::runtime_error("cannot read the web tile '" + tilePath(id) + "'");
            pixels.copyTo(canvas(cv::Rect(tx * kTileSize_px, ty * kTileSize_px, kTileSize_px, kTileSize_px)));
          }
      }
      for (const auto& [key, source] : sources_) {
        if (!only_key.empty() && key != only_key) continue;
        const MercatorBox overlap = block.intersection(source.bounds);
        if (overlap.empty()) continue;
        // The overlap snapped outwards to the block's pixel grid.
        const int c0 = std::max(0, int(std::floor((overlap.min_x_m - block.min_x_m) / res_m)));
        const int c1 = std::min(canvas.cols, int(std::ceil((overlap.max_x_m - block.min_x_m) / res_m)));
        const int r0 = std::max(0, int(std::floor((block.max_y_m - overlap.max_y_m) / res_m)));
        const int r1 = std::min(canvas.rows, int(std::ceil((block.max_y_m - overlap.min_y_m) / res_m)));
        if (c1 <= c0 || r1 <= r0) continue;
        auto& dataset = opened[key];
        if (!dataset) {
          if (std::find(report->unreadable.begin(), report->unreadable.end(), key) != report->unreadable.end())
            continue;
          dataset.reset(GDALOpen(source.path.c_str(), GA_ReadOnly));
          if (!dataset) {
            errors.take();
            report->unreadable.push_back(key);
            continue;
          }
        }
        const double x0 = block.min_x_m + c0 * res_m, x1 = block.min_x_m + c1 * res_m;
        const double y1 = block.max_y_m - r0 * res_m, y0 = block.max_y_m - r1 * res_m;
        std::vector<std::string> args = {"-of", "MEM", "-t_srs", "EPSG:3857", "-te", number(x0), number(y0), number(x1),
                                         number(y1), "-ts", std::to_string(c1 - c0), std::to_string(r1 - r0), "-r",
                                         config_.resampling, "-dstalpha",
                                         // One chunk per warp: GDAL's default 64 MB splits a block and reads the
                                         // source again for each piece (twice as slow on a 2048-px block).
                                         "-wm", "512"};
        std::vector<char*> argv;
        for (auto& a : args) argv.push_back(a.data());
        argv.push_back(nullptr);
        std::unique_ptr<GDALWarpAppOptions, decltype(&GDALWarpAppOptionsFree)> options(
            GDALWarpAppOptionsNew(argv.data(), nullptr), &GDALWarpAppOptionsFree);
        if (!options) throw std::runtime_error("GDAL warp options refused: " + errors.take());
        const auto warp_start = Clock::now();
        GDALDatasetH source_handle = dataset.get();
        int usage_error = 0;
        detail::DatasetPtr warped(GDALWarp("", nullptr, 1, &source_handle, options.get(), &usage_error));
        report->warp_ms += msSince(warp_start);
        ++report->sources_warped;
        if (!warped) throw std::runtime_error("GDAL cannot warp '" + source.path + "': " + errors.take());
        const int bands = GDALGetRasterCount(warped.get());
        // Colour (RGB, or grey repeated) then the alpha band GDAL added last, into BGRA.
        int band_map[4] = {3, 2, 1, bands};
        if (bands == 2) band_map[0] = band_map[1] = band_map[2] = 1;
        if (bands != 2 && bands < 4) throw std::runtime_error("'" + source.path + "': unexpected band count");
        cv::Mat piece(r1 - r0, c1 - c0, CV_8UC4);
        if (GDALDatasetRasterIO(warped.get(), GF_Read, 0, 0, piece.cols, piece.rows, piece.data, piece.cols, piece.rows,
                                GDT_Byte, 4, band_map, 4, static_cast<int>(piece.step), 1) != CE_None)
          throw std::runtime_error("cannot read the warped '" + source.path + "': " + errors.take());
        compositeOver(piece, canvas(cv::Rect(c0, r0, piece.cols, piece.rows)));
      }
      for (int ty = 0; ty < ny; ++ty)
        for (int tx = 0; tx < nx; ++tx) {
          const cv::Mat tile = canvas(cv::Rect(tx * kTileSize_px, ty * kTileSize_px, kTileSize_px, kTileSize_px));
          store({max_zoom_, bx + tx, by + ty}, tile.data, tile.step, report);
        }
    }
  }
}

void WebTileCutter::buildParents(std::set<TileId> children, int down_to_zoom, CutReport* report) {
  while (!children.empty() && children.begin()->z > down_to_zoom) {
    std::set<TileId> parents;
    for (const TileId& child : children) parents.insert(parentOf(child));
    for (const TileId& parent : parents) buildParent(parent, report);
    children = std::move(parents);
  }
}

void WebTileCutter::buildParent(const TileId& parent, CutReport* report) {
  // Alpha-weighted 2 x 2 mean of the four children: no-data pixels do not darken the edges.
  cv::Mat out(kTileSize_px, kTileSize_px, CV_8UC4, cv::Scalar::all(0));
  for (int j = 0; j < 2; ++j) {
    for (int i = 0; i < 2; ++i) {
      const TileId child{parent.z + 1, 2 * parent.x + i, 2 * parent.y + j};
      if (!tiles_.count(child)) continue;
      const auto fresh = fresh_.find(child);
      const cv::Mat pixels = fresh != fresh_.end() ? fresh->second : readTile(tilePath(child));
      if (pixels.rows != kTileSize_px || pixels.cols != kTileSize_px)
        throw std::runtime_error("cannot read the web tile '" + tilePath(child) + "'");
      constexpr int kHalf = kTileSize_px / 2;
      for (int r = 0; r < kHalf; ++r) {
        const uchar* a = pixels.ptr<uchar>(2 * r);
        const uchar* b = pixels.ptr<uchar>(2 * r + 1);
        uchar* o = out.ptr<uchar>(j * kHalf + r) + 4 * i * kHalf;
        for (int c = 0; c < kHalf; ++c, o += 4) {
          const uchar* p[4] = {a + 8 * c, a + 8 * c + 4, b + 8 * c, b + 8 * c + 4};
          const int alpha = p[0][3] + p[1][3] + p[2][3] + p[3][3];
          if (alpha == 0) continue;
          for (int k = 0; k < 3; ++k)
            o[k] = static_cast<uchar>(
                (p[0][k] * p[0][3] + p[1][k] * p[1][3] + p[2][k] * p[2][3] + p[3][k] * p[3][3] + alpha / 2) / alpha);
          o[3] = static_cast<uchar>(std::max(1, (alpha + 2) / 4));  // a pixel with any data keeps some
        }
      }
    }
  }
  store(parent, out.data, out.step, report);
}

void WebTileCutter::lowerMinZoom(CutReport* report) {
  if (config_.min_zoom >= 0) return;
  const int fit = zoomFittingBox(surveyBounds(), max_zoom_);
  if (fit >= min_zoom_) return;
  std::set<TileId> level;
  for (const TileId& t : tiles_)
    if (t.z == min_zoom_) level.insert(t);
  buildParents(std::move(level), fit, report);
  min_zoom_ = fit;
}

void WebTileCutter::store(const TileId& tile, const void* bgra, size_t step_bytes, CutReport* report) {
  const cv::Mat pixels(kTileSize_px, kTileSize_px, CV_8UC4, const_cast<void*>(bgra), step_bytes);
  const std::string path = tilePath(tile);
  if (!hasData(pixels)) {
    if (tiles_.erase(tile)) {
      std::error_code ignored;
      fs::remove(path, ignored);
      report->removed.push_back(tile);
    }
    return;
  }
  std::vector<uchar> png;
  // Run-length matching only: as small as the default strategy on seabed pictures, a third faster.
  if (!cv::imencode(".png", pixels, png,
                    {cv::IMWRITE_PNG_COMPRESSION, config_.png_compression, cv::IMWRITE_PNG_STRATEGY,
                     cv::IMWRITE_PNG_STRATEGY_RLE}))
    throw std::runtime_error("cannot encode the web tile " + tile.path() + " as PNG");
  std::error_code ec;
  fs::create_directories(fs::path(path).parent_path(), ec);
  if (ec) throw std::runtime_error("cannot create the folder of '" + path + "': " + ec.message());
  writeFileReplacing(path, png);
  tiles_.insert(tile);
  fresh_[tile] = pixels.clone();  // its parent is made next: no need to decode it again
  report->written.push_back(tile);
}

}  // namespace tiles
}  // namespace exocet_web
