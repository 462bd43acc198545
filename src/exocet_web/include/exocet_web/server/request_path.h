/**
 * @file request_path.h
 * @brief Maps an HTTP request target to a file of the served folder and nothing else: the sanitiser of the web
 * map's server. No ROS in it.
 *
 * Two steps. parseRequestTarget() works on the raw target as received (before any decoding, so that an encoded
 * "%2e%2e" or "%2f" cannot slip past a check made on decoded text): it refuses what no page of the site asks for.
 * resolveInside() then canonicalises the path on disk (realpath: symbolic links followed) and refuses any result
 * outside the folder's own canonical path, so a symbolic link inside the folder may point within it but not out.
 */
#pragma once

#include <string>

namespace exocet_web {
namespace server {

/// The verdict on a request target.
struct RequestPath {
  int status = 200;      ///< 200 usable; 400 malformed or a traversal attempt; 404 a name never served
  std::string relative;  ///< the decoded path below the served folder ("index.html" for "/"), when usable
  std::string reason;    ///< why not, for the log
};

/**
 * @brief Decodes and checks a request target ("/tiles/21/3/4.png?r=7").
 *
 * 400 for: a target not starting with '/', a target starting with "//" (an absolute or network path), a malformed
 * percent escape, an encoded '/', '\\' or NUL (%2f, %5c, %00), a raw '\\', a control character, an empty segment
 * ("a//b"), a "." or ".." segment, encoded or not. 404 for a segment starting with '.' (hidden and temporary files).
 * The query ("?...") and fragment are ignored; a trailing '/' names the folder's index.html.
 */
RequestPath parseRequestTarget(const std::string& target);

/// A file found inside the served folder.
struct ResolvedFile {
  int status = 404;  ///< 200 found; 404 no such regular file; 403 a link or path leading out of the folder
  std::string path;  ///< canonical absolute path, when found
  std::string reason;
};

/**
 * @brief The regular file `relative` (from parseRequestTarget) names under `root_canonical` (a canonical absolute
 * folder path, realpath'ed by the caller once), with every symbolic link resolved: refused (403) when it lands
 * outside the folder, 404 when missing or not a regular file.
 */
ResolvedFile resolveInside(const std::string& root_canonical, const std::string& relative);

/// realpath() of an existing folder; "" if it does not exist.
std::string canonicalFolder(const std::string& path);

}  // namespace server
}  // namespace exocet_web
