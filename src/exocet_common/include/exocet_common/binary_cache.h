/**
 * @file binary_cache.h
 * @brief What the benchmarks' and tests' on-disk caches are made of: a content hash to name a cache after what it
 * was computed from, and plain-old-data values and vectors written and read in the machine's byte order (a cache
 * is read back on the machine that wrote it; a file that does not read back is recomputed).
 */
#pragma once

#include <cstdint>
#include <istream>
#include <ostream>
#include <string>
#include <vector>

namespace exocet_common {

/// 64-bit FNV-1a hash of a text (the description a cache was computed from).
inline uint64_t fnv1a(const std::string& text) {
  uint64_t h = 1469598103934665603ULL;
  for (unsigned char c : text) h = (h ^ c) * 1099511628211ULL;
  return h;
}

/// Writes the bytes of a plain-data value (numbers, fixed-size Eigen matrices, structs of those: no pointers).
template <typename T>
void putValue(std::ostream& out, const T& v) {
  out.write(reinterpret_cast<const char*>(&v), sizeof(T));
}

/// Reads what putValue() wrote; false at the end of the stream or on a read error.
template <typename T>
bool getValue(std::istream& in, T* v) {
  return bool(in.read(reinterpret_cast<char*>(v), sizeof(T)));
}

/// Writes a vector of plain-data values: its size, then its elements.
template <typename T>
void putVector(std::ostream& out, const std::vector<T>& v) {
  putValue(out, uint64_t(v.size()));
  if (!v.empty()) out.write(reinterpret_cast<const char*>(v.data()), std::streamsize(v.size() * sizeof(T)));
}

/// Reads what putVector() wrote; false on a short read or a size beyond max_elements (a corrupt file).
template <typename T>
bool getVector(std::istream& in, std::vector<T>* v, uint64_t max_elements = 1ULL << 32) {
  uint64_t n = 0;
  if (!getValue(in, &n) || n > max_elements) return false;
  v->resize(n);
  return n == 0 || bool(in.read(reinterpret_cast<char*>(v->data()), std::streamsize(n * sizeof(T))));
}

}  // namespace exocet_common
