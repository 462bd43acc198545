// adjust_tiles: after the dive, moves the tiles by one similarity each so that overlapping ones agree (the return
// passes with the outbound ones), keeping the network where the navigation put it (tiles/tile_network_adjustment.h).
// The live tiles are kept; the adjusted ones go to another folder.
//   rosrun exocet_mosaic adjust_tiles --tiles DIR --output DIR [--report FILE.json] [--patch-px N]
// Exit status: 0 written, 2 bad input (the message names it), 1 a write failed.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

#include "exocet_mosaic/tiles/tile_json.h"
#include "exocet_mosaic/tiles/tile_network_adjustment.h"

namespace {

namespace et = exocet_mosaic::tiles;

const char kUsage[] =
    "usage: adjust_tiles --tiles DIR --output DIR [--report FILE.json] [--patch-px N] [--patch-sigma-px S]\n"
    "                    [--rotation-scale-sigma R]\n"
    "Registers every pair of overlapping tiles (<prefix>_NNNN.tif in DIR, as the tile writer names them) and moves\n"
    "each by one similarity (shift, rotation, scale) so that they agree, weighed against each tile's navigation\n"
    "1-sigma (EXOCET_POSITION_SIGMA_M). Writes the tiles resampled north-up (same names, GSD, compression and\n"
    "metadata, plus EXOCET_ADJUSTMENT_*; .tfw) into the output folder, which must exist and differ from DIR;\n"
    "nothing is overwritten.\n";

int usage(const std::string& why) {
  std::cerr << "adjust_tiles: " << why << "\n" << kUsage;
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  std::string tiles_dir, output_dir, report;
  et::TileAdjustmentConfig config;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto value = [&]() -> std::string { return i + 1 < argc ? argv[++i] : std::string(); };
    if (arg == "--tiles")
      tiles_dir = value();
    else if (arg == "--output")
      output_dir = value();
    else if (arg == "--report")
      report = value();
    else if (arg == "--patch-px")
      config.patch_px = std::atoi(value().c_str());
    else if (arg == "--patch-sigma-px")
      config.patch_sigma_px = std::atof(value().c_str());
    else if (arg == "--rotation-scale-sigma")
      config.rotation_scale_sigma = std::atof(value().c_str());
    else if (arg == "-h" || arg == "--help") {
      std::cout << kUsage;
      return 0;
    } else
      return usage("unknown argument '" + arg + "'");
  }
  if (tiles_dir.empty() || output_dir.empty()) return usage("--tiles and --output are required");
  const std::string invalid = config.validate();
  if (!invalid.empty()) return usage(invalid);

  std::string list_error;
  const std::vector<std::string> paths = et::listTiles(tiles_dir, &list_error);
  if (!list_error.empty()) return usage(list_error);
  if (paths.empty()) return usage("no tile (<prefix>_NNNN.tif) in '" + tiles_dir + "'");

  et::TileAdjustmentResult result = et::measureAndSolve(paths, config);
  if (!result.ok) {
    std::cerr << "adjust_tiles: " << result.error << "\n";
    return 2;
  }
  double worst_before = 0, worst_after = 0;
  for (const auto& p : result.pairs) {
    const double g = result.tiles[p.a].gsd_m;
    worst_before = std::max(worst_before, p.offset_en_m.norm() / g);
    worst_after = std::max(worst_after, p.residual_en_m.norm() / g);
  }
  std::printf("adjust_tiles: %zu tiles, %zu overlapping pairs measured; largest pair offset %.2f px before, %.2f px "
              "after\n",
              result.tiles.size(), result.pairs.size(), worst_before, worst_after);
  for (const auto& t : result.tiles)
    std::printf("  %s: moved %+.4f m E, %+.4f m N, rotated %+.2f mrad, scaled %+.2f permille (navigation 1-sigma "
                "%.3f m)\n",
                std::filesystem::path(t.path).filename().c_str(), t.shift_en_m.x(), t.shift_en_m.y(),
                1e3 * t.rotation_rad, 1e3 * t.scale_change, t.position_sigma_m);
  et::writeAdjustedTiles(output_dir, &result);
  if (!report.empty()) {
    std::ofstream out(report);
    out << "{\n  \"tiles\": " << result.tiles.size() << ",\n  \"pairs\": " << result.pairs.size()
        << ",\n  \"pair_offset_max_px\": " << et::jsonNumber(worst_before)
        << ",\n  \"pair_residual_max_px\": " << et::jsonNumber(worst_after) << ",\n  \"shifts_m\": {";
    for (size_t i = 0; i < result.tiles.size(); ++i)
      out << (i ? ", " : "") << "\"" << std::filesystem::path(result.tiles[i].path).filename().string() << "\": ["
          << et::jsonNumber(result.tiles[i].shift_en_m.x()) << ", " << et::jsonNumber(result.tiles[i].shift_en_m.y())
          << "]";
    out << "},\n  \"pair_list\": [";
    for (size_t i = 0; i < result.pairs.size(); ++i) {
      const auto& p = result.pairs[i];
      const double g = result.tiles[p.a].gsd_m;
      out << (i ? ",\n    " : "\n    ") << "{\"a\": \"" << std::filesystem::path(result.tiles[p.a].path).filename().string()
          << "\", \"b\": \"" << std::filesystem::path(result.tiles[p.b].path).filename().string()
          << "\", \"patches\": " << p.patches << ", \"patch_px\": " << p.patch_px
          << ", \"offset_px\": " << et::jsonNumber(p.offset_en_m.norm() / g)
          << ", \"residual_px\": " << et::jsonNumber(p.residual_en_m.norm() / g) << "}";
    }
    out << "]\n}\n";
  }
  if (!result.ok) {
    std::cerr << "adjust_tiles: " << result.error << "\n";
    return 1;
  }
  std::printf("adjust_tiles: wrote %zu tiles to %s\n", result.written.size(), output_dir.c_str());
  return 0;
}
