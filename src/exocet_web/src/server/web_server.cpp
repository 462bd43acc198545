#include "exocet_web/server/web_server.h"

#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <csignal>
#include <deque>
#include <fstream>
#include <mutex>
#include <stdexcept>
#include <vector>

#include <httplib.h>

#include "exocet_common/background_priority.h"
#include "exocet_web/server/request_path.h"

namespace exocet_web {
namespace server {

namespace {

// Whether the connection this thread serves is beyond max_clients: set by the pool before it runs the connection,
// read by the request handler, which then answers 503.
thread_local bool t_over_limit = false;

constexpr int kSpareThreads = 4;  // threads beyond max_clients, to answer 503 rather than leave a client waiting
constexpr size_t kInMemoryFileLimit_bytes = 4u << 20;  // larger files (an MBTiles export) are streamed

std::string contentType(const std::string& path) {
  static const std::vector<std::pair<std::string, std::string>> kTypes = {{".png", "image/png"},
                                                                          {".html", "text/html; charset=utf-8"},
                                                                          {".js", "text/javascript; charset=utf-8"},
                                                                          {".css", "text/css; charset=utf-8"},
                                                                          {".json", "application/json"},
                                                                          {".svg", "image/svg+xml"},
                                                                          {".jpg", "image/jpeg"},
                                                                          {".webp", "image/webp"},
                                                                          {".txt", "text/plain; charset=utf-8"},
                                                                          {".map", "application/json"},
                                                                          {".mbtiles", "application/vnd.sqlite3"},
                                                                          {".gpkg", "application/geopackage+sqlite3"}};
  for (const auto& [extension, type] : kTypes)
    if (path.size() > extension.size() &&
        path.compare(path.size() - extension.size(), extension.size(), extension) == 0)
      return type;
  return "application/octet-stream";
}

}  // namespace

struct WebServer::Counters {
  std::atomic<int> connections{0};
  std::atomic<int> event_streams{0};
  std::atomic<uint64_t> requests{0}, ok{0}, not_found{0}, refused{0}, busy{0}, bytes_sent{0};
};

/// cpp-httplib's task queue: one job per accepted connection. A fixed set of niced threads; the connections beyond
/// max_clients are still run (on the spare threads), marked over the limit, so that they are answered 503 at once.
class WebServer::ConnectionPool : public httplib::TaskQueue {
 public:
  ConnectionPool(int max_clients, int nice, std::shared_ptr<Counters> counters)
      : max_clients_(max_clients), counters_(std::move(counters)) {
    for (int i = 0; i < max_clients + kSpareThreads; ++i) {
      threads_.emplace_back([this, nice] {
        if (nice > 0) exocet_common::lowerThisThreadPriority(nice);
        run();
      });
    }
  }
  ~ConnectionPool() override = default;

  void enqueue(std::function<void()> job) override {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      jobs_.push_back(std::move(job));
    }
    cv_.notify_one();
  }

  void shutdown() override {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stop_ = true;
    }
    cv_.notify_all();
    for (auto& t : threads_) t.join();
  }

 private:
  void run() {
    while (true) {
      std::function<void()> job;
      {
        std::unique_lock<std::mutex> lock(mutex_);
        cv_.wait(lock, [&] { return stop_ || !jobs_.empty(); });
        if (jobs_.empty()) return;  // stopping, nothing left
        job = std::move(jobs_.front());
        jobs_.pop_front();
      }
      const int open = ++counters_->connections;
      t_over_limit = open > max_clients_;
      job();
      --counters_->connections;
      t_over_limit = false;
    }
  }

  const int max_clients_;
  std::shared_ptr<Counters> counters_;
  std::vector<std::thread> threads_;
  std::mutex mutex_;
  std::condition_variable cv_;
  std::deque<std::function<void()>> jobs_;
  bool stop_ = false;
};

std::string ServerConfig::validate() const {
  std::vector<std::string> errors;
  if (bind_address.empty()) errors.push_back("bind_address is empty");
  if (port < 0 || port > 65535) errors.push_back("port " + std::to_string(port) + " outside [0, 65535]");
  if (max_clients < 1 || max_clients > 1024)
    errors.push_back("max_clients " + std::to_string(max_clients) + " outside [1, 1024]");
  if (keep_alive_s < 1 || keep_alive_s > 60)
    errors.push_back("keep_alive_s " + std::to_string(keep_alive_s) + " outside [1, 60]");
  if (!(heartbeat_s >= 0.05 && heartbeat_s <= 60.0))
    errors.push_back("heartbeat_s " + std::to_string(heartbeat_s) + " outside [0.05, 60]");
  if (thread_nice < 0 || thread_nice > 19)
    errors.push_back("thread_nice " + std::to_string(thread_nice) + " outside [0, 19]");
  std::string joined;
  for (const auto& e : errors) joined += (joined.empty() ? "" : "; ") + e;
  return joined;
}

WebServer::WebServer(const ServerConfig& config, std::string root_dir, EventStream* events, SnapshotFunction snapshot,
                     AccessLog access_log)
    : config_(config),
      root_dir_(std::move(root_dir)),
      events_(events),
      snapshot_(std::move(snapshot)),
      access_log_(std::move(access_log)),
      counters_(std::make_shared<Counters>()) {
  const std::string error = config_.validate();
  if (!error.empty()) throw std::invalid_argument("web server: " + error);
  if (!events_) throw std::invalid_argument("web server: no event stream");
}

WebServer::~WebServer() { stop(); }

void WebServer::start() {
  if (http_) throw std::logic_error("web server already started");
  root_canonical_ = canonicalFolder(root_dir_);
  if (root_canonical_.empty()) throw std::runtime_error("web server: no folder '" + root_dir_ + "' to serve");
  // A client that leaves mid-response must not kill the process (cpp-httplib writes with send()).
  std::signal(SIGPIPE, SIG_IGN);
  http_ = std::make_unique<httplib::Server>();
  const int max_clients = config_.max_clients, nice = config_.thread_nice;
  auto counters = counters_;
  http_->new_task_queue = [max_clients, nice, counters] { return new ConnectionPool(max_clients, nice, counters); };
  // SO_REUSEADDR (a restart binds again at once) but not cpp-httplib's default SO_REUSEPORT, with which a second
  // node on the same port would share the connections silently instead of failing.
  http_->set_socket_options([](socket_t sock) {
    int yes = 1;
    ::setsockopt(sock, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof(yes));
  });
  http_->set_keep_alive_timeout(config_.keep_alive_s);
  http_->set_keep_alive_max_count(100);
  http_->set_read_timeout(5, 0);
  http_->set_write_timeout(5, 0);  // a browser that stops reading is dropped after 5 s, not waited for
  http_->set_pre_routing_handler([this](const httplib::Request& req, httplib::Response& res) {
    ++counters_->requests;
    if (t_over_limit) {
      res.status = 503;
      res.set_header("Retry-After", "2");
      res.set_header("Connection", "close");
      res.set_content("busy: " + std::to_string(config_.max_clients) + " connections served already\n", "text/plain");
    } else if (req.method != "GET" && req.method != "HEAD") {
      res.status = 405;
      res.set_header("Allow", "GET, HEAD");
      res.set_header("Connection", "close");
      res.set_content("read-only: GET and HEAD only\n", "text/plain");
    } else {
      const std::string path = req.target.substr(0, req.target.find_first_of("?#"));
      if (path == "/events") {
        serveEvents(req.get_header_value("Last-Event-ID"), req.get_param_value("after"), &res);
      } else if (path == "/state.json") {
        res.status = 200;
        res.set_header("Cache-Control", "no-store");
        const std::string body = snapshot_ ? snapshot_() : std::string("{}");
        counters_->bytes_sent += body.size();
        res.set_content(body, "application/json");
      } else {
        serveFile(req.target, req.get_header_value("If-None-Match"), req.method == "HEAD", &res);
      }
    }
    const int s = res.status;
    if (s == 200 || s == 304)
      ++counters_->ok;
    else if (s == 404)
      ++counters_->not_found;
    else if (s == 503)
      ++counters_->busy;
    else
      ++counters_->refused;
    if (access_log_) access_log_(req.method, req.target, s);
    return httplib::Server::HandlerResponse::Handled;
  });
  // Requests cpp-httplib refuses before routing (a method it does not know, a header too long) get a body too.
  http_->set_error_handler([](const httplib::Request&, httplib::Response& res) {
    if (res.body.empty()) res.set_content("error " + std::to_string(res.status) + "\n", "text/plain");
  });

  if (config_.port == 0) {
    port_ = http_->bind_to_any_port(config_.bind_address);
    if (port_ <= 0) port_ = 0;
  } else if (http_->bind_to_port(config_.bind_address, config_.port)) {
    port_ = config_.port;
  }
  if (port_ == 0) {
    const std::string why = std::strerror(errno);
    http_.reset();
    throw std::runtime_error("web server: cannot listen on " + config_.bind_address + ":" +
                             std::to_string(config_.port) + " (" + why + ")");
  }
  listener_ = std::thread([this] { http_->listen_after_bind(); });
  // cpp-httplib's stop() does nothing before its loop runs: wait for it, so that stop() always ends the listener.
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (!http_->is_running() && std::chrono::steady_clock::now() < give_up)
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
}

void WebServer::stop() {
  if (!http_ || stopped_.exchange(true)) return;
  events_->shutdown();  // wakes the event streams, which then end
  http_->stop();
  if (listener_.joinable()) listener_.join();
}

ServerStats WebServer::stats() const {
  ServerStats s;
  s.connections = counters_->connections;
  s.event_streams = counters_->event_streams;
  s.requests = counters_->requests;
  s.ok = counters_->ok;
  s.not_found = counters_->not_found;
  s.refused = counters_->refused;
  s.busy = counters_->busy;
  s.bytes_sent = counters_->bytes_sent;
  return s;
}

void WebServer::serveFile(const std::string& target, const std::string& if_none_match, bool head, void* response) {
  auto& res = *static_cast<httplib::Response*>(response);
  const RequestPath request = parseRequestTarget(target);
  if (request.status != 200) {
    res.status = request.status;
    res.set_content(request.reason + "\n", "text/plain");
    return;
  }
  const ResolvedFile file = resolveInside(root_canonical_, request.relative);
  if (file.status != 200) {
    res.status = file.status;
    res.set_content(file.status == 404 ? "not found\n" : "forbidden\n", "text/plain");
    return;
  }
  struct stat st {};
  if (::stat(file.path.c_str(), &st) != 0) {
    res.status = 404;
    res.set_content("not found\n", "text/plain");
    return;
  }
  const std::string etag = "\"" + std::to_string(st.st_size) + "-" + std::to_string(st.st_mtim.tv_sec) + "." +
                           std::to_string(st.st_mtim.tv_nsec) + "\"";
  res.set_header("ETag", etag);
  res.set_header("Cache-Control", "no-cache");  // revalidate: a web tile may have been re-cut
  if (!if_none_match.empty() && if_none_match == etag) {
    res.status = 304;
    return;
  }
  const std::string type = contentType(file.path);
  const auto size = static_cast<size_t>(st.st_size);
  res.status = 200;
  if (size <= kInMemoryFileLimit_bytes) {
    std::ifstream in(file.path, std::ios::binary);
    std::string body(size, '\0');
    if (!in.read(body.data(), static_cast<std::streamsize>(size))) {
      res.status = 404;  // removed or truncated meanwhile (a web tile being replaced is renamed, never truncated)
      res.set_content("not found\n", "text/plain");
      return;
    }
    if (!head) counters_->bytes_sent += size;
    res.set_content(std::move(body), type);
    return;
  }
  auto in = std::make_shared<std::ifstream>(file.path, std::ios::binary);
  auto counters = counters_;
  res.set_content_provider(size, type, [in, counters](size_t offset, size_t length, httplib::DataSink& sink) {
    std::vector<char> buffer(std::min<size_t>(length, 256 * 1024));
    in->seekg(static_cast<std::streamoff>(offset));
    in->read(buffer.data(), static_cast<std::streamsize>(buffer.size()));
    const auto n = static_cast<size_t>(in->gcount());
    if (n == 0) return false;
    counters->bytes_sent += n;
    return sink.write(buffer.data(), n);
  });
}

void WebServer::serveEvents(const std::string& last_event_id, const std::string& after, void* response) {
  auto& res = *static_cast<httplib::Response*>(response);
  // Where to resume: the browser's Last-Event-ID (it reconnects by itself) wins over the page's ?after=.
  std::optional<uint64_t> resume = events_->parseId(last_event_id);
  bool reset = !last_event_id.empty() && !resume;  // an id of another run: start over from a snapshot
  if (!resume && !reset) {
    resume = events_->parseId(after);
    reset = !after.empty() && !resume;
  }
  struct StreamState {
    uint64_t after_id = 0;
    bool greeted = false;
    bool reset = false;
  };
  auto state = std::make_shared<StreamState>();
  state->after_id = resume.value_or(events_->lastId());
  state->reset = reset;
  res.status = 200;
  res.set_header("Cache-Control", "no-store");
  res.set_header("X-Accel-Buffering", "no");
  ++counters_->event_streams;
  auto counters = counters_;
  EventStream* events = events_;
  const auto heartbeat = std::chrono::milliseconds(static_cast<int64_t>(config_.heartbeat_s * 1000.0));
  res.set_chunked_content_provider(
      "text/event-stream",
      [state, events, heartbeat](size_t, httplib::DataSink& sink) {
        std::string text;
        if (!state->greeted) {
          state->greeted = true;
          text = "retry: 2000\n: exocet web map\n\n";
        }
        bool gap = false;
        std::vector<Event> batch;
        if (!state->reset) batch = events->waitAfter(state->after_id, heartbeat, &gap);
        if (events->isShutdown()) {
          sink.done();
          return true;
        }
        if (gap || state->reset) {
          // Too far behind, or another run's id: the page reloads /state.json and goes on from here.
          state->reset = false;
          state->after_id = events->lastId();
          text += "id: " + events->idText(state->after_id) + "\nevent: reset\ndata: {}\n\n";
        }
        for (const Event& e : batch) {
          text += events->format(e);
          state->after_id = e.id;
        }
        if (text.empty()) text = ": heartbeat\n\n";
        return sink.write(text.data(), text.size());
      },
      [counters](bool) { --counters->event_streams; });
}

}  // namespace server
}  // namespace exocet_web
