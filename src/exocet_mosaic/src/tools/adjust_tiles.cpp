// adjust_tiles: after the dive, moves the tiles by one similarity each so that overlapping ones agree (the return
// passes with the outbound ones), keeping the network where the navigation put it (tiles/tile_network_adjustment.h).
// The live tiles are kept; the adjusted ones go to another folder.
//   rosrun exocet_mosaic adjust_tiles --tiles DIR --output DIR [--report FILE.json] [--patch-px N]
// Exit status: 0 written, 2 bad input (the message names it), 1 a write failed.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "exocet_common/json_file.h"
#include "exocet_mosaic/tiles/tile_network_adjustment.h"
#include "exocet_common/command_line.h"

namespace {

namespace et = exocet_mosaic::tiles;

int badInput(const std::string& why) {
  std::cerr << "adjust_tiles: " << why << "\n";
  return exocet_common::kExitBadInput;
}

std::string fileName(const std::string& path) { return std::filesystem::path(path).filename().string(); }

}  // namespace

int main(int argc, char** argv) {
  std::string tiles_dir, output_dir, report;
  et::TileAdjustmentConfig config;
  CLI::App app(
      "Registers every pair of overlapping tiles (<prefix>_NNNN.tif in DIR, as the tile writer names them) and moves\n"
      "each by one similarity (shift, rotation, scale) so that they agree, weighed against each tile's navigation\n"
      "1-sigma (EXOCET_POSITION_SIGMA_M). Writes the tiles resampled north-up (same names, GSD, compression and\n"
      "metadata, plus EXOCET_ADJUSTMENT_*; .tfw) into the output folder, which must exist and differ from DIR;\n"
      "nothing is overwritten.",
      "adjust_tiles");
  app.add_option("--tiles", tiles_dir, "folder of the live tiles")->required()->check(CLI::ExistingDirectory);
  app.add_option("--output", output_dir, "existing folder for the adjusted tiles, not the tiles' own")
      ->required()
      ->check(CLI::ExistingDirectory);
  app.add_option("--report", report, "also write the pairs measured and the shifts applied as JSON")
      ->type_name("FILE.json");
  app.add_option("--patch-px", config.patch_px, "side of the correlated patches (pixels), a power of two in [32, 1024]")
      ->type_name("N")
      ->capture_default_str();
  app.add_option("--patch-sigma-px", config.patch_sigma_px,
                 "1-sigma of one patch's measured offset (pixels), in (0, 100]")
      ->type_name("S")
      ->capture_default_str();
  app.add_option("--rotation-scale-sigma", config.rotation_scale_sigma,
                 "prior 1-sigma of a tile's rotation (rad) and scale change (fraction), in (0, 1]")
      ->type_name("R")
      ->capture_default_str();
  app.footer("Exit status: 0 written, 2 bad input (the message names it), 1 a write failed.");
  if (const auto exit_status = exocet_common::parseCommandLine(app, argc, argv)) return *exit_status;
  const std::string invalid = config.validate();
  if (!invalid.empty()) return badInput(invalid);

  std::string list_error;
  const std::vector<std::string> paths = et::listTiles(tiles_dir, &list_error);
  if (!list_error.empty()) return badInput(list_error);
  if (paths.empty()) return badInput("no tile (<prefix>_NNNN.tif) in '" + tiles_dir + "'");

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
    nlohmann::ordered_json json;
    json["tiles"] = result.tiles.size();
    json["pairs"] = result.pairs.size();
    json["pair_offset_max_px"] = worst_before;
    json["pair_residual_max_px"] = worst_after;
    json["shifts_m"] = nlohmann::ordered_json::object();
    for (const auto& t : result.tiles) json["shifts_m"][fileName(t.path)] = {t.shift_en_m.x(), t.shift_en_m.y()};
    json["pair_list"] = nlohmann::ordered_json::array();
    for (const auto& p : result.pairs) {
      const double g = result.tiles[p.a].gsd_m;
      json["pair_list"].push_back({{"a", fileName(result.tiles[p.a].path)},
                                   {"b", fileName(result.tiles[p.b].path)},
                                   {"patches", p.patches},
                                   {"patch_px", p.patch_px},
                                   {"offset_px", p.offset_en_m.norm() / g},
                                   {"residual_px", p.residual_en_m.norm() / g}});
    }
    try {
      exocet_common::writeJsonFileAtomically(report, json);
    } catch (const std::exception& e) {
      std::cerr << "adjust_tiles: " << e.what() << "\n";
      return 1;
    }
  }
  if (!result.ok) {
    std::cerr << "adjust_tiles: " << result.error << "\n";
    return 1;
  }
  std::printf("adjust_tiles: wrote %zu tiles to %s\n", result.written.size(), output_dir.c_str());
  return 0;
}
