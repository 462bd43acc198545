/**
 * @file site_assets.h
 * @brief The web map's page (index.html, web_map.js, geo.js, web_map.css: built into the library from
 * src/exocet_web/site/) and Leaflet (copied from Debian's libjs-leaflet), written into a site folder so that it is
 * self-contained: nothing is loaded from outside, the folder can be copied elsewhere, served by any web server or
 * opened from disk. No ROS in it.
 */
#pragma once

#include <map>
#include <string>

namespace exocet_web {
namespace site {

/// The page's files by name ("index.html", "web_map.js", "geo.js", "web_map.css").
const std::map<std::string, std::string>& pageAssets();

/// Debian's libjs-leaflet.
constexpr const char* kDefaultLeafletDir = "/usr/share/javascript/leaflet";

/**
 * @brief Writes the page's files into `site_dir` and copies Leaflet (leaflet.js, leaflet.css, images/) from
 * `leaflet_dir` into `site_dir`/leaflet/ (copies, not links: the site must not point outside itself). Files are
 * replaced atomically.
 * @return "" on success, otherwise what failed (a missing Leaflet names the Debian package)
 */
std::string writeSiteAssets(const std::string& site_dir, const std::string& leaflet_dir = kDefaultLeafletDir);

}  // namespace site
}  // namespace exocet_web
