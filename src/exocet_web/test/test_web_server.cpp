// The web map's HTTP server through real connections on loopback (an ephemeral port): files, status codes, the
// read-only rule, the limit on clients, the live events and their resumption, a client leaving mid-stream, a restart
// on the same port.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <string>
#include <thread>

#include <gtest/gtest.h>

#include "exocet_common/testing/temp_dir.h"
#include "exocet_web/server/web_server.h"

namespace es = exocet_web::server;
using exocet_common::testing::TempDir;

namespace {

/// A raw TCP connection to the server: requests are sent as written (no client-side normalisation of the path).
class Connection {
 public:
  explicit Connection(int port) {
    fd_ = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in address{};
    address.sin_family = AF_INET;
    address.sin_port = htons(static_cast<uint16_t>(port));
    address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    connected_ = ::connect(fd_, reinterpret_cast<sockaddr*>(&address), sizeof(address)) == 0;
  }
  ~Connection() { close(); }
  bool connected() const { return connected_; }
  void send(const std::string& text) { (void)!::write(fd_, text.data(), text.size()); }
  /// Reads until `marker` has arrived (true) or `timeout_s` passed or the server closed (false).
  bool readUntil(const std::string& marker, double timeout_s = 30.0) {
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
    while (received_.find(marker) == std::string::npos) {
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(end - std::chrono::steady_clock::now());
      if (left.count() <= 0 || !readSome(int(left.count()))) return false;
    }
    return true;
  }
  /// Reads until the server closes the connection.
  std::string readAll(double timeout_s = 30.0) {
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
    while (true) {
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(end - std::chrono::steady_clock::now());
      if (left.count() <= 0 || !readSome(int(left.count()))) break;
    }
    return received_;
  }
  const std::string& received() const { return received_; }
  /// Leaves abruptly (a reset, as a browser tab killed).
  void abort() {
    linger l{1, 0};
    ::setsockopt(fd_, SOL_SOCKET, SO_LINGER, &l, sizeof(l));
    close();
  }
  void close() {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
  }

 private:
  bool readSome(int timeout_ms) {
    pollfd p{fd_, POLLIN, 0};
    if (::poll(&p, 1, timeout_ms) <= 0) return false;
    char buffer[65536];
    const ssize_t n = ::read(fd_, buffer, sizeof(buffer));
    if (n <= 0) return false;
    received_.append(buffer, static_cast<size_t>(n));
    return true;
  }
  int fd_ = -1;
  bool connected_ = false;
  std::string received_;
};

struct Reply {
  int status = 0;
  std::map<std::string, std::string> headers;  // lower-case names
  std::string body;
};

/// One request on its own connection ("Connection: close"), the reply parsed (no chunked bodies).
Reply request(int port, const std::string& method, const std::string& target, const std::string& extra_headers = "") {
  Connection c(port);
  EXPECT_TRUE(c.connected());
  c.send(method + " " + target + " HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n" + extra_headers + "\r\n");
  const std::string text = c.readAll();
  Reply r;
  const size_t end = text.find("\r\n\r\n");
  if (text.compare(0, 9, "HTTP/1.1 ") != 0 || end == std::string::npos) return r;
  r.status = std::stoi(text.substr(9, 3));
  size_t line = text.find("\r\n") + 2;
  while (line < end) {
    const size_t next = text.find("\r\n", line);
    const std::string h = text.substr(line, next - line);
    const size_t colon = h.find(':');
    std::string name = h.substr(0, colon);
    for (auto& ch : name) ch = static_cast<char>(std::tolower(ch));
    r.headers[name] = h.substr(colon + 2);
    line = next + 2;
  }
  r.body = text.substr(end + 4);
  return r;
}

/// Polls `condition` until true or 30 s pass (a slow machine only makes it wait longer).
template <typename Condition>
bool eventually(Condition condition) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(30);
  while (std::chrono::steady_clock::now() < end) {
    if (condition()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return condition();
}

struct Site {
  TempDir dir;
  std::string png = std::string("\x89PNG\r\n\x1a\n", 8) + std::string(3000, 'x');  // served as bytes
  Site() {
    std::filesystem::create_directories(dir.file("site/tiles/20/1"));
    std::ofstream(dir.file("site/index.html")) << "<html>map</html>";
    std::ofstream(dir.file("site/tiles/20/1/2.png"), std::ios::binary) << png;
    std::ofstream(dir.file("secret.txt")) << "secret";
    std::filesystem::create_symlink(dir.file("secret.txt"), dir.file("site/leak.txt"));
  }
  std::string root() const { return dir.file("site"); }
};

es::ServerConfig loopback(int max_clients = 8) {
  es::ServerConfig c;
  c.bind_address = "127.0.0.1";
  c.port = 0;  // any free port
  c.max_clients = max_clients;
  c.heartbeat_s = 0.1;
  c.keep_alive_s = 1;
  return c;
}

}  // namespace

TEST(WebServer, ServesTheFolderReadOnly) {
  Site site;
  es::EventStream events;
  es::WebServer server(loopback(), site.root(), &events, [] { return std::string("{\"snapshot\":true}"); });
  server.start();
  const int port = server.port();
  ASSERT_GT(port, 0);

  Reply tile = request(port, "GET", "/tiles/20/1/2.png?r=3");
  EXPECT_EQ(tile.status, 200);
  EXPECT_EQ(tile.body, site.png);
  EXPECT_EQ(tile.headers["content-type"], "image/png");
  EXPECT_EQ(tile.headers["cache-control"], "no-cache");
  ASSERT_FALSE(tile.headers["etag"].empty());
  EXPECT_EQ(request(port, "GET", "/tiles/20/1/2.png", "If-None-Match: " + tile.headers["etag"] + "\r\n").status, 304);
  Reply head = request(port, "HEAD", "/tiles/20/1/2.png");
  EXPECT_EQ(head.status, 200);
  EXPECT_EQ(head.headers["content-length"], std::to_string(site.png.size()));
  EXPECT_TRUE(head.body.empty());
  EXPECT_EQ(request(port, "GET", "/").body, "<html>map</html>");
  Reply state = request(port, "GET", "/state.json");
  EXPECT_EQ(state.status, 200);
  EXPECT_EQ(state.body, "{\"snapshot\":true}");
  EXPECT_EQ(state.headers["cache-control"], "no-store");

  EXPECT_EQ(request(port, "GET", "/tiles/20/1/3.png").status, 404);
  EXPECT_EQ(request(port, "GET", "/tiles/21/1/2.png").status, 404);
  for (const char* bad : {"/../secret.txt", "/%2e%2e/secret.txt", "/tiles/%2e%2e%2f%2e%2e%2fsecret.txt", "//etc/passwd",
                          "/tiles%2f20", "/%zz"}) {
    const int status = request(port, "GET", bad).status;
    EXPECT_TRUE(status == 400 || status == 404) << bad << ": " << status;
  }
  EXPECT_EQ(request(port, "GET", "/leak.txt").status, 403);  // a symbolic link out of the folder
  for (const char* method : {"POST", "PUT", "DELETE", "PATCH", "OPTIONS"}) {
    Reply r = request(port, method, "/index.html", "Content-Length: 0\r\n");
    EXPECT_EQ(r.status, 405) << method;
    EXPECT_EQ(r.headers["allow"], "GET, HEAD") << method;
  }
  // The file is as it was.
  std::ifstream in(site.dir.file("site/index.html"));
  EXPECT_EQ(std::string(std::istreambuf_iterator<char>(in), {}), "<html>map</html>");
  const es::ServerStats stats = server.stats();
  EXPECT_GE(stats.refused, 6u);
  EXPECT_GE(stats.not_found, 2u);
  EXPECT_GE(stats.ok, 5u);
  server.stop();
}

TEST(WebServer, RefusesClientsBeyondTheLimitWith503) {
  Site site;
  es::EventStream events;
  es::WebServer server(loopback(2), site.root(), &events, [] { return std::string("{}"); });
  server.start();
  // Two pages watching: each holds a connection.
  Connection a(server.port()), b(server.port());
  a.send("GET /events HTTP/1.1\r\nHost: x\r\n\r\n");
  b.send("GET /events HTTP/1.1\r\nHost: x\r\n\r\n");
  ASSERT_TRUE(a.readUntil("exocet web map"));
  ASSERT_TRUE(b.readUntil("exocet web map"));
  ASSERT_TRUE(eventually([&] { return server.stats().connections == 2; }));
  Reply busy = request(server.port(), "GET", "/index.html");
  EXPECT_EQ(busy.status, 503);
  EXPECT_FALSE(busy.headers["retry-after"].empty());
  EXPECT_EQ(server.stats().busy, 1u);
  // One leaves: a third is served again.
  a.abort();
  ASSERT_TRUE(eventually([&] { return server.stats().connections == 1; }));
  EXPECT_EQ(request(server.port(), "GET", "/index.html").status, 200);
  server.stop();
}

TEST(WebServer, EventsResumeAfterTheLastIdOrReset) {
  Site site;
  es::EventStream events(4);  // a small ring: an old id falls out of it
  es::WebServer server(loopback(), site.root(), &events, [] { return std::string("{}"); });
  server.start();
  Connection live(server.port());
  live.send("GET /events HTTP/1.1\r\nHost: x\r\n\r\n");
  ASSERT_TRUE(live.readUntil("exocet web map"));
  EXPECT_NE(live.received().find("text/event-stream"), std::string::npos);
  events.publish("tile", "{\"index\":1}");
  ASSERT_TRUE(live.readUntil("data: {\"index\":1}"));
  EXPECT_NE(live.received().find("id: " + events.idText(1) + "\nevent: tile\n"), std::string::npos);
  events.publish("webtiles", "{\"n\":2}");
  events.publish("track", "{\"n\":3}");
  ASSERT_TRUE(live.readUntil("{\"n\":3}"));

  // A browser reconnecting after event 1 gets 2 and 3, not 1.
  Connection again(server.port());
  again.send("GET /events HTTP/1.1\r\nHost: x\r\nLast-Event-ID: " + events.idText(1) + "\r\n\r\n");
  ASSERT_TRUE(again.readUntil("{\"n\":3}"));
  EXPECT_NE(again.received().find("{\"n\":2}"), std::string::npos);
  EXPECT_EQ(again.received().find("{\"index\":1}"), std::string::npos);
  // A page that loaded /state.json at event 0 asks for what follows it.
  Connection page(server.port());
  page.send("GET /events?after=" + events.idText(0) + " HTTP/1.1\r\nHost: x\r\n\r\n");
  ASSERT_TRUE(page.readUntil("{\"n\":3}"));
  EXPECT_NE(page.received().find("{\"index\":1}"), std::string::npos);
  // An id of another run of the node: start over from a snapshot.
  Connection stranger(server.port());
  stranger.send("GET /events HTTP/1.1\r\nHost: x\r\nLast-Event-ID: 0othernode-2\r\n\r\n");
  ASSERT_TRUE(stranger.readUntil("event: reset"));
  // Six more, the first stream reading each before the next is published: the ring holds 4 events, and on a loaded
  // machine the stream's writer may not run between publications made in a burst.
  for (int i = 0; i < 6; ++i) {
    const std::string data = "{\"later\":" + std::to_string(i) + "}";
    events.publish("track", data);
    ASSERT_TRUE(live.readUntil(data)) << "the first stream missed " << data;
  }
  // Too far behind: the ring (4 events) no longer holds event 2.
  Connection behind(server.port());
  behind.send("GET /events HTTP/1.1\r\nHost: x\r\nLast-Event-ID: " + events.idText(1) + "\r\n\r\n");
  ASSERT_TRUE(behind.readUntil("event: reset"));
  server.stop();
}

TEST(WebServer, AClientLeavingMidStreamLeavesTheOthersServed) {
  Site site;
  es::EventStream events;
  es::WebServer server(loopback(), site.root(), &events, [] { return std::string("{}"); });
  server.start();
  Connection leaving(server.port()), staying(server.port());
  leaving.send("GET /events HTTP/1.1\r\nHost: x\r\n\r\n");
  staying.send("GET /events HTTP/1.1\r\nHost: x\r\n\r\n");
  ASSERT_TRUE(leaving.readUntil("exocet web map"));
  ASSERT_TRUE(staying.readUntil("exocet web map"));
  ASSERT_TRUE(eventually([&] { return server.stats().event_streams == 2; }));
  events.publish("tile", "{\"before\":1}");
  ASSERT_TRUE(leaving.readUntil("{\"before\":1}"));
  leaving.abort();
  for (int i = 0; i < 50; ++i) events.publish("track", "{\"after\":" + std::to_string(i) + "}");
  ASSERT_TRUE(staying.readUntil("{\"after\":49}"));
  EXPECT_EQ(request(server.port(), "GET", "/tiles/20/1/2.png").status, 200);
  ASSERT_TRUE(eventually([&] { return server.stats().event_streams == 1; }));
  events.publish("tile", "{\"still\":1}");
  ASSERT_TRUE(staying.readUntil("{\"still\":1}"));
  server.stop();
  EXPECT_EQ(server.stats().event_streams, 0);
}

TEST(WebServer, ARestartListensOnTheSamePortAtOnceAndThePageStartsOver) {
  Site site;
  es::EventStream events;
  auto first = std::make_unique<es::WebServer>(loopback(), site.root(), &events, [] { return std::string("{}"); });
  first->start();
  const int port = first->port();
  // A page watching, and a request the server closed first: its side of that connection is left in TIME_WAIT.
  Connection page(port);
  page.send("GET /events HTTP/1.1\r\nHost: x\r\n\r\n");
  ASSERT_TRUE(page.readUntil("exocet web map"));
  events.publish("tile", "{\"index\":1}");
  ASSERT_TRUE(page.readUntil("{\"index\":1}"));
  EXPECT_EQ(request(port, "GET", "/index.html").status, 200);
  first->stop();
  first.reset();

  // The node started again (respawn): the same port, bound at once, while the page has not closed its connection.
  es::EventStream again_events;
  es::ServerConfig same = loopback();
  same.port = port;
  es::WebServer second(same, site.root(), &again_events, [] { return std::string("{}"); });
  ASSERT_NO_THROW(second.start());
  EXPECT_EQ(second.port(), port);
  EXPECT_EQ(request(port, "GET", "/index.html").status, 200);
  // The browser reconnects with the last id it got, of the killed run: it is told to start over from /state.json.
  Connection reconnected(port);
  reconnected.send("GET /events HTTP/1.1\r\nHost: x\r\nLast-Event-ID: " + events.idText(1) + "\r\n\r\n");
  ASSERT_TRUE(reconnected.readUntil("event: reset"));
  EXPECT_NE(reconnected.received().find("id: " + again_events.idText(0)), std::string::npos);
  second.stop();
}

TEST(WebServer, StartFailuresNameTheAddress) {
  Site site;
  es::EventStream events;
  es::WebServer first(loopback(), site.root(), &events, nullptr);
  first.start();
  es::ServerConfig same = loopback();
  same.port = first.port();
  es::EventStream other_events;
  es::WebServer second(same, site.root(), &other_events, nullptr);
  try {
    second.start();
    FAIL() << "a second server bound the same port";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("127.0.0.1:" + std::to_string(first.port())), std::string::npos) << e.what();
  }
  es::ServerConfig bad = loopback();
  bad.max_clients = 0;
  EXPECT_THROW(es::WebServer(bad, site.root(), &events, nullptr), std::invalid_argument);
  es::WebServer nowhere(loopback(), site.dir.file("missing"), &other_events, nullptr);
  EXPECT_THROW(nowhere.start(), std::runtime_error);
  first.stop();
}
