// export_tile_package: packs a web map's tiles (<site>/tiles/<z>/<x>/<y>.png) into one GeoPackage (QGIS) or MBTiles
// file.
//   rosrun exocet_web export_tile_package --site DIR --output FILE.gpkg|FILE.mbtiles [--name NAME]
// Exit status: 0 written, 2 bad input, 1 the file could not be written.
#include <iostream>
#include <string>

#include "exocet_common/command_line.h"
#include "exocet_web/tiles/tile_packages.h"

int main(int argc, char** argv) {
  std::string site_dir, output;
  exocet_web::tiles::TilePackageInfo info;
  CLI::App app(
      "Packs the web tiles of a web map site (<site>/tiles/<z>/<x>/<y>.png, as web_map_node and web_map_site write\n"
      "them) into one file: a GeoPackage (.gpkg: QGIS opens it as a raster layer, every level) or an MBTiles file\n"
      "(.mbtiles: tile servers, mobile map apps; GDAL and QGIS do not read MBTiles levels beyond 22).",
      "export_tile_package");
  app.add_option("--site", site_dir, "site folder (holding tiles/)")->required()->check(CLI::ExistingDirectory);
  app.add_option("--output", output, "file to write, .gpkg or .mbtiles (replaced when it exists)")->required();
  app.add_option("--name", info.name, "layer name");
  if (const auto status = exocet_common::parseCommandLine(app, argc, argv)) return *status;
  const auto endsWith = [&](const std::string& suffix) {
    return output.size() > suffix.size() && output.compare(output.size() - suffix.size(), suffix.size(), suffix) == 0;
  };
  if (!endsWith(".gpkg") && !endsWith(".mbtiles")) {
    std::cerr << "export_tile_package: --output " << output << ": the name must end in .gpkg or .mbtiles\n";
    return exocet_common::kExitBadInput;
  }
  info.description = "Seabed mosaic (Exocet web map)";
  const auto result = endsWith(".gpkg") ? exocet_web::tiles::exportGeoPackage(site_dir + "/tiles", output, info)
                                        : exocet_web::tiles::exportMbtiles(site_dir + "/tiles", output, info);
  if (!result.ok) {
    std::cerr << "export_tile_package: " << result.error << "\n";
    return 1;
  }
  std::cout << "export_tile_package: " << result.tiles << " web tiles, levels " << result.min_zoom << " to "
            << result.max_zoom << " in " << output << "\n";
  return 0;
}
