/**
 * @file filter_step_file.h
 * @brief The filter's steps written out as the dive goes (fixed-size binary records, this process's own scratch
 * file): a kept log of an hour at 20 steps/s is about 120 MB, which the node must not hold in memory. No ROS.
 */
#pragma once

#include <cstdint>
#include <cstdio>
#include <deque>
#include <string>

#include "exocet_mosaic/fusion/filter_log.h"

namespace exocet_mosaic {
namespace fusion {

/**
 * @brief An append-only file of FilterSteps, read back whole (for the smoother and the track files).
 *
 * A failed append (disk full) writes nothing and says so: the caller keeps those steps and tries again later.
 * The file is truncated when opened and removed when the object goes (it serves one run).
 */
class FilterStepFile {
 public:
  /// Creates (or truncates) `path`. @throws std::runtime_error naming the path and the OS error.
  explicit FilterStepFile(const std::string& path);
  ~FilterStepFile();
  FilterStepFile(const FilterStepFile&) = delete;
  FilterStepFile& operator=(const FilterStepFile&) = delete;

  /// Appends steps [first, last) whole, or none of them. @return false on a write error (error() says which).
  bool append(std::deque<FilterStep>::const_iterator first, std::deque<FilterStep>::const_iterator last);
  /// Every step appended, in order, appended to `out`. @throws std::runtime_error when the file cannot be read back.
  void readAll(std::deque<FilterStep>* out) const;
  /// Forgets every step (a new dive).
  void clear();
  uint64_t size() const { return steps_; }
  uint64_t bytes() const;
  const std::string& path() const { return path_; }
  const std::string& error() const { return error_; }
  /// Bytes of one record.
  static size_t recordBytes();

 private:
  std::string path_;
  std::FILE* file_ = nullptr;
  uint64_t steps_ = 0;
  std::string error_;
};

}  // namespace fusion
}  // namespace exocet_mosaic
