/**
 * Tests of the tile JSON and its UDP notification: a real tile is written, sent to a socket bound on the loopback,
 * received and parsed with an independent JSON parser (GDAL's CPLJSONDocument, json-c), and every field compared
 * with the WrittenTile.
 */
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <iostream>
#include <limits>
#include <string>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cpl_json.h>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "exocet_common/testing/temp_dir.h"
#include "exocet_mosaic/tiles/geotiff_tile_writer.h"
#include "exocet_mosaic/tiles/tile_json.h"
#include "exocet_mosaic/tiles/tile_notifier.h"

namespace fs = std::filesystem;
using exocet_mosaic::tiles::GeoTiffTileWriter;
using exocet_mosaic::tiles::jsonNumber;
using exocet_mosaic::tiles::TileMetadata;
using exocet_mosaic::tiles::TileNotifier;
using exocet_mosaic::tiles::TileRaster;
using exocet_mosaic::tiles::tileToJson;
using exocet_mosaic::tiles::TileWriterConfig;
using exocet_mosaic::tiles::WrittenTile;

namespace {

/// A UDP socket bound on the loopback (IPv4 or IPv6) at an ephemeral port.
class UdpReceiver {
 public:
  explicit UdpReceiver(int family) {
    fd_ = ::socket(family, SOCK_DGRAM, 0);
    if (fd_ < 0) return;
    sockaddr_storage address{};
    socklen_t length = 0;
    if (family == AF_INET) {
      auto* v4 = reinterpret_cast<sockaddr_in*>(&address);
      v4->sin_family = AF_INET;
      v4->sin_addr.s_addr = htonl(INADDR_LOOPBACK);
      length = sizeof(sockaddr_in);
    } else {
      auto* v6 = reinterpret_cast<sockaddr_in6*>(&address);
      v6->sin6_family = AF_INET6;
      v6->sin6_addr = in6addr_loopback;
      length = sizeof(sockaddr_in6);
    }
    if (::bind(fd_, reinterpret_cast<sockaddr*>(&address), length) != 0 ||
        ::getsockname(fd_, reinterpret_cast<sockaddr*>(&address), &length) != 0) {
      ::close(fd_);
      fd_ = -1;
      return;
    }
    port_ = ntohs(family == AF_INET ? reinterpret_cast<sockaddr_in*>(&address)->sin_port
                                    : reinterpret_cast<sockaddr_in6*>(&address)->sin6_port);
  }
  ~UdpReceiver() {
    if (fd_ >= 0) ::close(fd_);
  }
  bool ok() const { return fd_ >= 0; }
  int port() const { return port_; }
  /// One datagram, or "" after 2 s.
  std::string receive() {
    pollfd p{fd_, POLLIN, 0};
    if (::poll(&p, 1, 2000) <= 0) return "";
    char buffer[65536];
    const ssize_t n = ::recv(fd_, buffer, sizeof(buffer), 0);
    return n > 0 ? std::string(buffer, n) : "";
  }

 private:
  int fd_ = -1;
  int port_ = 0;
};

using TempDir = exocet_common::testing::TempDir;

/// A real tile (zone 56 S, Sydney) with COG and KMZ, so that every path is set.
WrittenTile writeTile(const std::string& folder) {
  TileWriterConfig config;
  config.output_dir = folder;
  config.write_cog = true;
  config.write_kmz = true;
  GeoTiffTileWriter writer(config);
  TileRaster raster;
  raster.image = cv::Mat(64, 80, CV_8UC3, cv::Scalar(10, 120, 200));
  raster.origin_easting_m = 334000.0;
  raster.origin_northing_m = 6252000.0;
  raster.gsd_m = 0.05;
  raster.utm_zone = 56;
  raster.northern_hemisphere = false;
  TileMetadata metadata;
  metadata.dive_name = "sydney_\"harbour\"\\dive\n1";
  metadata.first_frame = 7;
  metadata.last_frame = 913;
  metadata.start_time_s = 1715940000.125;
  metadata.end_time_s = 1715940300.5;
  metadata.mean_altitude_m = 2.5;
  metadata.close_reason = "size";
  metadata.extra["operator"] = "Zo\xC3\xAB";  // UTF-8
  return writer.write(raster, metadata);
}

}  // namespace

TEST(TilesNotifier, SendsTheTileAsJsonThatParsesBackFieldByField) {
  TempDir dir;
  const WrittenTile tile = writeTile(dir.path());
  ASSERT_TRUE(tile.ok) << tile.error;
  UdpReceiver receiver(AF_INET);
  ASSERT_TRUE(receiver.ok());
  TileNotifier notifier("127.0.0.1", receiver.port());
  std::string error = "not cleared";
  ASSERT_TRUE(notifier.send(tile, &error)) << error;
  EXPECT_TRUE(error.empty());
  const std::string datagram = receiver.receive();
  ASSERT_FALSE(datagram.empty()) << "nothing received";
  EXPECT_EQ(datagram, tileToJson(tile));
  EXPECT_LT(datagram.size(), 8192u);
  std::cout << "[ info     ] " << datagram.size() << " bytes: " << datagram << "\n";

  CPLJSONDocument document;
  ASSERT_TRUE(document.LoadMemory(datagram)) << datagram;
  const CPLJSONObject json = document.GetRoot();
  EXPECT_EQ(json.GetString("type"), "exocet_tile");
  EXPECT_EQ(json.GetInteger("version"), 1);
  EXPECT_TRUE(json.GetBool("ok", false));
  EXPECT_EQ(json.GetObj("error").GetType(), CPLJSONObject::Type::Null);
  EXPECT_EQ(json.GetInteger("index", -9), 0);
  EXPECT_EQ(json.GetString("geotiff_path"), dir.path() + "/tile_0000.tif");
  EXPECT_EQ(json.GetString("world_file_path"), dir.path() + "/tile_0000.tfw");
  EXPECT_EQ(json.GetString("cog_path"), dir.path() + "/tile_0000.cog.tif");
  EXPECT_EQ(json.GetString("kmz_path"), dir.path() + "/tile_0000.kmz");
  for (const char* key : {"geotiff_path", "world_file_path", "cog_path", "kmz_path"}) {
    EXPECT_TRUE(fs::exists(json.GetString(key))) << key;
  }
  EXPECT_EQ(json.GetInteger("epsg"), 32756);
  // Numbers read back to the same doubles.
  EXPECT_EQ(json.GetDouble("min_easting_m"), tile.min_easting_m);
  EXPECT_EQ(json.GetDouble("max_easting_m"), 334004.0);
  EXPECT_EQ(json.GetDouble("min_northing_m"), 6251996.8);
  EXPECT_EQ(json.GetDouble("max_northing_m"), 6252000.0);
  EXPECT_EQ(json.GetDouble("gsd_m"), 0.05);
  EXPECT_EQ(json.GetInteger("width_px"), 80);
  EXPECT_EQ(json.GetInteger("height_px"), 64);
  EXPECT_EQ(json.GetDouble("west_deg"), tile.west_deg);
  EXPECT_EQ(json.GetDouble("south_deg"), tile.south_deg);
  EXPECT_EQ(json.GetDouble("east_deg"), tile.east_deg);
  EXPECT_EQ(json.GetDouble("north_deg"), tile.north_deg);
  EXPECT_LT(json.GetDouble("north_deg"), -33.0);
  EXPECT_GT(json.GetDouble("west_deg"), 151.0);
  EXPECT_EQ(json.GetString("dive_name"), "sydney_\"harbour\"\\dive\n1");
  EXPECT_EQ(json.GetInteger("first_frame"), 7);
  EXPECT_EQ(json.GetInteger("last_frame"), 913);
  EXPECT_EQ(json.GetDouble("start_time_s"), 1715940000.125);
  EXPECT_EQ(json.GetDouble("end_time_s"), 1715940300.5);
  EXPECT_EQ(json.GetDouble("mean_altitude_m"), 2.5);
  EXPECT_EQ(json.GetString("close_reason"), "size");
  EXPECT_EQ(json.GetString("software"), "Exocet");
  EXPECT_EQ(json.GetObj("extra").GetString("operator"), "Zo\xC3\xAB");
  EXPECT_GT(json.GetDouble("write_ms"), 0.0);
}

TEST(TilesNotifier, HostNamesAndIpv6AreAccepted) {
  WrittenTile tile;
  tile.ok = true;
  tile.index = 3;
  UdpReceiver v4(AF_INET);
  ASSERT_TRUE(v4.ok());
  TileNotifier by_name("localhost", v4.port());
  std::string error;
  // "localhost" may resolve to ::1 first: then the IPv4 receiver gets nothing, and that is not the notifier's fault.
  if (by_name.destination().find("127.0.0.1") != std::string::npos) {
    ASSERT_TRUE(by_name.send(tile, &error)) << error;
    EXPECT_NE(v4.receive().find("\"index\":3"), std::string::npos);
  }
  UdpReceiver v6(AF_INET6);
  if (!v6.ok()) GTEST_SKIP() << "no IPv6 loopback here";
  TileNotifier ipv6("::1", v6.port());
  ASSERT_TRUE(ipv6.send(tile, &error)) << error;
  EXPECT_NE(v6.receive().find("\"index\":3"), std::string::npos);
}

TEST(TilesNotifier, TheSocketIsBoundToTheAddressItIsGiven) {
  WrittenTile tile;
  tile.ok = true;
  tile.index = 4;
  UdpReceiver v4(AF_INET);
  ASSERT_TRUE(v4.ok());
  TileNotifier bound("127.0.0.1", v4.port(), "127.0.0.1");
  std::string error;
  ASSERT_TRUE(bound.send(tile, &error)) << error;
  EXPECT_NE(v4.receive().find("\"index\":4"), std::string::npos);
  // Bound to loopback (the default of the node), it cannot reach another host: said at once, not at the first tile.
  try {
    TileNotifier unreachable("10.1.2.3", 5005, "127.0.0.1");
    FAIL() << "a loopback socket towards another host was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("loopback"), std::string::npos) << e.what();
  }
  EXPECT_THROW(TileNotifier("127.0.0.1", 5005, "not-an-address"), std::runtime_error);
  EXPECT_THROW(TileNotifier("127.0.0.1", 5005, "192.0.2.77"), std::runtime_error);  // not this machine's
}

TEST(TilesNotifier, BadHostOrPortGivesAClearError) {
  try {
    TileNotifier notifier("no.such.host.invalid", 5005);
    FAIL() << "a host that does not resolve was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("no.such.host.invalid"), std::string::npos) << e.what();
  }
  for (const int port : {0, -1, 65536}) {
    try {
      TileNotifier notifier("127.0.0.1", port);
      FAIL() << "port " << port << " accepted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("65535"), std::string::npos) << e.what();
    }
  }
  EXPECT_THROW(TileNotifier("", 5005), std::invalid_argument);
  // Nobody listening is not an error for UDP: the send still succeeds, and so does the next one.
  TileNotifier nobody("127.0.0.1", 9);
  std::string error;
  EXPECT_TRUE(nobody.send(WrittenTile(), &error)) << error;
  EXPECT_TRUE(nobody.send(WrittenTile(), &error)) << error;
}

TEST(TilesNotifier, OversizedDatagramIsRefused) {
  UdpReceiver receiver(AF_INET);
  ASSERT_TRUE(receiver.ok());
  TileNotifier notifier("127.0.0.1", receiver.port());
  WrittenTile tile;
  tile.metadata.extra["notes"] = std::string(9000, 'x');
  std::string error;
  EXPECT_FALSE(notifier.send(tile, &error));
  EXPECT_NE(error.find("8191"), std::string::npos) << error;
}

TEST(TilesJson, StringsAreEscapedAndAlwaysValidUtf8) {
  const char kNasty[] = "q\"b\\s/\n\t\r\b\f nul\0x\x01\x1f caf\xC3\xA9 \xE2\x82\xAC \xF0\x9F\x90\x9F";
  const std::string nasty(kNasty, sizeof(kNasty) - 1);
  WrittenTile tile;
  tile.metadata.dive_name = nasty;
  tile.metadata.extra["latin1"] = "latin1 caf\xE9!";      // not UTF-8
  tile.metadata.extra["overlong"] = "overlong \xC0\xAF";  // '/' in two bytes
  tile.metadata.extra["cut"] = "cut \xE2\x82";
  tile.metadata.extra["surrogate"] = "surrogate \xED\xA0\x80";
  const std::string text = tileToJson(tile);
  EXPECT_EQ(text.find('\n'), std::string::npos) << "one line";
  EXPECT_NE(text.find("\"q\\\"b\\\\s/\\n\\t\\r\\b\\f nul\\u0000x\\u0001\\u001f caf\xC3\xA9 \xE2\x82\xAC"),
            std::string::npos)
      << text;
  // Read back (the parser refuses invalid UTF-8): the escapes give the text back, NUL included.
  nlohmann::json parsed;
  ASSERT_NO_THROW(parsed = nlohmann::json::parse(text)) << text;
  EXPECT_EQ(parsed["dive_name"], nasty);
  // GDAL's parser too; the bytes that are not UTF-8 became U+FFFD, and nothing else changed.
  CPLJSONDocument document;
  ASSERT_TRUE(document.LoadMemory(text)) << text;
  const CPLJSONObject json = document.GetRoot();
  EXPECT_EQ(json.GetString("dive_name"), nasty.substr(0, nasty.find('\0')));  // a C string: up to the NUL
  EXPECT_EQ(json.GetObj("extra").GetString("latin1"), "latin1 caf\xEF\xBF\xBD!");
  for (const std::string key : {"overlong", "cut", "surrogate"}) {
    const std::string value = json.GetObj("extra").GetString(key);
    ASSERT_EQ(value.rfind(key + " ", 0), 0u) << value;
    const std::string replaced = value.substr(key.size() + 1);
    ASSERT_FALSE(replaced.empty()) << key;
    for (size_t i = 0; i < replaced.size(); i += 3) EXPECT_EQ(replaced.substr(i, 3), "\xEF\xBF\xBD") << key;
  }
}

TEST(TilesJson, NumbersRoundTripAndNonFiniteIsNull) {
  for (const double value : {0.0, 0.05, -33.8612345678901, 6252000.123456789, 1715940000.125, 1e-7, 123456789.0}) {
    EXPECT_EQ(std::stod(jsonNumber(value)), value) << jsonNumber(value);
  }
  EXPECT_EQ(jsonNumber(0.05), "0.05");
  EXPECT_EQ(jsonNumber(std::numeric_limits<double>::quiet_NaN()), "null");
  EXPECT_EQ(jsonNumber(std::numeric_limits<double>::infinity()), "null");
  WrittenTile tile;  // a failed tile: paths null, error set, altitude unknown
  tile.error = "cannot create GeoTIFF '/x/.tile_0000.tif.partial': No space left on device";
  CPLJSONDocument document;
  ASSERT_TRUE(document.LoadMemory(tileToJson(tile)));
  const CPLJSONObject json = document.GetRoot();
  EXPECT_FALSE(json.GetBool("ok", true));
  EXPECT_EQ(json.GetString("error"), tile.error);
  EXPECT_EQ(json.GetObj("geotiff_path").GetType(), CPLJSONObject::Type::Null);
  EXPECT_EQ(json.GetObj("mean_altitude_m").GetType(), CPLJSONObject::Type::Null);
  EXPECT_EQ(json.GetObj("extra").GetType(), CPLJSONObject::Type::Object);
}
