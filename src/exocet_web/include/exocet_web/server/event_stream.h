/**
 * @file event_stream.h
 * @brief The live events of the web map (a new tile, web tiles re-cut, the track grown, a USBL fix) kept in a ring
 * for Server-Sent Events: each event has an id, so that a page reconnecting with its Last-Event-ID gets what it
 * missed, or a "reset" when the ring no longer holds it (then it reloads /state.json). No ROS in it.
 */
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

namespace exocet_web {
namespace server {

/// One event: an SSE "event:" type and a one-line "data:" (JSON).
struct Event {
  uint64_t id = 0;  ///< 1, 2, ... in publication order
  std::string type;
  std::string data;
};

/// Thread-safe: any thread publishes, any number of server threads wait.
class EventStream {
 public:
  /// @param capacity events kept for reconnecting pages, >= 1
  explicit EventStream(size_t capacity = 4096);

  /// Publishes an event (`data` must hold no newline) and wakes the waiting streams. @return its id
  uint64_t publish(const std::string& type, const std::string& data);

  /// Id of the last event published (0: none yet).
  uint64_t lastId() const;

  /// This process's stream name: ids of another run (a restarted node) are not taken for ours.
  const std::string& epoch() const { return epoch_; }

  /**
   * @brief The events after `after_id`, waiting up to `timeout` for one when there is none yet.
   * @param gap set to true when events after `after_id` have left the ring (the reader must start over from a
   *            snapshot); the events returned then start after the snapshot point, i.e. none.
   * @return empty on timeout or after shutdown()
   */
  std::vector<Event> waitAfter(uint64_t after_id, std::chrono::milliseconds timeout, bool* gap);

  /// Wakes every waiter for good (the server stops).
  void shutdown();
  bool isShutdown() const;

  /// The SSE text of an event: "id: <epoch>-<id>\nevent: <type>\ndata: <data>\n\n".
  std::string format(const Event& event) const;
  /// The id in "<epoch>-<id>" (Last-Event-ID) when the epoch is ours; nullopt otherwise.
  std::optional<uint64_t> parseId(const std::string& text) const;
  /// "<epoch>-<id>".
  std::string idText(uint64_t id) const;

 private:
  const size_t capacity_;
  const std::string epoch_;
  mutable std::mutex mutex_;
  std::condition_variable cv_;
  std::deque<Event> ring_;
  uint64_t last_id_ = 0;
  bool shutdown_ = false;
};

}  // namespace server
}  // namespace exocet_web
