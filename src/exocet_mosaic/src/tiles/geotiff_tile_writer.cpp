#include "exocet_mosaic/tiles/geotiff_tile_writer.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <limits>
#include <memory>
#include <mutex>
#include <set>
#include <sstream>
#include <stdexcept>
#include <vector>

#include <dirent.h>
#include <fcntl.h>
#include <sys/stat.h>
#include <sys/statvfs.h>
#include <unistd.h>

#include <cpl_conv.h>
#include <cpl_error.h>
#include <gdal_alg.h>
#include <gdal_priv.h>
#include <gdal_utils.h>
#include <gdalwarper.h>
#include <ogr_spatialref.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "exocet_common/utm_grid.h"
#include "exocet_mosaic/tiles/tile_json.h"

namespace exocet_mosaic {
namespace tiles {

namespace {

constexpr int kOverviewThresholdPx = 1024;  // larger tiles get overviews, so that the GIS opens them fast

/// A failure of one step of write(): the message is the WrittenTile's error.
struct TileWriteError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

/// GDAL's block cache unless GDAL_CACHEMAX says otherwise: its default, 5 % of the machine's memory, fills over a long
/// dive and reads as a node that grows; a tile is written once and read back once for its overviews.
constexpr GIntBig kGdalCacheBytes = GIntBig(128) << 20;

void registerGdalOnce() {
  static std::once_flag once;
  std::call_once(once, [] {
    GDALAllRegister();
    if (CPLGetConfigOption("GDAL_CACHEMAX", nullptr) == nullptr) GDALSetCacheMax64(kGdalCacheBytes);
  });
}

/// Collects the GDAL errors raised in this thread while it lives (instead of GDAL printing them to stderr), so that
/// write() can put them into its error message.
class GdalErrorCollector {
 public:
  GdalErrorCollector() {
    CPLErrorReset();
    CPLPushErrorHandlerEx(&GdalErrorCollector::handle, this);
  }
  ~GdalErrorCollector() { CPLPopErrorHandler(); }
  GdalErrorCollector(const GdalErrorCollector&) = delete;
  GdalErrorCollector& operator=(const GdalErrorCollector&) = delete;

  bool failed() const { return !failures_.empty(); }
  /// The first distinct failures since the last take(), "; "-joined ("" if none), and forget them: libtiff repeats
  /// the same error for every block it could not write.
  std::string take() {
    constexpr size_t kMaxMessages = 3;
    std::vector<std::string> distinct;
    for (const auto& message : failures_) {
      if (std::find(distinct.begin(), distinct.end(), message) == distinct.end()) distinct.push_back(message);
    }
    std::string joined;
    for (size_t i = 0; i < std::min(distinct.size(), kMaxMessages); ++i) {
      joined += (joined.empty() ? "" : "; ") + distinct[i];
    }
    if (distinct.size() > kMaxMessages) joined += "; (" + std::to_string(distinct.size() - kMaxMessages) + " more)";
    failures_.clear();
    return joined;
  }

 private:
  static void CPL_STDCALL handle(CPLErr error_class, CPLErrorNum, const char* message) {
    auto* self = static_cast<GdalErrorCollector*>(CPLGetErrorHandlerUserData());
    if (self && error_class >= CE_Failure) self->failures_.emplace_back(message ? message : "unknown GDAL error");
  }
  std::vector<std::string> failures_;
};

/// Sets a GDAL configuration option for this thread only while it lives, then restores the previous value.
class ScopedGdalOption {
 public:
  ScopedGdalOption(const char* key, const std::string& value) : key_(key) {
    const char* previous = CPLGetThreadLocalConfigOption(key, nullptr);
    had_previous_ = previous != nullptr;
    if (had_previous_) previous_ = previous;
    CPLSetThreadLocalConfigOption(key, value.c_str());
  }
  ~ScopedGdalOption() { CPLSetThreadLocalConfigOption(key_, had_previous_ ? previous_.c_str() : nullptr); }
  ScopedGdalOption(const ScopedGdalOption&) = delete;
  ScopedGdalOption& operator=(const ScopedGdalOption&) = delete;

 private:
  const char* key_;
  bool had_previous_ = false;
  std::string previous_;
};

struct DatasetCloser {
  void operator()(GDALDataset* dataset) const {
    if (dataset) GDALClose(GDALDataset::ToHandle(dataset));
  }
};
using DatasetPtr = std::unique_ptr<GDALDataset, DatasetCloser>;

/// GDAL string lists ("KEY=VALUE") freed with the object.
class StringList {
 public:
  StringList() = default;
  ~StringList() { CSLDestroy(list_); }
  StringList(const StringList&) = delete;
  StringList& operator=(const StringList&) = delete;
  void set(const char* key, const std::string& value) { list_ = CSLSetNameValue(list_, key, value.c_str()); }
  void add(const std::string& item) { list_ = CSLAddString(list_, item.c_str()); }
  char** get() const { return list_; }

 private:
  char** list_ = nullptr;
};

std::string osError(int error_number) { return std::strerror(error_number); }

bool fileExists(const std::string& path) {
  struct stat st;
  return ::lstat(path.c_str(), &st) == 0;
}

/// Adds to a failed I/O step what the file system says: a full disk is the likely cause during a long dive.
std::string describeFileSystem(const std::string& folder) {
  struct statvfs fs;
  if (::statvfs(folder.c_str(), &fs) != 0) return "";
  const unsigned long long free_bytes = static_cast<unsigned long long>(fs.f_bavail) * fs.f_frsize;
  if (fs.f_flag & ST_RDONLY) return " (the file system of '" + folder + "' is read-only)";
  // Measured before the failed tile's temporaries are removed: a full disk shows (almost) nothing free.
  if (free_bytes < 256ull * 1024) {
    return " (No space left on device: " + std::to_string(free_bytes) + " bytes free on the file system of '" + folder +
           "')";
  }
  return "";
}

void fsyncPath(const std::string& path, const std::string& what) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw TileWriteError("cannot open " + what + " '" + path + "' to sync it: " + osError(errno));
  const int synced = ::fsync(fd);
  const int sync_errno = errno;
  ::close(fd);
  if (synced != 0) throw TileWriteError("cannot sync " + what + " '" + path + "' to disk: " + osError(sync_errno));
}

void writeTextFile(const std::string& path, const std::string& contents, const std::string& what) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) throw TileWriteError("cannot create " + what + " '" + path + "': " + osError(errno));
  size_t done = 0;
  while (done < contents.size()) {
    const ssize_t n = ::write(fd, contents.data() + done, contents.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const int write_errno = n < 0 ? errno : EIO;
      ::close(fd);
      throw TileWriteError("cannot write " + what + " '" + path + "': " + osError(write_errno));
    }
    done += static_cast<size_t>(n);
  }
  const int synced = ::fsync(fd);
  const int sync_errno = errno;
  if (::close(fd) != 0 || synced != 0) {
    throw TileWriteError("cannot write " + what + " '" + path + "': " + osError(synced != 0 ? sync_errno : errno));
  }
}

/// rename() that never replaces an existing file (another writer, or a tile a user put there since nextIndex()).
int renameNoReplace(const std::string& from, const std::string& to) {
  if (::renameat2(AT_FDCWD, from.c_str(), AT_FDCWD, to.c_str(), RENAME_NOREPLACE) == 0) return 0;
  if (errno != EINVAL && errno != ENOSYS) return -1;
  // The file system has no RENAME_NOREPLACE: link() fails with EEXIST just the same.
  if (::link(from.c_str(), to.c_str()) != 0) return -1;
  ::unlink(from.c_str());
  return 0;
}

std::string checkRaster(const TileRaster& raster) {
  std::vector<std::string> errors;
  if (raster.image.empty()) {
    errors.push_back("image is empty");
  } else if (raster.image.type() != CV_8UC3 && raster.image.type() != CV_8UC1) {
    errors.push_back("image type must be CV_8UC3 (BGR) or CV_8UC1, got " + std::to_string(raster.image.channels()) +
                     " channels of depth " + std::to_string(raster.image.depth()));
  }
  if (!raster.mask.empty() && (raster.mask.type() != CV_8UC1 || raster.mask.size() != raster.image.size())) {
    errors.push_back("mask must be empty or CV_8UC1 of the image's size");
  }
  if (!(raster.gsd_m > 0.0) || !std::isfinite(raster.gsd_m)) {
    errors.push_back("gsd_m must be finite and > 0, got " + jsonNumber(raster.gsd_m));
  }
  if (!std::isfinite(raster.origin_easting_m) || !std::isfinite(raster.origin_northing_m)) {
    errors.push_back("origin_easting_m and origin_northing_m must be finite");
  }
  if (raster.local_frame.empty() && (raster.utm_zone < 0 || raster.utm_zone > 60)) {
    errors.push_back("utm_zone must be in [0, 60] (1..60 UTM, 0 UPS), got " + std::to_string(raster.utm_zone));
  }
  std::string joined;
  for (const auto& e : errors) joined += (joined.empty() ? "" : "; ") + e;
  return joined;
}

/// Fills the UTM bounds and the WGS 84 bounding box: the outline is sampled, since its edges are curved in
/// latitude/longitude (and the box of the corners alone misses the bulge of the edges).
void computeBounds(const TileRaster& raster, WrittenTile* tile) {
  tile->min_easting_m = raster.origin_easting_m;
  tile->max_northing_m = raster.origin_northing_m;
  tile->max_easting_m = raster.origin_easting_m + raster.image.cols * raster.gsd_m;
  tile->min_northing_m = raster.origin_northing_m - raster.image.rows * raster.gsd_m;
  if (!raster.local_frame.empty()) {
    // Not geo-referenced: no latitude or longitude to give.
    tile->west_deg = tile->east_deg = tile->south_deg = tile->north_deg = std::numeric_limits<double>::quiet_NaN();
    return;
  }
  const auto grid = exocet_common::UtmGrid::fromZone(raster.utm_zone, raster.northern_hemisphere);
  const double centre_e = 0.5 * (tile->min_easting_m + tile->max_easting_m);
  const double centre_n = 0.5 * (tile->min_northing_m + tile->max_northing_m);
  // Longitudes unwrapped around the zone's central meridian (UTM) or the tile's centre (UPS): a tile crossing the
  // antimeridian keeps a continuous range.
  const double reference_lon_deg = grid.isUps() ? grid.toLatLon(centre_e, centre_n).y() : 6.0 * raster.utm_zone - 183.0;
  constexpr int kSamplesPerEdge = 32;
  const Eigen::Vector2d corners[4] = {{tile->min_easting_m, tile->max_northing_m},
                                      {tile->max_easting_m, tile->max_northing_m},
                                      {tile->max_easting_m, tile->min_northing_m},
                                      {tile->min_easting_m, tile->min_northing_m}};
  double west = 1e9, east = -1e9, south = 1e9, north = -1e9;
  for (int edge = 0; edge < 4; ++edge) {
    for (int k = 0; k < kSamplesPerEdge; ++k) {
      const double t = static_cast<double>(k) / kSamplesPerEdge;
      const Eigen::Vector2d point = (1.0 - t) * corners[edge] + t * corners[(edge + 1) % 4];
      const double e = point.x(), n = point.y();
      const Eigen::Vector2d lat_lon = grid.toLatLon(e, n);
      const double lon = reference_lon_deg + std::remainder(lat_lon.y() - reference_lon_deg, 360.0);
      west = std::min(west, lon);
      east = std::max(east, lon);
      south = std::min(south, lat_lon.x());
      north = std::max(north, lat_lon.x());
    }
  }
  if (grid.isUps()) {
    constexpr double kPoleGrid_m = 2000000.0;  // UPS false easting and northing: the pole
    if (tile->min_easting_m <= kPoleGrid_m && kPoleGrid_m <= tile->max_easting_m &&
        tile->min_northing_m <= kPoleGrid_m && kPoleGrid_m <= tile->max_northing_m) {
      west = -180.0;
      east = 180.0;
      (raster.northern_hemisphere ? north : south) = raster.northern_hemisphere ? 90.0 : -90.0;
    }
  }
  if (west < -180.0) {
    west += 360.0;
    east += 360.0;
  } else if (west >= 180.0) {
    west -= 360.0;
    east -= 360.0;
  }
  tile->west_deg = west;
  tile->east_deg = east;
  tile->south_deg = south;
  tile->north_deg = north;
}

std::string utcNowTiffDateTime() {
  const std::time_t now = std::time(nullptr);
  std::tm utc{};
  gmtime_r(&now, &utc);
  char text[32];
  std::strftime(text, sizeof(text), "%Y:%m:%d %H:%M:%S", &utc);  // the TIFF DateTime format
  return text;
}

/// Metadata key of an extra item: EXOCET_<KEY> in upper case with [A-Z0-9_] only (GDAL keys hold no '=' nor spaces).
std::string extraKey(const std::string& key) {
  if (key.rfind("EXOCET_", 0) == 0 || key.rfind("TIFFTAG_", 0) == 0) return key;
  std::string out = "EXOCET_";
  for (const char c : key) {
    const bool keep = (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_';
    const bool lower = c >= 'a' && c <= 'z';
    out += keep ? c : lower ? static_cast<char>(c - 'a' + 'A') : '_';
  }
  return out;
}

void setMetadata(GDALDataset* dataset, const TileMetadata& metadata, int index, double gsd_m) {
  const auto set = [&](const std::string& key, const std::string& value) {
    dataset->SetMetadataItem(key.c_str(), value.c_str());
  };
  set("TIFFTAG_SOFTWARE", metadata.software);
  set("TIFFTAG_DATETIME", utcNowTiffDateTime());
  if (!metadata.dive_name.empty()) set("TIFFTAG_DOCUMENTNAME", metadata.dive_name);
  std::ostringstream description;
  description << "Exocet seabed mosaic tile " << index;
  if (!metadata.dive_name.empty()) description << " of dive " << metadata.dive_name;
  description << ", frames " << metadata.first_frame << " to " << metadata.last_frame;
  set("TIFFTAG_IMAGEDESCRIPTION", description.str());
  set("EXOCET_TILE_INDEX", std::to_string(index));
  set("EXOCET_DIVE_NAME", metadata.dive_name);
  set("EXOCET_FIRST_FRAME", std::to_string(metadata.first_frame));
  set("EXOCET_LAST_FRAME", std::to_string(metadata.last_frame));
  set("EXOCET_START_TIME_S", jsonNumber(metadata.start_time_s));
  set("EXOCET_END_TIME_S", jsonNumber(metadata.end_time_s));
  if (std::isfinite(metadata.mean_altitude_m)) set("EXOCET_MEAN_ALTITUDE_M", jsonNumber(metadata.mean_altitude_m));
  set("EXOCET_CLOSE_REASON", metadata.close_reason);
  set("EXOCET_GSD_M", jsonNumber(gsd_m));
  for (const auto& item : metadata.extra) set(extraKey(item.first), item.second);
}

/// The files of one tile: temporaries while writing, final names after commit().
class TileFiles {
 public:
  explicit TileFiles(std::string folder) : folder_(std::move(folder)) {}
  /// Cleans up whatever has not been committed.
  ~TileFiles() { abort(); }

  /// Registers a file to write; returns its temporary path: "<folder>/.<final_name>.partial" by default.
  std::string add(const std::string& final_name, const std::string& temporary_name = "") {
    Entry entry{folder_ + "/" + final_name,
                folder_ + "/" + (temporary_name.empty() ? "." + final_name + ".partial" : temporary_name)};
    entries_.push_back(entry);
    return entry.temporary;
  }

  /// Renames every temporary to its final name, in order (so add the GeoTIFF last); on failure undoes the renames.
  void commit() {
    std::vector<std::string> renamed;
    for (const auto& entry : entries_) {
      if (renameNoReplace(entry.temporary, entry.final_path) != 0) {
        const int rename_errno = errno;
        for (const auto& done : renamed) ::unlink(done.c_str());
        throw TileWriteError("cannot rename '" + entry.temporary + "' to '" + entry.final_path +
                             "': " + osError(rename_errno) +
                             (rename_errno == EEXIST ? " (another writer uses this folder and prefix?)" : ""));
      }
      renamed.push_back(entry.final_path);
    }
    // The renames themselves are durable once the folder is synced.
    const int fd = ::open(folder_.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (fd >= 0) {
      ::fsync(fd);
      ::close(fd);
    }
    entries_.clear();
  }

  void abort() {
    for (const auto& entry : entries_) removeTemporary(entry.temporary);
    entries_.clear();
  }

  /// Gives up one file (its temporary and side-cars removed): the others are committed without it.
  void drop(const std::string& temporary) {
    for (auto it = entries_.begin(); it != entries_.end(); ++it) {
      if (it->temporary != temporary) continue;
      removeTemporary(it->temporary);
      entries_.erase(it);
      return;
    }
  }

 private:
  struct Entry {
    std::string final_path;
    std::string temporary;
  };
  static void removeTemporary(const std::string& temporary) {
    // GDAL side-cars are disabled (PAM off, internal mask), but a driver may still leave one. A directory in the
    // way of a temporary (rmdir) is not this writer's to remove: unlink fails on it and it stays.
    for (const char* sidecar : {"", ".aux.xml", ".msk", ".ovr", ".ovr.tmp", ".msk.ovr.tmp"}) {
      ::unlink((temporary + sidecar).c_str());
    }
  }
  std::string folder_;
  std::vector<Entry> entries_;
};

/// Overview factors 2, 4, ... down to about one block, or none for a tile small enough to open without them.
std::vector<int> overviewLevels(int width, int height, int block_size_px) {
  std::vector<int> levels;
  if (std::max(width, height) <= kOverviewThresholdPx) return levels;
  for (int level = 2;; level *= 2) {
    levels.push_back(level);
    if ((std::max(width, height) + level - 1) / level <= block_size_px) break;
  }
  return levels;
}

/**
 * Fills the overviews (created empty) of a GeoTIFF whose last band is an alpha band, from its pixels in memory
 * (`pixels`: the file's band order, interleaved, CV_8UC(bands)). Each level is the area average of the one above,
 * colour weighted by alpha (GDAL's AVERAGE with a mask): GDAL would instead read the whole tile back and decompress it,
 * which took as long as writing it.
 */
void writeOverviewsFromMemory(GDALDataset* dataset, const cv::Mat& pixels, const std::string& path,
                              GdalErrorCollector* errors) {
  const int bands = pixels.channels();
  const int alpha_band = bands - 1;
  // Premultiplied by alpha (8 bits: the rounding only shows at the partly covered edge pixels), so that no-data
  // pixels do not darken the edges of the overviews; each level is then an area average of the one above.
  cv::Mat level(pixels.size(), pixels.type());
  for (int y = 0; y < pixels.rows; ++y) {
    const uchar* in = pixels.ptr<uchar>(y);
    uchar* out = level.ptr<uchar>(y);
    for (int x = 0; x < pixels.cols; ++x, in += bands, out += bands) {
      const int a = in[alpha_band];
      for (int c = 0; c < alpha_band; ++c) out[c] = a == 255 ? in[c] : static_cast<uchar>((in[c] * a + 127) / 255);
      out[alpha_band] = static_cast<uchar>(a);
    }
  }
  GDALRasterBand* first = dataset->GetRasterBand(1);
  cv::Mat smaller, out;
  for (int i = 0; i < first->GetOverviewCount(); ++i) {
    GDALRasterBand* overview_band = first->GetOverview(i);
    GDALDataset* overview = overview_band ? overview_band->GetDataset() : nullptr;
    if (!overview || overview->GetRasterCount() != bands)
      throw TileWriteError("cannot fill overview " + std::to_string(i) + " of '" + path + "': no overview dataset");
    const cv::Size size(overview->GetRasterXSize(), overview->GetRasterYSize());
    cv::resize(level, smaller, size, 0, 0, cv::INTER_AREA);
    cv::swap(level, smaller);
    // Back to straight colour (GDAL's AVERAGE with a mask: the mean of the pixels with data).
    level.copyTo(out);
    for (int y = 0; y < out.rows; ++y) {
      uchar* p = out.ptr<uchar>(y);
      for (int x = 0; x < out.cols; ++x, p += bands) {
        const int a = p[alpha_band];
        if (a == 255 || a == 0) continue;
        for (int c = 0; c < alpha_band; ++c) p[c] = static_cast<uchar>(std::min(255, (p[c] * 255 + a / 2) / a));
      }
    }
    if (overview->RasterIO(GF_Write, 0, 0, size.width, size.height, out.data, size.width, size.height, GDT_Byte, bands,
                           nullptr, bands, static_cast<GSpacing>(out.step), 1, nullptr) != CE_None)
      throw TileWriteError("cannot write overview " + std::to_string(i) + " of '" + path + "': " + errors->take());
  }
}

/// Writes the GeoTIFF itself to `path`: pixels in RGB(A) band order, georeferencing, metadata, overviews.
void writeGeoTiff(const TileWriterConfig& config, const TileRaster& raster, const TileMetadata& metadata,
                  const WrittenTile& tile, const std::string& path, GdalErrorCollector* errors) {
  const bool colour = raster.image.channels() == 3;
  const bool jpeg = config.compression == "JPEG";
  // JPEG cannot compress an alpha band with YCbCr: the no-data goes to an internal 1-bit mask instead.
  const int data_bands = colour ? 3 : 1;
  const int bands = jpeg ? data_bands : data_bands + 1;
  const int width = raster.image.cols, height = raster.image.rows;

  StringList options;
  options.set("TILED", "YES");
  options.set("BLOCKXSIZE", std::to_string(config.block_size_px));
  options.set("BLOCKYSIZE", std::to_string(config.block_size_px));
  options.set("COMPRESS", config.compression);
  if (config.compression == "DEFLATE" || config.compression == "LZW") options.set("PREDICTOR", "2");
  if (config.compression == "DEFLATE") options.set("ZLEVEL", std::to_string(config.deflate_level));
  options.set("BIGTIFF", "IF_SAFER");
  options.set("INTERLEAVE", "PIXEL");
  if (colour) {
    options.set("PHOTOMETRIC", jpeg ? "YCBCR" : "RGB");
  } else {
    options.set("PHOTOMETRIC", "MINISBLACK");
  }
  if (!jpeg) options.set("ALPHA", "UNASSOCIATED");

  GDALDriver* driver = GetGDALDriverManager()->GetDriverByName("GTiff");
  if (!driver) throw TileWriteError("GDAL has no GTiff driver");
  DatasetPtr dataset(driver->Create(path.c_str(), width, height, bands, GDT_Byte, options.get()));
  if (!dataset) throw TileWriteError("cannot create GeoTIFF '" + path + "': " + errors->take());

  double geotransform[6] = {raster.origin_easting_m, raster.gsd_m, 0.0, raster.origin_northing_m, 0.0, -raster.gsd_m};
  dataset->SetGeoTransform(geotransform);
  OGRSpatialReference srs;
  if (!raster.local_frame.empty()) {
    // An engineering CRS: QGIS opens the tile in metres, and its name says which frame and that it has no geodetic
    // datum.
    const std::string name =
        "Exocet local frame '" + raster.local_frame + "' (metres, x east, y north; not geo-referenced)";
    if (srs.SetLocalCS(name.c_str()) != OGRERR_NONE || srs.SetLinearUnits(SRS_UL_METER, 1.0) != OGRERR_NONE)
      throw TileWriteError("cannot make the local CRS of frame '" + raster.local_frame + "': " + errors->take());
  } else if (srs.importFromEPSG(tile.epsg) != OGRERR_NONE) {
    throw TileWriteError("the PROJ database does not know EPSG:" + std::to_string(tile.epsg) + ": " + errors->take());
  }
  srs.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);  // easting first, as the geotransform
  dataset->SetSpatialRef(&srs);
  setMetadata(dataset.get(), metadata, tile.index, raster.gsd_m);
  if (colour) {
    dataset->GetRasterBand(1)->SetColorInterpretation(GCI_RedBand);
    dataset->GetRasterBand(2)->SetColorInterpretation(GCI_GreenBand);
    dataset->GetRasterBand(3)->SetColorInterpretation(GCI_BlueBand);
  } else {
    dataset->GetRasterBand(1)->SetColorInterpretation(GCI_GrayIndex);
  }
  if (!jpeg) dataset->GetRasterBand(bands)->SetColorInterpretation(GCI_AlphaBand);
  GDALRasterBand* mask_band = nullptr;
  if (jpeg) {
    if (dataset->CreateMaskBand(GMF_PER_DATASET) != CE_None) {
      throw TileWriteError("cannot create the no-data mask of '" + path + "': " + errors->take());
    }
    mask_band = dataset->GetRasterBand(1)->GetMaskBand();
  }
  if (errors->failed()) throw TileWriteError("cannot set up GeoTIFF '" + path + "': " + errors->take());

  // One row of blocks at a time, all bands interleaved as the file stores them: each block is compressed once. With
  // an alpha band the interleaved pixels are kept whole, for the overviews.
  const std::vector<int> levels = overviewLevels(width, height, config.block_size_px);
  const bool overviews_from_memory = !jpeg && !levels.empty();
  cv::Mat pixels;
  if (overviews_from_memory) pixels.create(height, width, CV_8UC(bands));
  const int strip_rows = config.block_size_px;
  cv::Mat strip, alpha;
  for (int row = 0; row < height; row += strip_rows) {
    const int rows = std::min(strip_rows, height - row);
    const cv::Rect roi(0, row, width, rows);
    const cv::Mat image = raster.image(roi);
    if (raster.mask.empty()) {
      alpha = cv::Mat(rows, width, CV_8UC1, cv::Scalar(255));
    } else {
      cv::compare(raster.mask(roi), 0, alpha, cv::CMP_NE);  // any nonzero mask value is data: alpha 255
    }
    if (overviews_from_memory)
      strip = pixels(roi);
    else
      strip.create(rows, width, CV_8UC(bands));
    if (colour) {
      // OpenCV's BGR to the file's RGB(A).
      const cv::Mat sources[] = {image, alpha};
      const int from_to_rgba[] = {2, 0, 1, 1, 0, 2, 3, 3};
      cv::mixChannels(sources, 2, &strip, 1, from_to_rgba, bands);
    } else if (!jpeg) {
      const cv::Mat sources[] = {image, alpha};
      const int from_to_ga[] = {0, 0, 1, 1};
      cv::mixChannels(sources, 2, &strip, 1, from_to_ga, 2);
    } else {
      image.copyTo(strip);
    }
    if (dataset->RasterIO(GF_Write, 0, row, width, rows, strip.data, width, rows, GDT_Byte, bands, nullptr, bands,
                          static_cast<GSpacing>(strip.step), 1, nullptr) != CE_None) {
      throw TileWriteError("cannot write the pixels of '" + path + "': " + errors->take());
    }
    if (mask_band && mask_band->RasterIO(GF_Write, 0, row, width, rows, alpha.data, width, rows, GDT_Byte, 1,
                                         static_cast<GSpacing>(alpha.step), nullptr) != CE_None) {
      throw TileWriteError("cannot write the no-data mask of '" + path + "': " + errors->take());
    }
  }

  if (!levels.empty()) {
    // "NONE" creates the overviews without computing them: they are filled from memory (JPEG: GDAL's AVERAGE, which
    // also handles the internal mask).
    std::vector<int> factors = levels;
    if (GDALBuildOverviews(GDALDataset::ToHandle(dataset.get()), overviews_from_memory ? "NONE" : "AVERAGE",
                           static_cast<int>(factors.size()), factors.data(), 0, nullptr, nullptr, nullptr) != CE_None) {
      throw TileWriteError("cannot build the overviews of '" + path + "': " + errors->take());
    }
    if (overviews_from_memory) writeOverviewsFromMemory(dataset.get(), pixels, path, errors);
    if (errors->failed()) throw TileWriteError("cannot write the overviews of '" + path + "': " + errors->take());
  }
  dataset.reset();  // flushes and closes: write errors of the last blocks show up here
  if (errors->failed()) throw TileWriteError("cannot write GeoTIFF '" + path + "': " + errors->take());
  fsyncPath(path, "GeoTIFF");
}

DatasetPtr openWritten(const std::string& path, GdalErrorCollector* errors) {
  const char* const drivers[] = {"GTiff", nullptr};
  DatasetPtr dataset(
      GDALDataset::FromHandle(GDALOpenEx(path.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY, drivers, nullptr, nullptr)));
  if (!dataset) throw TileWriteError("cannot read back GeoTIFF '" + path + "': " + errors->take());
  return dataset;
}

void writeCog(const TileWriterConfig& config, GDALDataset* source, const std::string& path,
              GdalErrorCollector* errors) {
  GDALDriver* driver = GetGDALDriverManager()->GetDriverByName("COG");
  if (!driver) throw TileWriteError("GDAL has no COG driver (GDAL >= 3.1 needed)");
  StringList options;
  options.set("COMPRESS", config.compression);
  if (config.compression == "DEFLATE" || config.compression == "LZW") options.set("PREDICTOR", "YES");
  if (config.compression == "DEFLATE") options.set("LEVEL", std::to_string(config.deflate_level));
  options.set("BLOCKSIZE", std::to_string(config.block_size_px));
  options.set("BIGTIFF", "IF_SAFER");
  options.set("RESAMPLING", "AVERAGE");
  options.set("OVERVIEWS", "AUTO");  // reuses the GeoTIFF's overviews when it has some
  DatasetPtr cog(driver->CreateCopy(path.c_str(), source, FALSE, options.get(), nullptr, nullptr));
  if (!cog) throw TileWriteError("cannot write COG '" + path + "': " + errors->take());
  cog.reset();
  if (errors->failed()) throw TileWriteError("cannot write COG '" + path + "': " + errors->take());
  fsyncPath(path, "COG");
}

/// Warps the tile to WGS 84 (downsampled to at most kmz_max_side_px) and writes a KML super-overlay with PNG images
/// (transparent where there is no data).
void writeKmz(const TileWriterConfig& config, GDALDataset* source, const std::string& name, const std::string& path,
              GdalErrorCollector* errors) {
  OGRSpatialReference wgs84;
  wgs84.SetWellKnownGeogCS("WGS84");
  wgs84.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
  char* wgs84_wkt = nullptr;
  wgs84.exportToWkt(&wgs84_wkt);
  const std::string dst_wkt = wgs84_wkt ? wgs84_wkt : "";
  CPLFree(wgs84_wkt);

  // The natural size of the warped raster, then at most kmz_max_side_px.
  StringList transformer_options;
  transformer_options.set("DST_SRS", dst_wkt);
  void* transformer =
      GDALCreateGenImgProjTransformer2(GDALDataset::ToHandle(source), nullptr, transformer_options.get());
  if (!transformer) throw TileWriteError("cannot transform the tile to WGS 84: " + errors->take());
  double geotransform[6];
  double extent[4];
  int width = 0, height = 0;
  const CPLErr suggested = GDALSuggestedWarpOutput2(GDALDataset::ToHandle(source), GDALGenImgProjTransform, transformer,
                                                    geotransform, &width, &height, extent, 0);
  GDALDestroyGenImgProjTransformer(transformer);
  if (suggested != CE_None || width <= 0 || height <= 0) {
    throw TileWriteError("cannot size the WGS 84 raster of the KMZ: " + errors->take());
  }
  const double shrink = std::max(1.0, static_cast<double>(std::max(width, height)) / config.kmz_max_side_px);
  width = std::max(1, static_cast<int>(std::lround(width / shrink)));
  height = std::max(1, static_cast<int>(std::lround(height / shrink)));

  StringList warp_arguments;
  for (const std::string& argument :
       {std::string("-of"), std::string("MEM"), std::string("-t_srs"), dst_wkt, std::string("-te"),
        jsonNumber(extent[0]), jsonNumber(extent[1]), jsonNumber(extent[2]), jsonNumber(extent[3]), std::string("-ts"),
        std::to_string(width), std::to_string(height), std::string("-r"),
        std::string(shrink > 1.0 ? "average" : "bilinear"), std::string("-dstalpha")}) {
    warp_arguments.add(argument);
  }
  GDALWarpAppOptions* warp_options = GDALWarpAppOptionsNew(warp_arguments.get(), nullptr);
  if (!warp_options) throw TileWriteError("bad warp options for the KMZ: " + errors->take());
  GDALDatasetH source_handle = GDALDataset::ToHandle(source);
  int usage_error = FALSE;
  DatasetPtr warped(GDALDataset::FromHandle(GDALWarp("", nullptr, 1, &source_handle, warp_options, &usage_error)));
  GDALWarpAppOptionsFree(warp_options);
  if (!warped) throw TileWriteError("cannot warp the tile to WGS 84 for the KMZ: " + errors->take());
  if (warped->GetRasterCount() == 2) {
    // A grey tile (grey and alpha): the super-overlay driver takes 1, 3 or 4 bands and refuses 2 without a word.
    StringList rgba_arguments;
    for (const char* argument : {"-of", "MEM", "-b", "1", "-b", "1", "-b", "1", "-b", "2", "-colorinterp",
                                 "red,green,blue,alpha"})
      rgba_arguments.add(argument);
    GDALTranslateOptions* rgba_options = GDALTranslateOptionsNew(rgba_arguments.get(), nullptr);
    if (!rgba_options) throw TileWriteError("bad options for the KMZ's RGBA raster: " + errors->take());
    DatasetPtr rgba(
        GDALDataset::FromHandle(GDALTranslate("", GDALDataset::ToHandle(warped.get()), rgba_options, &usage_error)));
    GDALTranslateOptionsFree(rgba_options);
    if (!rgba) throw TileWriteError("cannot make the KMZ's RGBA raster from a grey tile: " + errors->take());
    warped = std::move(rgba);
  }
  if (warped->GetRasterCount() != 3 && warped->GetRasterCount() != 4)
    throw TileWriteError("the KMZ's raster has " + std::to_string(warped->GetRasterCount()) +
                         " bands; the KML super-overlay takes 3 (RGB) or 4 (RGBA)");

  GDALDriver* driver = GetGDALDriverManager()->GetDriverByName("KMLSUPEROVERLAY");
  if (!driver) throw TileWriteError("GDAL has no KMLSUPEROVERLAY driver");
  StringList options;
  options.set("FORMAT", "PNG");  // PNG keeps the no-data transparent
  options.set("NAME", name);
  DatasetPtr kmz(driver->CreateCopy(path.c_str(), warped.get(), FALSE, options.get(), nullptr, nullptr));
  if (!kmz) throw TileWriteError("cannot write KMZ '" + path + "': " + errors->take());
  kmz.reset();
  if (errors->failed()) throw TileWriteError("cannot write KMZ '" + path + "': " + errors->take());
  fsyncPath(path, "KMZ");
}

std::string worldFileText(const TileRaster& raster) {
  // The world file locates the CENTRE of the top-left pixel (the geotransform its corner).
  std::string text;
  for (const double value : {raster.gsd_m, 0.0, 0.0, -raster.gsd_m, raster.origin_easting_m + 0.5 * raster.gsd_m,
                             raster.origin_northing_m - 0.5 * raster.gsd_m}) {
    text += jsonNumber(value) + "\n";
  }
  return text;
}

}  // namespace

std::string TileWriterConfig::validate() const {
  std::vector<std::string> errors;
  if (output_dir.empty()) errors.push_back("output_dir must not be empty");
  const bool prefix_chars_ok = std::all_of(prefix.begin(), prefix.end(), [](char c) {
    return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_' || c == '-' ||
           c == '.';
  });
  if (prefix.empty() || prefix.size() > 64 || !prefix_chars_ok || prefix[0] == '.') {
    errors.push_back("prefix '" + prefix + "' must be 1..64 characters of [A-Za-z0-9_-.], not starting with '.'");
  }
  if (compression != "DEFLATE" && compression != "LZW" && compression != "JPEG" && compression != "NONE") {
    errors.push_back("compression '" + compression + "' must be one of DEFLATE, LZW, JPEG, NONE");
  }
  if (deflate_level < 1 || deflate_level > 9) {
    errors.push_back("deflate_level " + std::to_string(deflate_level) + " must be in [1, 9]");
  }
  if (block_size_px < 16 || block_size_px > 4096 || block_size_px % 16 != 0) {
    errors.push_back("block_size_px " + std::to_string(block_size_px) + " must be a multiple of 16 in [16, 4096]");
  }
  if (kmz_max_side_px < 256 || kmz_max_side_px > 32768) {
    errors.push_back("kmz_max_side_px " + std::to_string(kmz_max_side_px) + " must be in [256, 32768]");
  }
  std::string joined;
  for (const auto& e : errors) joined += (joined.empty() ? "" : "; ") + e;
  return joined;
}

int epsgForUtm(int zone, bool northern) { return exocet_common::UtmGrid::fromZone(zone, northern).epsg(); }

GeoTiffTileWriter::GeoTiffTileWriter(const TileWriterConfig& config) : config_(config) {
  const std::string error = config_.validate();
  if (!error.empty()) throw std::invalid_argument("invalid tile writer configuration: " + error);
  while (config_.output_dir.size() > 1 && config_.output_dir.back() == '/') config_.output_dir.pop_back();
  registerGdalOnce();
}

std::string GeoTiffTileWriter::baseName(int index) const {
  char number[16];
  std::snprintf(number, sizeof(number), "%04d", index);
  return config_.prefix + "_" + number;
}

std::string GeoTiffTileWriter::baseName(int index, int version) const {
  return version <= 1 ? baseName(index) : baseName(index) + "_v" + std::to_string(version);
}

int GeoTiffTileWriter::nextIndex() const {
  // Indices of later versions (<prefix>_<NNNN>_v<K>.*) count too: their first version is gone.
  std::set<int> versioned;
  if (DIR* folder = ::opendir(config_.output_dir.c_str())) {
    const std::string start = config_.prefix + "_";
    while (const dirent* entry = ::readdir(folder)) {
      const std::string name = entry->d_name;
      if (name.rfind(start, 0) != 0) continue;
      const std::string rest = name.substr(start.size());
      std::size_t digits = 0;
      while (digits < rest.size() && std::isdigit(static_cast<unsigned char>(rest[digits]))) ++digits;
      if (digits >= 4 && rest.compare(digits, 2, "_v") == 0) versioned.insert(std::stoi(rest.substr(0, digits)));
    }
    ::closedir(folder);
  }
  for (int index = 0;; ++index) {
    const std::string base = config_.output_dir + "/" + baseName(index);
    bool used = versioned.count(index) > 0;
    for (const char* extension : {".tif", ".tfw", ".cog.tif", ".kmz"}) used = used || fileExists(base + extension);
    if (!used) return index;
  }
}

int GeoTiffTileWriter::removeVersion(int index, int version) const {
  int removed = 0;
  const std::string base = config_.output_dir + "/" + baseName(index, version);
  for (const char* extension : {".tif", ".tfw", ".cog.tif", ".kmz"})
    if (::unlink((base + extension).c_str()) == 0) ++removed;
  return removed;
}

int GeoTiffTileWriter::removeStaleTemporaries() const {
  DIR* folder = ::opendir(config_.output_dir.c_str());
  if (!folder) return 0;
  const std::string start = "." + config_.prefix + "_";
  std::vector<std::string> stale;
  while (const dirent* entry = ::readdir(folder)) {
    const std::string name = entry->d_name;
    if (name.rfind(start, 0) == 0 && name.find(".partial") != std::string::npos) stale.push_back(name);
  }
  ::closedir(folder);
  int removed = 0;
  for (const auto& name : stale) {
    if (::unlink((config_.output_dir + "/" + name).c_str()) == 0) ++removed;
  }
  return removed;
}

int GeoTiffTileWriter::removeIncompleteTiles() const {
  DIR* folder = ::opendir(config_.output_dir.c_str());
  if (!folder) return 0;
  const std::string start = config_.prefix + "_";
  std::vector<std::string> orphans;
  while (const dirent* entry = ::readdir(folder)) {
    const std::string name = entry->d_name;
    if (name.rfind(start, 0) != 0) continue;
    // <prefix>_<NNNN>[_v<K>]<companion extension>
    std::size_t end = start.size();
    while (end < name.size() && std::isdigit(static_cast<unsigned char>(name[end]))) ++end;
    if (end - start.size() < 4) continue;
    if (name.compare(end, 2, "_v") == 0) {
      std::size_t digits = end + 2;
      while (digits < name.size() && std::isdigit(static_cast<unsigned char>(name[digits]))) ++digits;
      if (digits == end + 2) continue;
      end = digits;
    }
    const std::string extension = name.substr(end);
    if (extension != ".tfw" && extension != ".cog.tif" && extension != ".kmz") continue;
    if (!fileExists(config_.output_dir + "/" + name.substr(0, end) + ".tif")) orphans.push_back(name);
  }
  ::closedir(folder);
  int removed = 0;
  for (const auto& name : orphans)
    if (::unlink((config_.output_dir + "/" + name).c_str()) == 0) ++removed;
  return removed;
}

WrittenTile GeoTiffTileWriter::write(const TileRaster& raster, const TileMetadata& metadata) {
  return writeAt(raster, metadata, -1);
}

WrittenTile GeoTiffTileWriter::writeAt(const TileRaster& raster, const TileMetadata& metadata, int index) {
  return writeFiles(raster, metadata, index, 1);
}

WrittenTile GeoTiffTileWriter::writeVersion(const TileRaster& raster, const TileMetadata& metadata, int index,
                                            int version) {
  if (index < 0 || version < 2) {
    WrittenTile tile;
    tile.error = "writeVersion: index must be >= 0 and version >= 2 (got index " + std::to_string(index) +
                 ", version " + std::to_string(version) + ")";
    return tile;
  }
  TileMetadata versioned = metadata;
  versioned.extra["EXOCET_TILE_VERSION"] = std::to_string(version);
  return writeFiles(raster, versioned, index, version);
}

WrittenTile GeoTiffTileWriter::writeFiles(const TileRaster& raster, const TileMetadata& metadata, int index,
                                          int version) {
  const auto start = std::chrono::steady_clock::now();
  WrittenTile tile;
  tile.metadata = metadata;
  tile.gsd_m = raster.gsd_m;
  tile.width_px = raster.image.cols;
  tile.height_px = raster.image.rows;
  const auto finish = [&](std::string error) {
    tile.ok = error.empty();
    tile.error = std::move(error);
    if (!tile.ok) tile.geotiff_path = tile.world_file_path = tile.cog_path = tile.kmz_path = "";
    tile.write_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    return tile;
  };

  const std::string raster_error = checkRaster(raster);
  if (!raster_error.empty()) return finish("invalid tile raster: " + raster_error);
  try {
    tile.local_frame = raster.local_frame;
    tile.epsg = raster.local_frame.empty() ? epsgForUtm(raster.utm_zone, raster.northern_hemisphere) : 0;
    computeBounds(raster, &tile);
  } catch (const std::exception& e) {
    return finish(std::string("tile raster outside its UTM zone's limits: ") + e.what());
  }

  struct stat st;
  if (::stat(config_.output_dir.c_str(), &st) != 0) {
    return finish("output folder '" + config_.output_dir + "' is not usable: " + osError(errno));
  }
  if (!S_ISDIR(st.st_mode)) return finish("output folder '" + config_.output_dir + "' is not a folder");

  tile.index = index >= 0 ? index : nextIndex();
  tile.version = version;
  const std::string base = baseName(tile.index, version);
  registerGdalOnce();
  GdalErrorCollector errors;
  // No .aux.xml beside the temporaries (it would not be renamed), the JPEG mask inside the file, overview blocks as
  // large as the main ones.
  ScopedGdalOption no_pam("GDAL_PAM_ENABLED", "NO");
  ScopedGdalOption internal_mask("GDAL_TIFF_INTERNAL_MASK", "YES");
  ScopedGdalOption overview_block("GDAL_TIFF_OVR_BLOCKSIZE", std::to_string(config_.block_size_px));
  TileFiles files(config_.output_dir);
  // A KMZ is in WGS 84: a tile in a local frame has none.
  const bool write_kmz = config_.write_kmz && raster.local_frame.empty();
  bool cog_written = config_.write_cog, kmz_written = write_kmz;  // cleared when the companion is left out
  try {
    // Companions first and the GeoTIFF last in commit order: once the GeoTIFF exists, so do they.
    std::string world_tmp, cog_tmp, kmz_tmp;
    if (config_.write_world_file) world_tmp = files.add(base + ".tfw");
    if (config_.write_cog) cog_tmp = files.add(base + ".cog.tif");
    // The KMZ driver writes a KMZ only for a name ending in ".kmz", and GDAL's /vsizip/ cannot handle a second
    // ".kmz" inside the name: ".<base>.partial.kmz".
    if (write_kmz) kmz_tmp = files.add(base + ".kmz", "." + base + ".partial.kmz");
    const std::string tif_tmp = files.add(base + ".tif");

    writeGeoTiff(config_, raster, metadata, tile, tif_tmp, &errors);
    if (config_.write_world_file) writeTextFile(world_tmp, worldFileText(raster), "world file");
    if (config_.write_cog || write_kmz) {
      DatasetPtr written = openWritten(tif_tmp, &errors);
      // A companion that fails is left out and reported; the GeoTIFF and the other companions are still written.
      const auto companion = [&](const char* what, const std::string& temporary, bool* ok, const auto& write) {
        try {
          write();
        } catch (const TileWriteError& e) {
          errors.take();
          tile.companion_errors.push_back(std::string(what) + ": " + e.what());
          files.drop(temporary);
          *ok = false;
        }
      };
      if (config_.write_cog)
        companion("COG", cog_tmp, &cog_written, [&] { writeCog(config_, written.get(), cog_tmp, &errors); });
      if (write_kmz)
        companion("KMZ", kmz_tmp, &kmz_written, [&] { writeKmz(config_, written.get(), base, kmz_tmp, &errors); });
    }
    files.commit();
  } catch (const TileWriteError& e) {
    const std::string error = e.what() + describeFileSystem(config_.output_dir);
    files.abort();
    return finish(error);
  } catch (const std::exception& e) {  // bad_alloc, cv::Exception: still no throw and no partial file
    files.abort();
    return finish("cannot write tile '" + config_.output_dir + "/" + base + ".tif': " + e.what());
  }
  const std::string folder_base = config_.output_dir + "/" + base;
  tile.geotiff_path = folder_base + ".tif";
  if (config_.write_world_file) tile.world_file_path = folder_base + ".tfw";
  if (cog_written) tile.cog_path = folder_base + ".cog.tif";
  if (kmz_written) tile.kmz_path = folder_base + ".kmz";
  return finish("");
}

}  // namespace tiles
}  // namespace exocet_mosaic
