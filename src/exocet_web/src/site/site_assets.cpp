#include "exocet_web/site/site_assets.h"

#include <filesystem>
#include <fstream>
#include <iterator>

#include "exocet_common/atomic_file.h"

namespace exocet_web {
namespace site {

// Generated at build time from src/exocet_web/site/ (cmake/embed_site.cmake).
const std::map<std::string, std::string>& embeddedSiteFiles();

const std::map<std::string, std::string>& pageAssets() { return embeddedSiteFiles(); }

namespace {

namespace fs = std::filesystem;

std::string copyFile(const fs::path& from, const fs::path& to) {
  std::ifstream in(from, std::ios::binary);
  if (!in) return "cannot read '" + from.string() + "'";
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  try {
    exocet_common::writeFileAtomically(to.string(), bytes);
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

}  // namespace

std::string writeSiteAssets(const std::string& site_dir, const std::string& leaflet_dir) {
  std::error_code ec;
  fs::create_directories(fs::path(site_dir) / "leaflet" / "images", ec);
  if (ec) return "cannot create '" + site_dir + "/leaflet/images': " + ec.message();
  for (const auto& [name, text] : pageAssets()) {
    try {
      exocet_common::writeFileAtomically((fs::path(site_dir) / name).string(), text);
    } catch (const std::exception& e) {
      return e.what();
    }
  }
  const fs::path leaflet(leaflet_dir);
  if (!fs::exists(leaflet / "leaflet.js")) return "no Leaflet in '" + leaflet_dir + "' (Debian package libjs-leaflet)";
  for (const char* name : {"leaflet.js", "leaflet.css"}) {
    const std::string error = copyFile(leaflet / name, fs::path(site_dir) / "leaflet" / name);
    if (!error.empty()) return error;
  }
  for (const auto& entry : fs::directory_iterator(leaflet / "images", ec)) {
    if (!entry.is_regular_file()) continue;
    const std::string error =
        copyFile(entry.path(), fs::path(site_dir) / "leaflet" / "images" / entry.path().filename());
    if (!error.empty()) return error;
  }
  return "";
}

}  // namespace site
}  // namespace exocet_web
