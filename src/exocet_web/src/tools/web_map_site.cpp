// web_map_site: builds (or brings up to date) the web map site of a dive's GeoTIFF tiles without ROS: the page, the
// web tiles, the state files with the track of fused_track.csv, and the GeoPackage export, as web_map_node leaves them.
//   rosrun exocet_web web_map_site --tiles DIR [--site DIR] [--gpkg FILE|""] [--mbtiles FILE] [--dive-name NAME]
// Exit status: 0 written, 2 bad input (the message names it), 1 a GeoTIFF or a file could not be written.
#include <chrono>
#include <iostream>
#include <string>

#include "exocet_common/command_line.h"
#include "exocet_web/site/web_map.h"

int main(int argc, char** argv) {
  exocet_web::site::WebMapConfig config;
  std::string gpkg = "default";
  CLI::App app(
      "Builds the web map site of a finished dive (what web_map_node writes live): the page and Leaflet, the web\n"
      "tiles cut from every GeoTIFF tile of --tiles (only the new or changed ones when the site exists), state.json,\n"
      "state.js, tiles.json, track.json (from fused_track.csv) and a GeoPackage for QGIS. Open <site>/index.html in a\n"
      "browser, or serve the folder with any web server.",
      "web_map_site");
  app.add_option("--tiles", config.tiles_dir, "folder of the GeoTIFF tiles (<prefix>_NNNN.tif)")
      ->required()
      ->check(CLI::ExistingDirectory);
  app.add_option("--site", config.site_dir, "site folder (default <tiles>/web)");
  app.add_option("--gpkg", gpkg, "GeoPackage written, for QGIS (default <site>/mosaic.gpkg; \"\" for none)");
  app.add_option("--mbtiles", config.mbtiles_path, "MBTiles file written too (default none)");
  app.add_option("--dive-name", config.dive_name, "name in the page's title and the MBTiles metadata");
  app.add_option("--max-zoom", config.cutter.max_zoom, "finest level, -1: the first tile's native level")
      ->check(CLI::Range(-1, 30));
  app.add_option("--min-zoom", config.cutter.min_zoom, "coarsest level, -1: the survey in one tile")
      ->check(CLI::Range(-1, 30));
  app.add_option("--png-compression", config.cutter.png_compression, "zlib level of the web tiles")
      ->check(CLI::Range(0, 9));
  app.add_option("--block-tiles", config.cutter.block_tiles, "web tiles per side warped at once")
      ->check(CLI::Range(1, 64));
  app.add_option("--leaflet", config.leaflet_dir, "Leaflet's folder (Debian's libjs-leaflet)");
  app.add_option("--track", config.track_csv, "the fusion's track (fused_track.csv; default <tiles>/fused_track.csv)")
      ->check(CLI::ExistingFile);
  if (const auto status = exocet_common::parseCommandLine(app, argc, argv)) return *status;
  if (config.site_dir.empty()) config.site_dir = config.tiles_dir + "/web";
  config.gpkg_path = gpkg == "default" ? config.site_dir + "/mosaic.gpkg" : gpkg;
  config.worker_nice = 0;
  try {
    exocet_web::site::WebMap map(config, [](auto, const std::string&, const std::string& message) {
      std::cerr << "web_map_site: " << message << "\n";
    });
    map.start();
    map.waitIdle(std::chrono::hours(24));
    const std::string errors = map.shutdown();
    const auto stats = map.stats();
    std::cout << "web_map_site: " << stats.sources << " GeoTIFF tiles, " << stats.web_tiles << " web tiles (levels "
              << stats.min_zoom << " to " << stats.max_zoom << "), track of " << stats.track_points << " points in "
              << config.site_dir << "/index.html" << (config.gpkg_path.empty() ? "" : ", " + config.gpkg_path)
              << (config.mbtiles_path.empty() ? "" : ", " + config.mbtiles_path) << "\n";
    return errors.empty() && stats.errors == 0 ? 0 : 1;
  } catch (const std::invalid_argument& e) {
    std::cerr << "web_map_site: " << e.what() << "\n";
    return exocet_common::kExitBadInput;
  } catch (const std::exception& e) {
    std::cerr << "web_map_site: " << e.what() << "\n";
    return 1;
  }
}
