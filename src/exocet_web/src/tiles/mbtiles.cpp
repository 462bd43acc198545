#include "exocet_web/tiles/mbtiles.h"

#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <memory>
#include <vector>

#include <sqlite3.h>

namespace exocet_web {
namespace tiles {

namespace {

namespace fs = std::filesystem;

struct DatabaseCloser {
  void operator()(sqlite3* db) const { sqlite3_close(db); }
};
struct StatementFinalizer {
  void operator()(sqlite3_stmt* s) const { sqlite3_finalize(s); }
};
using Database = std::unique_ptr<sqlite3, DatabaseCloser>;
using Statement = std::unique_ptr<sqlite3_stmt, StatementFinalizer>;

struct TileFile {
  TileId id;
  std::string path;
};

std::vector<TileFile> listTileFiles(const std::string& tiles_dir) {
  std::vector<TileFile> files;
  std::error_code ec;
  const auto asInt = [](const std::string& s, int* v) {
    if (s.empty() || s.size() > 9 || !std::all_of(s.begin(), s.end(), ::isdigit)) return false;
    *v = std::stoi(s);
    return true;
  };
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

}  // namespace

MbtilesResult exportMbtiles(const std::string& tiles_dir, const std::string& output_path, const MbtilesInfo& info) {
  MbtilesResult result;
  const std::vector<TileFile> files = listTileFiles(tiles_dir);
  if (files.empty()) {
    result.error = "no web tile in '" + tiles_dir + "'";
    return result;
  }
  const fs::path final_path(output_path);
  const std::string temporary =
      (final_path.parent_path() / ("." + final_path.filename().string() + ".partial-" + std::to_string(::getpid())))
          .string();
  std::remove(temporary.c_str());
  sqlite3* raw = nullptr;
  const int open_status = sqlite3_open_v2(temporary.c_str(), &raw, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE, nullptr);
  Database db(raw);
  const auto fail = [&](const std::string& what) {
    result.error = what + " (" + temporary + "): " + (db ? sqlite3_errmsg(db.get()) : "cannot open");
    db.reset();
    std::remove(temporary.c_str());
    return result;
  };
  if (open_status != SQLITE_OK) return fail("cannot create the MBTiles file");
  const char* schema =
      "PRAGMA journal_mode=OFF; PRAGMA synchronous=OFF;"
      "CREATE TABLE metadata (name TEXT, value TEXT);"
      "CREATE TABLE tiles (zoom_level INTEGER, tile_column INTEGER, tile_row INTEGER, tile_data BLOB);"
      "CREATE UNIQUE INDEX tile_index ON tiles (zoom_level, tile_column, tile_row);"
      "BEGIN;";
  if (sqlite3_exec(db.get(), schema, nullptr, nullptr, nullptr) != SQLITE_OK) return fail("cannot create the tables");

  sqlite3_stmt* insert_raw = nullptr;
  if (sqlite3_prepare_v2(db.get(), "INSERT INTO tiles VALUES (?, ?, ?, ?)", -1, &insert_raw, nullptr) != SQLITE_OK)
    return fail("cannot prepare the insertion");
  Statement insert(insert_raw);
  MercatorBox extent;
  for (const TileFile& file : files) {
    std::ifstream in(file.path, std::ios::binary);
    const std::vector<char> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (!in.good() && !in.eof()) continue;  // removed meanwhile
    const int tms_row = (1 << file.id.z) - 1 - file.id.y;  // MBTiles counts rows from the south
    sqlite3_bind_int(insert.get(), 1, file.id.z);
    sqlite3_bind_int(insert.get(), 2, file.id.x);
    sqlite3_bind_int(insert.get(), 3, tms_row);
    sqlite3_bind_blob(insert.get(), 4, bytes.data(), static_cast<int>(bytes.size()), SQLITE_TRANSIENT);
    if (sqlite3_step(insert.get()) != SQLITE_DONE) return fail("cannot insert tile " + file.id.path());
    sqlite3_reset(insert.get());
    ++result.tiles;
    result.min_zoom = result.min_zoom < 0 ? file.id.z : std::min(result.min_zoom, file.id.z);
    result.max_zoom = std::max(result.max_zoom, file.id.z);
    if (file.id.z == files.back().id.z) extent = extent.unitedWith(tileBounds(file.id));
  }
  LatLonBox bounds = info.bounds;
  if (!(bounds.east_deg > bounds.west_deg)) {
    bounds = {longitudeFromMercatorX_deg(extent.min_x_m), latitudeFromMercatorY_deg(extent.min_y_m),
              longitudeFromMercatorX_deg(extent.max_x_m), latitudeFromMercatorY_deg(extent.max_y_m)};
  }
  char text[160];
  std::snprintf(text, sizeof(text), "%.9f,%.9f,%.9f,%.9f", bounds.west_deg, bounds.south_deg, bounds.east_deg,
                bounds.north_deg);
  const std::string bounds_text = text;
  std::snprintf(text, sizeof(text), "%.9f,%.9f,%d", 0.5 * (bounds.west_deg + bounds.east_deg),
                0.5 * (bounds.south_deg + bounds.north_deg), std::max(result.min_zoom, result.max_zoom - 2));
  const std::string center_text = text;
  const std::vector<std::pair<std::string, std::string>> metadata = {
      {"name", info.name},
      {"format", "png"},
      {"type", "overlay"},
      {"version", "1.3"},
      {"description", info.description},
      {"bounds", bounds_text},
      {"center", center_text},
      {"minzoom", std::to_string(result.min_zoom)},
      {"maxzoom", std::to_string(result.max_zoom)}};
  sqlite3_stmt* meta_raw = nullptr;
  if (sqlite3_prepare_v2(db.get(), "INSERT INTO metadata VALUES (?, ?)", -1, &meta_raw, nullptr) != SQLITE_OK)
    return fail("cannot prepare the metadata");
  Statement meta(meta_raw);
  for (const auto& [name, value] : metadata) {
    sqlite3_bind_text(meta.get(), 1, name.c_str(), -1, SQLITE_TRANSIENT);
    sqlite3_bind_text(meta.get(), 2, value.c_str(), -1, SQLITE_TRANSIENT);
    if (sqlite3_step(meta.get()) != SQLITE_DONE) return fail("cannot write the metadata");
    sqlite3_reset(meta.get());
  }
  insert.reset();
  meta.reset();
  if (sqlite3_exec(db.get(), "COMMIT;", nullptr, nullptr, nullptr) != SQLITE_OK) return fail("cannot commit");
  if (sqlite3_close(db.release()) != SQLITE_OK) {
    std::remove(temporary.c_str());
    result.error = "cannot close '" + temporary + "'";
    return result;
  }
  if (std::rename(temporary.c_str(), output_path.c_str()) != 0) {
    result.error = "cannot rename '" + temporary + "' to '" + output_path + "': " + std::strerror(errno);
    std::remove(temporary.c_str());
    return result;
  }
  result.ok = true;
  return result;
}

}  // namespace tiles
}  // namespace exocet_web
