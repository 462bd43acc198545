#include "exocet_web/server/request_path.h"

#include <limits.h>
#include <stdlib.h>
#include <sys/stat.h>

#include <cerrno>
#include <cstring>
#include <memory>
#include <vector>

namespace exocet_web {
namespace server {

namespace {

int hexValue(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

RequestPath refuse(int status, const std::string& reason) {
  RequestPath p;
  p.status = status;
  p.reason = reason;
  return p;
}

std::string realPath(const std::string& path) {
  std::unique_ptr<char, decltype(&::free)> resolved(::realpath(path.c_str(), nullptr), &::free);
  return resolved ? std::string(resolved.get()) : std::string();
}

}  // namespace

RequestPath parseRequestTarget(const std::string& target) {
  if (target.empty() || target[0] != '/') return refuse(400, "the target does not start with '/'");
  std::string raw = target.substr(0, target.find_first_of("?#"));
  if (raw.size() >= 2 && raw[1] == '/') return refuse(400, "an absolute or network path ('//')");
  // Segments are split on the raw '/' only; each is then decoded, so an encoded '/' never separates.
  std::vector<std::string> segments;
  size_t start = 1;
  while (true) {
    const size_t end = raw.find('/', start);
    const std::string encoded = raw.substr(start, end == std::string::npos ? std::string::npos : end - start);
    const bool last = end == std::string::npos;
    if (encoded.empty()) {
      if (!last) return refuse(400, "an empty path segment ('//')");
      segments.push_back("");  // trailing '/': the folder's index
      break;
    }
    std::string decoded;
    for (size_t i = 0; i < encoded.size(); ++i) {
      char c = encoded[i];
      if (c == '%') {
        if (i + 2 >= encoded.size()) return refuse(400, "a truncated percent escape");
        const int hi = hexValue(encoded[i + 1]), lo = hexValue(encoded[i + 2]);
        if (hi < 0 || lo < 0) return refuse(400, "a malformed percent escape");
        c = static_cast<char>(hi * 16 + lo);
        i += 2;
        if (c == '/' || c == '\\' || c == '\0') return refuse(400, "an encoded '/', '\\' or NUL");
      } else if (c == '\\') {
        return refuse(400, "a '\\' in the path");
      }
      if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) return refuse(400, "a control character in the path");
      decoded += c;
    }
    if (decoded == "." || decoded == "..") return refuse(400, "a '.' or '..' segment (path traversal)");
    if (decoded[0] == '.') return refuse(404, "a hidden or temporary file");
    segments.push_back(decoded);
    if (last) break;
    start = end + 1;
  }
  RequestPath p;
  for (size_t i = 0; i < segments.size(); ++i) {
    if (i > 0) p.relative += '/';
    p.relative += segments[i];
  }
  if (segments.back().empty()) p.relative += "index.html";
  return p;
}

ResolvedFile resolveInside(const std::string& root_canonical, const std::string& relative) {
  ResolvedFile f;
  if (root_canonical.empty() || root_canonical[0] != '/' || relative.empty() || relative[0] == '/') {
    f.reason = "no served folder, or an absolute path";
    f.status = 400;
    return f;
  }
  const std::string resolved = realPath(root_canonical + "/" + relative);
  if (resolved.empty()) {
    f.reason = std::string("not found (") + std::strerror(errno) + ")";
    return f;
  }
  const std::string prefix = root_canonical == "/" ? "/" : root_canonical + "/";
  if (resolved.compare(0, prefix.size(), prefix) != 0) {
    f.status = 403;
    f.reason = "leads out of the served folder (to '" + resolved + "')";
    return f;
  }
  struct stat st {};
  if (::stat(resolved.c_str(), &st) != 0 || !S_ISREG(st.st_mode)) {
    f.reason = "not a regular file";
    return f;
  }
  f.status = 200;
  f.path = resolved;
  return f;
}

std::string canonicalFolder(const std::string& path) {
  const std::string resolved = realPath(path);
  struct stat st {};
  if (resolved.empty() || ::stat(resolved.c_str(), &st) != 0 || !S_ISDIR(st.st_mode)) return "";
  return resolved;
}

}  // namespace server
}  // namespace exocet_web
