#include "exocet_web/server/event_stream.h"

#include <unistd.h>

#include <algorithm>
#include <stdexcept>

namespace exocet_web {
namespace server {

namespace {

std::string makeEpoch() {
  // Wall clock in microseconds and the pid, base 36: distinct for every run of the node.
  const auto us =
      std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::system_clock::now().time_since_epoch())
          .count();
  const auto base36 = [](uint64_t v) {
    std::string s;
    do {
      s += "0123456789abcdefghijklmnopqrstuvwxyz"[v % 36];
      v /= 36;
    } while (v);
    return std::string(s.rbegin(), s.rend());
  };
  return base36(static_cast<uint64_t>(us)) + "x" + base36(static_cast<uint64_t>(::getpid()));
}

}  // namespace

EventStream::EventStream(size_t capacity) : capacity_(std::max<size_t>(1, capacity)), epoch_(makeEpoch()) {}

uint64_t EventStream::publish(const std::string& type, const std::string& data) {
  if (data.find_first_of("\r\n") != std::string::npos || type.find_first_of("\r\n") != std::string::npos)
    throw std::invalid_argument("an SSE event's type and data must be one line");
  uint64_t id;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    id = ++last_id_;
    ring_.push_back({id, type, data});
    while (ring_.size() > capacity_) ring_.pop_front();
  }
  cv_.notify_all();
  return id;
}

uint64_t EventStream::lastId() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return last_id_;
}

std::vector<Event> EventStream::waitAfter(uint64_t after_id, std::chrono::milliseconds timeout, bool* gap) {
  std::unique_lock<std::mutex> lock(mutex_);
  if (gap) *gap = false;
  cv_.wait_for(lock, timeout, [&] { return shutdown_ || last_id_ > after_id; });
  std::vector<Event> out;
  if (shutdown_ || last_id_ <= after_id) return out;
  // The ring holds ids [front, last]: a reader behind front has missed some.
  if (ring_.empty() || ring_.front().id > after_id + 1) {
    if (gap) *gap = true;
    return out;
  }
  for (auto it = ring_.begin(); it != ring_.end(); ++it)
    if (it->id > after_id) out.push_back(*it);
  return out;
}

void EventStream::shutdown() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    shutdown_ = true;
  }
  cv_.notify_all();
}

bool EventStream::isShutdown() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return shutdown_;
}

std::string EventStream::idText(uint64_t id) const { return epoch_ + "-" + std::to_string(id); }

std::string EventStream::format(const Event& event) const {
  return "id: " + idText(event.id) + "\nevent: " + event.type + "\ndata: " + event.data + "\n\n";
}

std::optional<uint64_t> EventStream::parseId(const std::string& text) const {
  const size_t dash = text.rfind('-');
  if (dash == std::string::npos || text.compare(0, dash, epoch_) != 0 || dash != epoch_.size()) return std::nullopt;
  const std::string digits = text.substr(dash + 1);
  if (digits.empty() || digits.size() > 19 || digits.find_first_not_of("0123456789") != std::string::npos)
    return std::nullopt;
  return std::stoull(digits);
}

}  // namespace server
}  // namespace exocet_web
