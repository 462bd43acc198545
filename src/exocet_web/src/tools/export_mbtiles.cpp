// export_mbtiles: packs a web map's tiles (<site>/tiles/<z>/<x>/<y>.png) into one MBTiles file for QGIS.
//   rosrun exocet_web export_mbtiles --site DIR --output FILE.mbtiles [--name NAME]
// Exit status: 0 written, 2 bad input, 1 the file could not be written.
#include <iostream>
#include <string>

#include "exocet_common/command_line.h"
#include "exocet_web/tiles/mbtiles.h"

int main(int argc, char** argv) {
  std::string site_dir, output;
  exocet_web::tiles::MbtilesInfo info;
  CLI::App app(
      "Packs the web tiles of a web map site (<site>/tiles/<z>/<x>/<y>.png, as web_map_node and web_map_site write\n"
      "them) into one MBTiles file (SQLite), which QGIS opens as a raster layer (drag it in).",
      "export_mbtiles");
  app.add_option("--site", site_dir, "site folder (holding tiles/)")->required()->check(CLI::ExistingDirectory);
  app.add_option("--output", output, "MBTiles file to write (replaced when it exists)")->required();
  app.add_option("--name", info.name, "layer name");
  if (const auto status = exocet_common::parseCommandLine(app, argc, argv)) return *status;
  info.description = "Seabed mosaic (Exocet web map)";
  const auto result = exocet_web::tiles::exportMbtiles(site_dir + "/tiles", output, info);
  if (!result.ok) {
    std::cerr << "export_mbtiles: " << result.error << "\n";
    return 1;
  }
  std::cout << "export_mbtiles: " << result.tiles << " web tiles, levels " << result.min_zoom << " to "
            << result.max_zoom << " in " << output << "\n";
  return 0;
}
