#include "exocet_mosaic/tiles/tile_notifier.h"

#include <cerrno>
#include <cstring>
#include <stdexcept>

#include <arpa/inet.h>
#include <fcntl.h>
#include <netdb.h>
#include <unistd.h>

#include "exocet_mosaic/tiles/tile_json.h"

namespace exocet_mosaic {
namespace tiles {

namespace {

bool isLoopback(const sockaddr* address) {
  if (address->sa_family == AF_INET)
    return (ntohl(reinterpret_cast<const sockaddr_in*>(address)->sin_addr.s_addr) >> 24) == 127;
  if (address->sa_family == AF_INET6) {
    const in6_addr& a = reinterpret_cast<const sockaddr_in6*>(address)->sin6_addr;
    return IN6_IS_ADDR_LOOPBACK(&a) || (IN6_IS_ADDR_V4MAPPED(&a) && a.s6_addr[12] == 127);
  }
  return false;
}

}  // namespace

TileNotifier::TileNotifier(const std::string& host, int port, const std::string& bind_address) {
  if (port < 1 || port > 65535) {
    throw std::invalid_argument("UDP notification port " + std::to_string(port) + " out of range [1, 65535]");
  }
  if (host.empty()) throw std::invalid_argument("UDP notification host is empty (an IPv4/IPv6 address or a name)");
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_DGRAM;
  hints.ai_protocol = IPPROTO_UDP;
  hints.ai_flags = AI_NUMERICSERV;
  addrinfo* found = nullptr;
  const int resolved = ::getaddrinfo(host.c_str(), std::to_string(port).c_str(), &hints, &found);
  if (resolved != 0) {
    throw std::invalid_argument("UDP notification host '" + host + "' does not resolve: " + gai_strerror(resolved));
  }
  std::string last_error = "no address";
  for (const addrinfo* candidate = found; candidate; candidate = candidate->ai_next) {
    const int fd =
        ::socket(candidate->ai_family, candidate->ai_socktype | SOCK_NONBLOCK | SOCK_CLOEXEC, candidate->ai_protocol);
    if (fd < 0) {
      last_error = std::strerror(errno);
      continue;
    }
    if (!bind_address.empty()) {
      // The socket's own address: the station's interface towards the GIS (loopback: this computer only).
      addrinfo local_hints{};
      local_hints.ai_family = candidate->ai_family;
      local_hints.ai_socktype = SOCK_DGRAM;
      local_hints.ai_flags = AI_NUMERICHOST | AI_PASSIVE;
      addrinfo* local = nullptr;
      if (::getaddrinfo(bind_address.c_str(), "0", &local_hints, &local) != 0 || !local) {
        ::close(fd);
        last_error = "bind address '" + bind_address + "' is not a numeric address of this family";
        continue;
      }
      const bool local_loopback = isLoopback(local->ai_addr);
      const int bound = ::bind(fd, local->ai_addr, local->ai_addrlen);
      const int bind_errno = errno;
      ::freeaddrinfo(local);
      if (bound != 0) {
        ::close(fd);
        last_error = "cannot bind to '" + bind_address + "': " + std::strerror(bind_errno);
        continue;
      }
      if (local_loopback && !isLoopback(candidate->ai_addr)) {
        ::close(fd);
        ::freeaddrinfo(found);
        throw std::invalid_argument("UDP notification socket bound to " + bind_address +
                                    " (loopback) cannot reach '" + host +
                                    "': bind it to this station's address on the GIS's network");
      }
    }
    socket_ = fd;
    std::memcpy(&address_, candidate->ai_addr, candidate->ai_addrlen);
    address_length_ = candidate->ai_addrlen;
    char numeric[NI_MAXHOST] = "?";
    ::getnameinfo(candidate->ai_addr, candidate->ai_addrlen, numeric, sizeof(numeric), nullptr, 0, NI_NUMERICHOST);
    destination_ = host + ":" + std::to_string(port) + " (" + numeric + ")";
    break;
  }
  ::freeaddrinfo(found);
  if (socket_ < 0) {
    throw std::runtime_error("cannot open a UDP socket towards '" + host + "' port " + std::to_string(port) + ": " +
                             last_error);
  }
}

TileNotifier::~TileNotifier() {
  if (socket_ >= 0) ::close(socket_);
}

bool TileNotifier::send(const WrittenTile& tile, std::string* error) {
  const std::string json = tileToJson(tile);
  if (json.size() > kMaxTileDatagramBytes) {
    if (error) {
      *error = "tile notification of " + std::to_string(json.size()) + " bytes exceeds the " +
               std::to_string(kMaxTileDatagramBytes) + "-byte datagram limit (shorten the metadata's extra items)";
    }
    return false;
  }
  // sendto() rather than connect() + send(): an ICMP "port unreachable" of a GIS not listening yet must not make
  // the next tile's send fail.
  ssize_t sent = -1;
  do {
    sent = ::sendto(socket_, json.data(), json.size(), MSG_DONTWAIT | MSG_NOSIGNAL,
                    reinterpret_cast<const sockaddr*>(&address_), address_length_);
  } while (sent < 0 && errno == EINTR);
  if (sent < 0) {
    if (error) {
      const bool would_block = errno == EAGAIN || errno == EWOULDBLOCK;
      *error = "cannot send the tile notification to " + destination_ + ": " + std::strerror(errno) +
               (would_block ? " (send buffer full)" : "");
    }
    return false;
  }
  if (static_cast<size_t>(sent) != json.size()) {
    if (error) *error = "tile notification to " + destination_ + " truncated";
    return false;
  }
  if (error) error->clear();
  return true;
}

}  // namespace tiles
}  // namespace exocet_mosaic
