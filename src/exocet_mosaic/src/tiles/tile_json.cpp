#include "exocet_mosaic/tiles/tile_json.h"

#include <charconv>
#include <cmath>

#include <nlohmann/json.hpp>

#include "exocet_common/json_file.h"

namespace exocet_mosaic {
namespace tiles {

namespace {

/// An optional path: null when empty, so that a reader does not take "" for a file.
nlohmann::ordered_json pathOrNull(const std::string& path) {
  return path.empty() ? nlohmann::ordered_json(nullptr) : nlohmann::ordered_json(path);
}

}  // namespace

std::string jsonNumber(double value) {
  if (!std::isfinite(value)) return "null";
  char buffer[64];
  // std::to_chars: shortest round-trip form, and no locale (a ',' decimal separator would break the JSON).
  const auto result = std::to_chars(buffer, buffer + sizeof(buffer), value);
  return std::string(buffer, result.ptr);
}

std::string tileToJson(const WrittenTile& tile) {
  nlohmann::ordered_json json;
  json["type"] = "exocet_tile";
  json["version"] = kTileJsonVersion;
  json["ok"] = tile.ok;
  json["error"] = tile.error.empty() ? nlohmann::ordered_json(nullptr) : nlohmann::ordered_json(tile.error);
  json["index"] = tile.index;
  json["tile_version"] = tile.version;
  json["geotiff_path"] = pathOrNull(tile.geotiff_path);
  json["world_file_path"] = pathOrNull(tile.world_file_path);
  json["cog_path"] = pathOrNull(tile.cog_path);
  json["kmz_path"] = pathOrNull(tile.kmz_path);
  json["epsg"] = tile.epsg;
  json["local_frame"] =
      tile.local_frame.empty() ? nlohmann::ordered_json(nullptr) : nlohmann::ordered_json(tile.local_frame);
  json["min_easting_m"] = tile.min_easting_m;
  json["min_northing_m"] = tile.min_northing_m;
  json["max_easting_m"] = tile.max_easting_m;
  json["max_northing_m"] = tile.max_northing_m;
  json["gsd_m"] = tile.gsd_m;
  json["width_px"] = tile.width_px;
  json["height_px"] = tile.height_px;
  json["west_deg"] = tile.west_deg;
  json["south_deg"] = tile.south_deg;
  json["east_deg"] = tile.east_deg;
  json["north_deg"] = tile.north_deg;
  const TileMetadata& m = tile.metadata;
  json["dive_name"] = m.dive_name;
  json["first_frame"] = m.first_frame;
  json["last_frame"] = m.last_frame;
  json["start_time_s"] = m.start_time_s;
  json["end_time_s"] = m.end_time_s;
  json["mean_altitude_m"] = m.mean_altitude_m;
  json["close_reason"] = m.close_reason;
  json["software"] = m.software;
  json["extra"] = nlohmann::ordered_json::object();
  for (const auto& item : m.extra) json["extra"][item.first] = item.second;
  json["write_ms"] = tile.write_ms;
  return exocet_common::jsonText(json, -1);
}

}  // namespace tiles
}  // namespace exocet_mosaic
