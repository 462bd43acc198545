/**
 * @file tile_notifier.h
 * @brief The "network message" of a written tile for a GIS that is not a ROS node: one UDP datagram per tile holding
 * the tile's JSON (tile_json.h, documented in config/tiles/UDP_NOTIFICATION.md). No ROS in it.
 *
 * UDP because the GIS may be down or restarted at any time during a dive: sending never blocks nor waits for it.
 */
#pragma once

#include <string>

#include <sys/socket.h>

#include "exocet_mosaic/tiles/tile_raster.h"

namespace exocet_mosaic {
namespace tiles {

/// Largest datagram sent (bytes): well under the 64 KB UDP limit and a typical 8 KB receive buffer of a GIS plugin.
constexpr size_t kMaxTileDatagramBytes = 8191;

/// Sends one JSON datagram per written tile to a fixed host and port.
class TileNotifier {
 public:
  /**
   * @param host numeric IPv4 ("192.168.1.20") or IPv6 ("::1") address, or a host name (resolved once, here)
   * @param port UDP port, [1, 65535]
   * @param bind_address numeric local address the socket is bound to (the station's interface towards the GIS;
   *        "127.0.0.1": this computer only); empty: not bound (the system's choice)
   * @throws std::invalid_argument naming the host or port when the port is out of range or the host does not
   *         resolve, or when a loopback bind address cannot reach the host; std::runtime_error when no socket can be
   *         opened and bound.
   */
  TileNotifier(const std::string& host, int port, const std::string& bind_address = "");
  ~TileNotifier();
  TileNotifier(const TileNotifier&) = delete;
  TileNotifier& operator=(const TileNotifier&) = delete;

  /**
   * @brief Sends tileToJson(tile) in one datagram, without blocking.
   * @param error if not null, set to why the datagram was not sent (too large, send buffer full, network down)
   * @return true when the datagram left (UDP: nothing tells whether anyone received it)
   */
  bool send(const WrittenTile& tile, std::string* error);

  /// "host:port (address)" for logs.
  const std::string& destination() const { return destination_; }

 private:
  int socket_ = -1;
  sockaddr_storage address_{};
  socklen_t address_length_ = 0;
  std::string destination_;
};

}  // namespace tiles
}  // namespace exocet_mosaic
