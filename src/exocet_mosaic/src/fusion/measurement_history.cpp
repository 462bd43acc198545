#include "exocet_mosaic/fusion/measurement_history.h"

#include <algorithm>

namespace exocet_mosaic {
namespace fusion {
namespace {

/// Index of the first sample not older than t (samples sorted by time).
template <typename Samples>
size_t lowerBound(const Samples& samples, double t) {
  const auto it = std::lower_bound(samples.begin(), samples.end(), t,
                                   [](const auto& sample, double stamp) { return sample.first < stamp; });
  return static_cast<size_t>(it - samples.begin());
}

template <typename Samples, typename Value>
void addSample(Samples* samples, double stamp_s, const Value& value, double window_s) {
  if (!samples->empty() && stamp_s < samples->back().first) samples->clear();  // time went back
  samples->emplace_back(stamp_s, value);
  while (samples->size() > 2 && samples->front().first < stamp_s - window_s) samples->pop_front();
}

/// Finds the samples bracketing t: (i, i) for a nearest-sample answer, (i, i+1) to interpolate; false if none fits.
template <typename Samples>
bool bracket(const Samples& samples, double t, double max_gap_s, size_t* lo, size_t* hi) {
  if (samples.empty()) return false;
  const size_t k = lowerBound(samples, t);
  if (k == 0) {
    if (samples.front().first - t > 0.5 * max_gap_s) return false;
    *lo = *hi = 0;
    return true;
  }
  if (k == samples.size()) {
    if (t - samples.back().first > 0.5 * max_gap_s) return false;
    *lo = *hi = samples.size() - 1;
    return true;
  }
  if (samples[k].first == t) {
    *lo = *hi = k;
    return true;
  }
  if (samples[k].first - samples[k - 1].first > max_gap_s) return false;
  *lo = k - 1;
  *hi = k;
  return true;
}

template <typename Samples>
std::vector<typename Samples::value_type> samplesBetween(const Samples& samples, double from_s, double to_s) {
  std::vector<typename Samples::value_type> out;
  for (size_t k = lowerBound(samples, from_s); k < samples.size() && samples[k].first <= to_s; ++k)
    out.push_back(samples[k]);
  return out;
}

}  // namespace

std::vector<std::pair<double, Eigen::Quaterniond>> AttitudeHistory::between(double from_s, double to_s) const {
  return samplesBetween(samples_, from_s, to_s);
}

std::optional<double> AttitudeHistory::newestStamp() const {
  if (samples_.empty()) return std::nullopt;
  return samples_.back().first;
}

std::vector<std::pair<double, double>> ScalarHistory::between(double from_s, double to_s) const {
  return samplesBetween(samples_, from_s, to_s);
}

void AttitudeHistory::add(double stamp_s, const Eigen::Quaterniond& world_from_body) {
  addSample(&samples_, stamp_s, world_from_body.normalized(), window_s_);
}

std::optional<Eigen::Quaterniond> AttitudeHistory::at(double stamp_s) const {
  size_t lo = 0, hi = 0;
  if (!bracket(samples_, stamp_s, max_gap_s_, &lo, &hi)) return std::nullopt;
  if (lo == hi) return samples_[lo].second;
  const double w = (stamp_s - samples_[lo].first) / (samples_[hi].first - samples_[lo].first);
  return samples_[lo].second.slerp(w, samples_[hi].second);
}

void ScalarHistory::add(double stamp_s, double value) { addSample(&samples_, stamp_s, value, window_s_); }

std::optional<double> ScalarHistory::at(double stamp_s) const {
  size_t lo = 0, hi = 0;
  if (!bracket(samples_, stamp_s, max_gap_s_, &lo, &hi)) return std::nullopt;
  if (lo == hi) return samples_[lo].second;
  const double w = (stamp_s - samples_[lo].first) / (samples_[hi].first - samples_[lo].first);
  return (1.0 - w) * samples_[lo].second + w * samples_[hi].second;
}

}  // namespace fusion
}  // namespace exocet_mosaic
