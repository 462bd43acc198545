#include "exocet_mosaic/fusion/filter_step_file.h"

#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <stdexcept>
#include <vector>

namespace exocet_mosaic {
namespace fusion {

namespace {

constexpr int kMatrices = 3;  // P_prior, P_posterior, transition
constexpr int kDoubles = 1 + 2 * kStateSize + kMatrices * kStateSize * kStateSize;
constexpr int kInts = 9;  // 3 flags and 6 counters

void encode(const FilterStep& s, unsigned char* record) {
  double d[kDoubles];
  int i = 0;
  d[i++] = s.stamp_s;
  for (const StateVector* v : {&s.x_prior, &s.x_posterior})
    for (int k = 0; k < kStateSize; ++k) d[i++] = (*v)(k);
  for (const StateMatrix* m : {&s.P_prior, &s.P_posterior, &s.transition})
    for (int k = 0; k < kStateSize * kStateSize; ++k) d[i++] = m->data()[k];
  const int32_t n[kInts] = {s.discontinuity,
                            s.image_motion,
                            s.dr_initialized,
                            s.fixes_applied,
                            s.fixes_rejected,
                            s.dr_applied,
                            s.dr_rejected,
                            s.consecutive_fix_rejections,
                            s.consecutive_dr_rejections};
  std::memcpy(record, d, sizeof d);
  std::memcpy(record + sizeof d, n, sizeof n);
}

FilterStep decode(const unsigned char* record) {
  double d[kDoubles];
  int32_t n[kInts];
  std::memcpy(d, record, sizeof d);
  std::memcpy(n, record + sizeof d, sizeof n);
  FilterStep s;
  int i = 0;
  s.stamp_s = d[i++];
  for (StateVector* v : {&s.x_prior, &s.x_posterior})
    for (int k = 0; k < kStateSize; ++k) (*v)(k) = d[i++];
  for (StateMatrix* m : {&s.P_prior, &s.P_posterior, &s.transition})
    for (int k = 0; k < kStateSize * kStateSize; ++k) m->data()[k] = d[i++];
  s.discontinuity = n[0] != 0;
  s.image_motion = n[1] != 0;
  s.dr_initialized = n[2] != 0;
  s.fixes_applied = n[3];
  s.fixes_rejected = n[4];
  s.dr_applied = n[5];
  s.dr_rejected = n[6];
  s.consecutive_fix_rejections = n[7];
  s.consecutive_dr_rejections = n[8];
  return s;
}

}  // namespace

size_t FilterStepFile::recordBytes() { return kDoubles * sizeof(double) + kInts * sizeof(int32_t); }

FilterStepFile::FilterStepFile(const std::string& path) : path_(path) {
  file_ = std::fopen(path_.c_str(), "w+b");
  if (!file_) throw std::runtime_error("filter step file " + path_ + ": cannot create it: " + std::strerror(errno));
}

FilterStepFile::~FilterStepFile() {
  if (file_) std::fclose(file_);
  std::remove(path_.c_str());
}

uint64_t FilterStepFile::bytes() const { return steps_ * recordBytes(); }

bool FilterStepFile::append(std::deque<FilterStep>::const_iterator first, std::deque<FilterStep>::const_iterator last) {
  const size_t count = static_cast<size_t>(last - first);
  if (count == 0) return true;
  std::vector<unsigned char> buffer(count * recordBytes());
  size_t k = 0;
  for (auto it = first; it != last; ++it, ++k) encode(*it, buffer.data() + k * recordBytes());
  const long end = static_cast<long>(steps_ * recordBytes());
  bool ok = std::fseek(file_, end, SEEK_SET) == 0 &&
            std::fwrite(buffer.data(), 1, buffer.size(), file_) == buffer.size() && std::fflush(file_) == 0;
  if (!ok) {
    error_ = "cannot append to " + path_ + ": " + std::strerror(errno);
    std::clearerr(file_);
    return false;  // the records past steps_ are garbage and get overwritten by the next append
  }
  steps_ += count;
  error_.clear();
  return true;
}

void FilterStepFile::readAll(std::deque<FilterStep>* out) const {
  if (steps_ == 0) return;
  std::vector<unsigned char> buffer(recordBytes() * 4096);
  if (std::fseek(file_, 0, SEEK_SET) != 0)
    throw std::runtime_error("filter step file " + path_ + ": cannot seek: " + std::strerror(errno));
  uint64_t left = steps_;
  while (left > 0) {
    const size_t n = static_cast<size_t>(std::min<uint64_t>(left, 4096));
    if (std::fread(buffer.data(), recordBytes(), n, file_) != n) {
      std::clearerr(file_);
      throw std::runtime_error("filter step file " + path_ + ": cannot read back its " + std::to_string(steps_) +
                               " steps");
    }
    for (size_t k = 0; k < n; ++k) out->push_back(decode(buffer.data() + k * recordBytes()));
    left -= n;
  }
}

void FilterStepFile::clear() {
  steps_ = 0;
  error_.clear();
  if (std::fflush(file_) == 0 && ::ftruncate(fileno(file_), 0) == 0) return;
  error_ = "cannot truncate " + path_ + ": " + std::strerror(errno);  // the next appends overwrite it anyway
}

}  // namespace fusion
}  // namespace exocet_mosaic
