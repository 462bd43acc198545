/**
 * @file random.h
 * @brief Deterministic, order-independent random numbers for the dive simulator.
 *
 * Every random draw of the simulator is a pure function of (seed, stream, counter), so that the same
 * arguments give the same bytes whatever the order of evaluation, the cache state or the number of threads.
 * The generators are written here rather than taken from <random> because the standard distributions are
 * implementation-defined: a bag must not change when the C++ library does.
 */
#pragma once

#include <cmath>
#include <cstdint>

namespace exocet_mosaic {
namespace sim {

/// SplitMix64 finaliser: a strong 64-bit mixing function (Steele et al. 2014).
inline uint64_t mix64(uint64_t x) {
  x += 0x9E3779B97F4A7C15ULL;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ULL;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBULL;
  return x ^ (x >> 31);
}

/// Hash of several integer keys, for counter-based draws (e.g. seed, tile x, tile y, level).
inline uint64_t hashKeys(uint64_t a, uint64_t b = 0, uint64_t c = 0, uint64_t d = 0) {
  return mix64(mix64(mix64(mix64(a) ^ b) ^ c) ^ d);
}

/// Uniform double in [0, 1) from 53 random bits.
inline double toUnit(uint64_t bits) { return static_cast<double>(bits >> 11) * (1.0 / 9007199254740992.0); }

/**
 * @brief Small sequential generator (SplitMix64 stream) with exact, portable distributions.
 */
class RandomStream {
 public:
  explicit RandomStream(uint64_t seed) : state_(seed) {}
  /// Seeded from several keys, e.g. (seed, stream id, frame index).
  RandomStream(uint64_t a, uint64_t b, uint64_t c = 0) : state_(hashKeys(a, b, c)) {}

  uint64_t next() {
    state_ += 0x9E3779B97F4A7C15ULL;
    uint64_t z = state_;
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    return z ^ (z >> 31);
  }
  /// Uniform in [0, 1).
  double uniform() { return toUnit(next()); }
  /// Uniform in [lo, hi).
  double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }
  /// Standard normal by the Box-Muller transform (both values used).
  double gaussian() {
    if (has_spare_) {
      has_spare_ = false;
      return spare_;
    }
    double u1 = uniform();
    while (u1 <= 1e-300) u1 = uniform();
    const double u2 = uniform();
    const double r = std::sqrt(-2.0 * std::log(u1));
    spare_ = r * std::sin(2.0 * M_PI * u2);
    has_spare_ = true;
    return r * std::cos(2.0 * M_PI * u2);
  }
  double gaussian(double sigma) { return sigma * gaussian(); }
  /// Bernoulli draw with probability p.
  bool chance(double p) { return uniform() < p; }
  /// Poisson draw (Knuth's method for small means, normal approximation above 30).
  int poisson(double mean) {
    if (mean <= 0.0) return 0;
    if (mean > 30.0) {
      const double v = std::floor(mean + std::sqrt(mean) * gaussian() + 0.5);
      return v < 0.0 ? 0 : static_cast<int>(v);
    }
    const double limit = std::exp(-mean);
    int k = 0;
    double p = uniform();
    while (p > limit) {
      ++k;
      p *= uniform();
    }
    return k;
  }

 private:
  uint64_t state_;
  double spare_ = 0.0;
  bool has_spare_ = false;
};

}  // namespace sim
}  // namespace exocet_mosaic
