/**
 * @file atomic_file.h
 * @brief Outputs that appear whole or not at all: write under a temporary name in the same folder, then rename.
 */
#pragma once

#include <string>

namespace exocet_common {

/// Temporary name beside `final_path` (same folder, so rename() is atomic): "<dir>/.<name>.partial-<pid>".
std::string temporaryPathFor(const std::string& final_path);

/// Writes `contents` to `final_path` atomically. Throws std::runtime_error naming the path and the OS error.
void writeFileAtomically(const std::string& final_path, const std::string& contents);

/// Renames `temporary_path` onto `final_path` (fsync'ing the data first). Throws std::runtime_error on failure.
void commitTemporaryFile(const std::string& temporary_path, const std::string& final_path);

/// Checks that the folder of `path` exists and is writable; returns an error message or "".
std::string checkWritableDestination(const std::string& path);

}  // namespace exocet_common
