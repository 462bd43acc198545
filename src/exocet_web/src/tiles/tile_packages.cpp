#include "exocet_web/tiles/tile_packages.h"

#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <memory>
#include <vector>

#include <cpl_conv.h>
#include <ogr_srs_api.h>
#include <sqlite3.h>

namespace exocet_web {
namespace tiles {

namespace {

namespace fs = std::filesystem;

struct TileFile {
  TileId id;
  std::string path;
};

std::vector<TileFile> listTileFiles(const std::string& tiles_dir) {
  std::vector<TileFile> files;
  const auto asInt = [](const std::string& s, int* v) {
    if (s.empty() || s.size() > 9 || !std::all_of(s.begin(), s.end(), ::isdigit)) return false;
    *v = std::stoi(s);
    return true;
  };
  std::error_code ec;
  for (const auto& level : fs::directory_iterator(tiles_dir, ec)) {
    int z = 0;
    if (!asInt(level.path().filename().string(), &z) || z > kMaxZoom) continue;
    std::error_code ec2;
    for (const auto& column : fs::directory_iterator(level.path(), ec2)) {
      int x = 0;
      if (!asInt(column.path().filename().string(), &x)) continue;
      std::error_code ec3;
      for (const auto& file : fs::directory_iterator(column.path(), ec3)) {
        const std::string name = file.path().filename().string();
        int y = 0;
        if (name.size() < 5 || name.compare(name.size() - 4, 4, ".png") != 0 ||
            !asInt(name.substr(0, name.size() - 4), &y))
          continue;
        files.push_back({{z, x, y}, file.path().string()});
      }
    }
  }
  std::sort(files.begin(), files.end(), [](const TileFile& a, const TileFile& b) { return a.id < b.id; });
  return files;
}

std::string readBytes(const std::string& path, bool* ok) {
  std::ifstream in(path, std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  *ok = static_cast<bool>(in) || in.eof();
  return bytes;
}

/// One SQLite file written under a temporary name, renamed into place by commit(), removed otherwise.
class PackageFile {
 public:
  explicit PackageFile(const std::string& final_path) : final_path_(final_path) {
    const fs::path p(final_path);
    temporary_ = (p.parent_path() / ("." + p.filename().string() + ".partial-" + std::to_string(::getpid()))).string();
    std::remove(temporary_.c_str());
    if (sqlite3_open_v2(temporary_.c_str(), &db_, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE, nullptr) != SQLITE_OK)
      error_ = "cannot create '" + temporary_ + "': " + (db_ ? sqlite3_errmsg(db_) : "out of memory");
  }
  ~PackageFile() {
    if (db_) sqlite3_close(db_);
    if (!committed_) std::remove(temporary_.c_str());
  }
  PackageFile(const PackageFile&) = delete;
  PackageFile& operator=(const PackageFile&) = delete;

  bool ok() const { return error_.empty(); }
  const std::string& error() const { return error_; }

  /// Runs SQL; false (and error()) on failure.
  bool exec(const std::string& sql, const std::string& what) {
    if (!ok()) return false;
    char* message = nullptr;
    if (sqlite3_exec(db_, sql.c_str(), nullptr, nullptr, &message) != SQLITE_OK) {
      error_ = what + " in '" + temporary_ + "': " + (message ? message : "unknown SQLite error");
      sqlite3_free(message);
      return false;
    }
    return true;
  }

  /// Runs one statement with bound values: bind(statement) sets them.
  bool run(const std::string& sql, const std::function<void(sqlite3_stmt*)>& bind, const std::string& what) {
    if (!ok()) return false;
    sqlite3_stmt* statement = nullptr;
    if (sqlite3_prepare_v2(db_, sql.c_str(), -1, &statement, nullptr) != SQLITE_OK) {
      error_ = what + ": " + sqlite3_errmsg(db_);
      return false;
    }
    bind(statement);
    const int status = sqlite3_step(statement);
    sqlite3_finalize(statement);
    if (status != SQLITE_DONE) {
      error_ = what + " in '" + temporary_ + "': " + sqlite3_errmsg(db_);
      return false;
    }
    return true;
  }

  /// Inserts every tile with `sql` (4 parameters: zoom, column, row, blob), rows from row(id).
  bool insertTiles(const std::string& sql, const std::vector<TileFile>& files,
                   const std::function<int64_t(const TileId&)>& row,
                   const std::function<int64_t(const TileId&)>& column, int* count) {
    if (!ok()) return false;
    sqlite3_stmt* statement = nullptr;
    if (sqlite3_prepare_v2(db_, sql.c_str(), -1, &statement, nullptr) != SQLITE_OK) {
      error_ = std::string("cannot prepare the tile insertion: ") + sqlite3_errmsg(db_);
      return false;
    }
    for (const TileFile& file : files) {
      bool read = false;
      const std::string bytes = readBytes(file.path, &read);
      if (!read || bytes.empty()) continue;  // removed meanwhile
      sqlite3_bind_int(statement, 1, file.id.z);
      sqlite3_bind_int64(statement, 2, column(file.id));
      sqlite3_bind_int64(statement, 3, row(file.id));
      sqlite3_bind_blob(statement, 4, bytes.data(), static_cast<int>(bytes.size()), SQLITE_TRANSIENT);
      if (sqlite3_step(statement) != SQLITE_DONE) {
        error_ = "cannot insert tile " + file.id.path() + " in '" + temporary_ + "': " + sqlite3_errmsg(db_);
        sqlite3_finalize(statement);
        return false;
      }
      sqlite3_reset(statement);
      ++*count;
    }
    sqlite3_finalize(statement);
    return true;
  }

  /// Closes the database and renames it into place.
  bool commit() {
    if (!ok()) return false;
    if (sqlite3_close(db_) != SQLITE_OK) {
      error_ = "cannot close '" + temporary_ + "'";
      return false;
    }
    db_ = nullptr;
    if (std::rename(temporary_.c_str(), final_path_.c_str()) != 0) {
      error_ = "cannot rename '" + temporary_ + "' to '" + final_path_ + "': " + std::strerror(errno);
      return false;
    }
    committed_ = true;
    return true;
  }

 private:
  std::string final_path_;
  std::string temporary_;
  sqlite3* db_ = nullptr;
  std::string error_;
  bool committed_ = false;
};

std::string quoted(const std::string& text) {
  std::string out = "'";
  for (char c : text) out += c == '\'' ? std::string("''") : std::string(1, c);
  return out + "'";
}

std::string number(double v) {
  char buffer[40];
  std::snprintf(buffer, sizeof(buffer), "%.17g", v);
  return buffer;
}

LatLonBox boundsOf(const std::vector<TileFile>& files, const LatLonBox& given) {
  if (given.east_deg > given.west_deg) return given;
  MercatorBox extent;
  for (const TileFile& f : files)
    if (f.id.z == files.back().id.z) extent = extent.unitedWith(tileBounds(f.id));
  return {longitudeFromMercatorX_deg(extent.min_x_m), latitudeFromMercatorY_deg(extent.min_y_m),
          longitudeFromMercatorX_deg(extent.max_x_m), latitudeFromMercatorY_deg(extent.max_y_m)};
}

std::string wktOf(int epsg) {
  OGRSpatialReferenceH srs = OSRNewSpatialReference(nullptr);
  std::string wkt;
  if (OSRImportFromEPSG(srs, epsg) == OGRERR_NONE) {
    char* text = nullptr;
    if (OSRExportToWkt(srs, &text) == OGRERR_NONE && text) wkt = text;
    CPLFree(text);
  }
  OSRDestroySpatialReference(srs);
  return wkt;
}

}  // namespace

TilePackageResult exportMbtiles(const std::string& tiles_dir, const std::string& output_path,
                                const TilePackageInfo& info) {
  TilePackageResult result;
  const std::vector<TileFile> files = listTileFiles(tiles_dir);
  if (files.empty()) {
    result.error = "no web tile in '" + tiles_dir + "'";
    return result;
  }
  PackageFile db(output_path);
  db.exec(
      "PRAGMA journal_mode=OFF; PRAGMA synchronous=OFF;"
      "CREATE TABLE metadata (name TEXT, value TEXT);"
      "CREATE TABLE tiles (zoom_level INTEGER, tile_column INTEGER, tile_row INTEGER, tile_data BLOB);"
      "CREATE UNIQUE INDEX tile_index ON tiles (zoom_level, tile_column, tile_row);"
      "BEGIN;",
      "cannot create the tables");
  // MBTiles counts rows from the south (TMS).
  db.insertTiles(
      "INSERT INTO tiles VALUES (?, ?, ?, ?)", files, [](const TileId& t) { return (int64_t(1) << t.z) - 1 - t.y; },
      [](const TileId& t) { return t.x; }, &result.tiles);
  result.min_zoom = files.front().id.z;
  result.max_zoom = files.back().id.z;
  const LatLonBox b = boundsOf(files, info.bounds);
  char text[200];
  std::snprintf(text, sizeof(text), "%.9f,%.9f,%.9f,%.9f", b.west_deg, b.south_deg, b.east_deg, b.north_deg);
  const std::string bounds = text;
  std::snprintf(text, sizeof(text), "%.9f,%.9f,%d", 0.5 * (b.west_deg + b.east_deg), 0.5 * (b.south_deg + b.north_deg),
                std::max(result.min_zoom, result.max_zoom - 2));
  const std::string center = text;
  for (const auto& [name, value] :
       std::vector<std::pair<std::string, std::string>>{{"name", info.name},
                                                        {"format", "png"},
                                                        {"type", "overlay"},
                                                        {"version", "1.3"},
                                                        {"description", info.description},
                                                        {"bounds", bounds},
                                                        {"center", center},
                                                        {"minzoom", std::to_string(result.min_zoom)},
                                                        {"maxzoom", std::to_string(result.max_zoom)}})
    db.exec("INSERT INTO metadata VALUES (" + quoted(name) + ", " + quoted(value) + ");", "cannot write the metadata");
  db.exec("COMMIT;", "cannot commit");
  if (!db.commit()) {
    result.error = db.error();
    return result;
  }
  result.ok = true;
  return result;
}

TilePackageResult exportGeoPackage(const std::string& tiles_dir, const std::string& output_path,
                                   const TilePackageInfo& info) {
  TilePackageResult result;
  const std::vector<TileFile> files = listTileFiles(tiles_dir);
  if (files.empty()) {
    result.error = "no web tile in '" + tiles_dir + "'";
    return result;
  }
  result.min_zoom = files.front().id.z;
  result.max_zoom = files.back().id.z;
  // The tile matrix set: the web tiles of the coarsest level that hold data, so that every level's tiles are whole
  // tiles of it (column = x - x0 * 2^(z - z0), row = y - y0 * 2^(z - z0); GeoPackage rows count from the top too).
  const int z0 = result.min_zoom;
  int x0 = INT32_MAX, y0 = INT32_MAX, x1 = -1, y1 = -1;
  for (const TileFile& f : files) {
    if (f.id.z != z0) break;
    x0 = std::min(x0, f.id.x);
    y0 = std::min(y0, f.id.y);
    x1 = std::max(x1, f.id.x);
    y1 = std::max(y1, f.id.y);
  }
  const MercatorBox top_left = tileBounds({z0, x0, y0}), bottom_right = tileBounds({z0, x1, y1});
  const std::string mercator_wkt = wktOf(3857), wgs84_wkt = wktOf(4326);
  if (mercator_wkt.empty() || wgs84_wkt.empty()) {
    result.error = "PROJ has no definition of EPSG:3857 or EPSG:4326";
    return result;
  }
  PackageFile db(output_path);
  db.exec(
      "PRAGMA application_id = 1196444487; PRAGMA user_version = 10200;"  // 'GPKG', GeoPackage 1.2
      "PRAGMA journal_mode=OFF; PRAGMA synchronous=OFF;"
      "CREATE TABLE gpkg_spatial_ref_sys (srs_name TEXT NOT NULL, srs_id INTEGER PRIMARY KEY, organization TEXT NOT "
      "NULL, organization_coordsys_id INTEGER NOT NULL, definition TEXT NOT NULL, description TEXT);"
      "CREATE TABLE gpkg_contents (table_name TEXT NOT NULL PRIMARY KEY, data_type TEXT NOT NULL, identifier TEXT "
      "UNIQUE, description TEXT DEFAULT '', last_change DATETIME NOT NULL DEFAULT "
      "(strftime('%Y-%m-%dT%H:%M:%fZ','now')), min_x DOUBLE, min_y DOUBLE, max_x DOUBLE, max_y DOUBLE, srs_id "
      "INTEGER, CONSTRAINT fk_gc_r_srs_id FOREIGN KEY (srs_id) REFERENCES gpkg_spatial_ref_sys(srs_id));"
      "CREATE TABLE gpkg_tile_matrix_set (table_name TEXT NOT NULL PRIMARY KEY, srs_id INTEGER NOT NULL, min_x DOUBLE "
      "NOT NULL, min_y DOUBLE NOT NULL, max_x DOUBLE NOT NULL, max_y DOUBLE NOT NULL, CONSTRAINT fk_gtms_table_name "
      "FOREIGN KEY (table_name) REFERENCES gpkg_contents(table_name), CONSTRAINT fk_gtms_srs FOREIGN KEY (srs_id) "
      "REFERENCES gpkg_spatial_ref_sys (srs_id));"
      "CREATE TABLE gpkg_tile_matrix (table_name TEXT NOT NULL, zoom_level INTEGER NOT NULL, matrix_width INTEGER NOT "
      "NULL, matrix_height INTEGER NOT NULL, tile_width INTEGER NOT NULL, tile_height INTEGER NOT NULL, pixel_x_size "
      "DOUBLE NOT NULL, pixel_y_size DOUBLE NOT NULL, CONSTRAINT pk_ttm PRIMARY KEY (table_name, zoom_level), "
      "CONSTRAINT fk_tmm_table_name FOREIGN KEY (table_name) REFERENCES gpkg_contents(table_name));"
      "CREATE TABLE mosaic (id INTEGER PRIMARY KEY AUTOINCREMENT, zoom_level INTEGER NOT NULL, tile_column INTEGER NOT "
      "NULL, tile_row INTEGER NOT NULL, tile_data BLOB NOT NULL, UNIQUE (zoom_level, tile_column, tile_row));"
      "BEGIN;",
      "cannot create the GeoPackage tables");
  db.exec(
      "INSERT INTO gpkg_spatial_ref_sys VALUES ('Undefined cartesian SRS', -1, 'NONE', -1, 'undefined', NULL);"
      "INSERT INTO gpkg_spatial_ref_sys VALUES ('Undefined geographic SRS', 0, 'NONE', 0, 'undefined', NULL);"
      "INSERT INTO gpkg_spatial_ref_sys VALUES ('WGS 84 geodetic', 4326, 'EPSG', 4326, " +
          quoted(wgs84_wkt) +
          ", NULL);"
          "INSERT INTO gpkg_spatial_ref_sys VALUES ('WGS 84 / Pseudo-Mercator', 3857, 'EPSG', 3857, " +
          quoted(mercator_wkt) + ", NULL);",
      "cannot write the spatial reference systems");
  const std::string box = number(top_left.min_x_m) + ", " + number(bottom_right.min_y_m) + ", " +
                          number(bottom_right.max_x_m) + ", " + number(top_left.max_y_m);
  db.exec(
      "INSERT INTO gpkg_contents (table_name, data_type, identifier, description, min_x, min_y, max_x, max_y, "
      "srs_id) VALUES ('mosaic', 'tiles', " +
          quoted(info.name) + ", " + quoted(info.description) + ", " + box +
          ", 3857);"
          "INSERT INTO gpkg_tile_matrix_set VALUES ('mosaic', 3857, " +
          box + ");",
      "cannot write the contents");
  for (int z = z0; z <= result.max_zoom; ++z) {
    const int64_t scale = int64_t(1) << (z - z0);
    const double res = resolution_m_per_px(z);
    db.exec("INSERT INTO gpkg_tile_matrix VALUES ('mosaic', " + std::to_string(z) + ", " +
                std::to_string((x1 - x0 + 1) * scale) + ", " + std::to_string((y1 - y0 + 1) * scale) + ", " +
                std::to_string(kTileSize_px) + ", " + std::to_string(kTileSize_px) + ", " + number(res) + ", " +
                number(res) + ");",
            "cannot write the tile matrices");
  }
  db.insertTiles(
      "INSERT INTO mosaic (zoom_level, tile_column, tile_row, tile_data) VALUES (?, ?, ?, ?)", files,
      [&](const TileId& t) { return int64_t(t.y) - (int64_t(y0) << (t.z - z0)); },
      [&](const TileId& t) { return int64_t(t.x) - (int64_t(x0) << (t.z - z0)); }, &result.tiles);
  db.exec("COMMIT;", "cannot commit");
  if (!db.commit()) {
    result.error = db.error();
    return result;
  }
  result.ok = true;
  return result;
}

}  // namespace tiles
}  // namespace exocet_web
