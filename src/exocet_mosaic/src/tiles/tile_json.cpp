#include "exocet_mosaic/tiles/tile_json.h"

#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdio>

namespace exocet_mosaic {
namespace tiles {

namespace {

/// Length of the valid UTF-8 sequence starting at s[i] (1..4), or 0 if the bytes there are not valid UTF-8
/// (overlong forms, surrogates and code points above U+10FFFF included).
size_t utf8SequenceLength(const std::string& s, size_t i) {
  const auto byte = [&](size_t k) { return static_cast<unsigned char>(s[k]); };
  const unsigned char c = byte(i);
  if (c < 0x80) return 1;
  size_t length = 0;
  uint32_t code = 0;
  if ((c & 0xE0) == 0xC0) {
    length = 2;
    code = c & 0x1F;
  } else if ((c & 0xF0) == 0xE0) {
    length = 3;
    code = c & 0x0F;
  } else if ((c & 0xF8) == 0xF0) {
    length = 4;
    code = c & 0x07;
  } else {
    return 0;
  }
  if (i + length > s.size()) return 0;
  for (size_t k = 1; k < length; ++k) {
    if ((byte(i + k) & 0xC0) != 0x80) return 0;
    code = (code << 6) | (byte(i + k) & 0x3F);
  }
  static const uint32_t kMinimum[5] = {0, 0, 0x80, 0x800, 0x10000};
  if (code < kMinimum[length] || code > 0x10FFFF || (code >= 0xD800 && code <= 0xDFFF)) return 0;
  return length;
}

class JsonObjectWriter {
 public:
  JsonObjectWriter() : text_("{") {}
  void raw(const char* key, const std::string& json_value) {
    if (text_.size() > 1) text_ += ',';
    text_ += jsonString(key);
    text_ += ':';
    text_ += json_value;
  }
  void string(const char* key, const std::string& value) { raw(key, jsonString(value)); }
  /// An optional path: null when empty, so that a reader does not take "" for a file.
  void path(const char* key, const std::string& value) { raw(key, value.empty() ? "null" : jsonString(value)); }
  void number(const char* key, double value) { raw(key, jsonNumber(value)); }
  void integer(const char* key, long long value) { raw(key, std::to_string(value)); }
  void boolean(const char* key, bool value) { raw(key, value ? "true" : "false"); }
  std::string close() { return text_ + '}'; }

 private:
  std::string text_;
};

}  // namespace

std::string jsonString(const std::string& text) {
  std::string out;
  out.reserve(text.size() + 2);
  out += '"';
  for (size_t i = 0; i < text.size();) {
    const unsigned char c = static_cast<unsigned char>(text[i]);
    const size_t length = utf8SequenceLength(text, i);
    if (length == 0) {
      out += "\\ufffd";  // replacement character: the byte is not UTF-8
      ++i;
      continue;
    }
    if (length > 1) {
      out.append(text, i, length);
      i += length;
      continue;
    }
    switch (c) {
      case '"':
        out += "\\\"";
        break;
      case '\\':
        out += "\\\\";
        break;
      case '\b':
        out += "\\b";
        break;
      case '\f':
        out += "\\f";
        break;
      case '\n':
        out += "\\n";
        break;
      case '\r':
        out += "\\r";
        break;
      case '\t':
        out += "\\t";
        break;
      default:
        if (c < 0x20 || c == 0x7F) {
          char escaped[8];
          std::snprintf(escaped, sizeof(escaped), "\\u%04x", c);
          out += escaped;
        } else {
          out += static_cast<char>(c);
        }
    }
    ++i;
  }
  out += '"';
  return out;
}

std::string jsonNumber(double value) {
  if (!std::isfinite(value)) return "null";
  char buffer[64];
  // std::to_chars: shortest round-trip form, and no locale (a ',' decimal separator would break the JSON).
  const auto result = std::to_chars(buffer, buffer + sizeof(buffer), value);
  return std::string(buffer, result.ptr);
}

std::string tileToJson(const WrittenTile& tile) {
  JsonObjectWriter json;
  json.string("type", "exocet_tile");
  json.integer("version", kTileJsonVersion);
  json.boolean("ok", tile.ok);
  json.raw("error", tile.error.empty() ? "null" : jsonString(tile.error));
  json.integer("index", tile.index);
  json.path("geotiff_path", tile.geotiff_path);
  json.path("world_file_path", tile.world_file_path);
  json.path("cog_path", tile.cog_path);
  json.path("kmz_path", tile.kmz_path);
  json.integer("epsg", tile.epsg);
  json.number("min_easting_m", tile.min_easting_m);
  json.number("min_northing_m", tile.min_northing_m);
  json.number("max_easting_m", tile.max_easting_m);
  json.number("max_northing_m", tile.max_northing_m);
  json.number("gsd_m", tile.gsd_m);
  json.integer("width_px", tile.width_px);
  json.integer("height_px", tile.height_px);
  json.number("west_deg", tile.west_deg);
  json.number("south_deg", tile.south_deg);
  json.number("east_deg", tile.east_deg);
  json.number("north_deg", tile.north_deg);
  const TileMetadata& m = tile.metadata;
  json.string("dive_name", m.dive_name);
  json.integer("first_frame", m.first_frame);
  json.integer("last_frame", m.last_frame);
  json.number("start_time_s", m.start_time_s);
  json.number("end_time_s", m.end_time_s);
  json.number("mean_altitude_m", m.mean_altitude_m);
  json.string("close_reason", m.close_reason);
  json.string("software", m.software);
  JsonObjectWriter extra;
  for (const auto& item : m.extra) extra.raw(item.first.c_str(), jsonString(item.second));
  json.raw("extra", extra.close());
  json.number("write_ms", tile.write_ms);
  return json.close();
}

}  // namespace tiles
}  // namespace exocet_mosaic
