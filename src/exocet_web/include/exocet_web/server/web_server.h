/**
 * @file web_server.h
 * @brief The web map's HTTP server (cpp-httplib): read-only, one folder, a bounded number of connections, the live
 * events as Server-Sent Events. No ROS in it.
 *
 * - GET and HEAD only; any other method gets 405 (Allow: GET, HEAD).
 * - Files of the served folder only (request_path.h): 400 for a malformed target or a traversal attempt, 403 for a
 *   symbolic link leading out, 404 for anything missing. Files are sent with an ETag (size and modification time)
 *   and Cache-Control: no-cache, so that a browser revalidates a web tile that was re-cut (304 when unchanged).
 * - /events: text/event-stream of EventStream; resumes after the Last-Event-ID header (a reconnecting browser) or
 *   the ?after=<id> parameter (a page that just loaded /state.json), or sends "reset" when it cannot; a comment
 *   line every heartbeat keeps proxies open and finds clients that left.
 * - /state.json: the snapshot function's JSON (not cached).
 * - Each connection has its own thread (cpp-httplib); at most max_clients connections are served at once: one
 *   more is answered 503 (Retry-After) and closed, without waiting. The threads run niced, so that browsers never
 *   take CPU from the mosaicking chain.
 */
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <thread>

#include "exocet_web/server/event_stream.h"

namespace httplib {
class Server;
}

namespace exocet_web {
namespace server {

/// Server settings. validate() lists the allowed values.
struct ServerConfig {
  std::string bind_address = "127.0.0.1";  ///< IPv4/IPv6 address or host name to listen on (0.0.0.0: every interface)
  int port = 8080;                         ///< [0, 65535]; 0: any free port (see WebServer::port())
  int max_clients = 64;                    ///< connections served at once, [1, 1024] (a browser opens up to 6)
  int keep_alive_s = 2;                    ///< an idle keep-alive connection is closed after this, [1, 60] s
  double heartbeat_s = 10.0;               ///< SSE comment period, [0.05, 60] s
  int thread_nice = 10;                    ///< niceness added to the server threads, [0, 19]

  /// Empty if usable; otherwise every bad field with its allowed range, "; "-separated.
  std::string validate() const;
};

/// Counters since start.
struct ServerStats {
  int connections = 0;    ///< open now
  int event_streams = 0;  ///< SSE clients now
  uint64_t requests = 0;
  uint64_t ok = 0;          ///< 200 and 304
  uint64_t not_found = 0;   ///< 404
  uint64_t refused = 0;     ///< 400, 403, 405
  uint64_t busy = 0;        ///< 503 (beyond max_clients)
  uint64_t bytes_sent = 0;  ///< file and snapshot bodies
};

class WebServer {
 public:
  /// The JSON text of /state.json.
  using SnapshotFunction = std::function<std::string()>;
  /// Called after each request with the method, target, status (an access log).
  using AccessLog = std::function<void(const std::string& method, const std::string& target, int status)>;

  /**
   * @param root_dir the served folder (must exist when start() is called)
   * @param events   the live events (outlives the server)
   * @throws std::invalid_argument with ServerConfig::validate()'s message
   */
  WebServer(const ServerConfig& config, std::string root_dir, EventStream* events, SnapshotFunction snapshot,
            AccessLog access_log = nullptr);
  /// stop()s.
  ~WebServer();
  WebServer(const WebServer&) = delete;
  WebServer& operator=(const WebServer&) = delete;

  /**
   * @brief Binds and starts serving in background threads.
   * @throws std::runtime_error naming the address and port when it cannot bind (in use, no such address, no
   *         permission) or the folder does not exist
   */
  void start();
  /// Stops accepting, ends the event streams and joins every thread (within about keep_alive_s). Idempotent.
  void stop();
  /// The port listened on (the one chosen when config port is 0); 0 before start().
  int port() const { return port_; }
  ServerStats stats() const;
  const ServerConfig& config() const { return config_; }

 private:
  class ConnectionPool;
  struct Counters;
  void serveFile(const std::string& target, const std::string& if_none_match, bool head, void* response);
  void serveEvents(const std::string& last_event_id, const std::string& after, void* response);

  ServerConfig config_;
  std::string root_dir_;
  std::string root_canonical_;
  EventStream* events_;
  SnapshotFunction snapshot_;
  AccessLog access_log_;
  std::unique_ptr<httplib::Server> http_;
  std::shared_ptr<Counters> counters_;
  std::thread listener_;
  int port_ = 0;
  std::atomic<bool> stopped_{false};
};

}  // namespace server
}  // namespace exocet_web
