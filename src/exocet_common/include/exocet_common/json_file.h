/**
 * @file json_file.h
 * @brief JSON files written whole or not at all (atomic_file.h) and read back, with nlohmann-json. Works with
 * nlohmann::json (keys sorted) and nlohmann::ordered_json (keys in insertion order). No ROS in it.
 */
#pragma once

#include <fstream>
#include <optional>
#include <string>

#include <nlohmann/json.hpp>

#include "exocet_common/atomic_file.h"

namespace exocet_common {

/**
 * @brief The text of `value`: indented by `indent` spaces (-1: compact, on one line), UTF-8, NaN and infinities as
 * null. Bytes that are not valid UTF-8 (a Latin-1 file name) become U+FFFD instead of making the text invalid.
 */
template <typename Json>
std::string jsonText(const Json& value, int indent = 2) {
  return value.dump(indent, ' ', false, Json::error_handler_t::replace);
}

/// Writes `value` (jsonText, indented by 2, and a final newline) to `path` atomically; throws std::runtime_error
/// naming the path and the OS error.
template <typename Json>
void writeJsonFileAtomically(const std::string& path, const Json& value) {
  writeFileAtomically(path, jsonText(value) + "\n");
}

/// The JSON object in the file at `path`; std::nullopt if the file cannot be read or holds no JSON object.
template <typename Json>
std::optional<Json> readJsonObjectFile(const std::string& path) {
  std::ifstream in(path);
  if (!in) return std::nullopt;
  Json value = Json::parse(in, nullptr, false);
  if (!value.is_object()) return std::nullopt;
  return value;
}

}  // namespace exocet_common
