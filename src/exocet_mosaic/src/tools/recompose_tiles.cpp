// recompose_tiles: after the dive, draws every tile again from its images at the pose graph's final corrections
// (tiles/tile_revisions.h: each image placed by its tile's chain, carried onto the graph per image), with the images'
// gains solved jointly over the dive (image_gains.h; --gain-model tile: one gain per tile, joint_tile_gains.h; opencv:
// OpenCV's stitcher's per-image, per-channel compensator, for comparison) and the lighting field of the whole dive.
// With --tile-adjustment the tiles so drawn are first registered with each other and each moved by one similarity
// (tile_network_adjustment.h, what adjust_tiles does); not by default: on the PAL and grid bench dives and the sample
// out-and-back dive the overlapping pairs agree better without it (PAL every pair 0.87-1.14 px against 1.13-1.21).
// Then the images themselves are moved into agreement where they overlap, return passes, turns and crossings
// included: tie points between overlapping images, one small similarity per image (image_network_adjustment.h;
// --no-image-adjustment: the graph's placements as they are).
// Reads the records the tile writer keeps (<tiles>/.exocet_images/) and the last graph corrections it received
// (graph_corrections.csv there, or --corrections). The live tiles are kept.
//   rosrun exocet_mosaic recompose_tiles --tiles DIR --output DIR [--corrections FILE.csv] [--report FILE.json]
// Exit status: 0 written, 2 bad input (the message names it), 1 a write failed.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <memory>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/stitching/detail/exposure_compensate.hpp>

#include "exocet_common/command_line.h"
#include "exocet_common/json_file.h"
#include "exocet_mosaic/compose/image_gains.h"
#include "exocet_mosaic/compose/joint_tile_gains.h"
#include "exocet_mosaic/compose/lighting_corrector.h"
#include "exocet_mosaic/compose/tile_gain_compensator.h"
#include "exocet_mosaic/tiles/geotiff_tile_writer.h"
#include "exocet_mosaic/tiles/image_network_adjustment.h"
#include "exocet_mosaic/tiles/tile_network_adjustment.h"
#include "exocet_mosaic/tiles/tile_revisions.h"
#include "exocet_mosaic/tiles/tile_writer_resume.h"

namespace {

namespace et = exocet_mosaic::tiles;
namespace ec = exocet_mosaic::compose;

int badInput(const std::string& why) {
  std::cerr << "recompose_tiles: " << why << "\n";
  return exocet_common::kExitBadInput;
}

/// stamp_s,east_m,north_m with a header line; throws naming the line.
et::PositionCorrectionTrack readCorrections(const std::string& path) {
  int left_out = 0;
  et::PositionCorrectionTrack track = et::readPositionCorrections(path, &left_out);
  if (left_out > 0)
    std::cerr << "recompose_tiles: " << left_out << " correction(s) not finite or not in time order: left out\n";
  return track;
}

/// Per image file, each channel's gain from OpenCV's stitcher's ChannelsCompensator (Brown & Lowe per channel), fed
/// with the images corrected for the lighting and warped at a coarse ground sample distance onto one UTM grid.
std::map<std::string, std::array<double, 3>> openCvGains(const std::map<std::string, ec::ImagePlacement>& placements,
                                                         const std::string& records_dir,
                                                         const std::function<cv::Mat(const cv::Mat&)>& prepare,
                                                         double gsd_m) {
  std::vector<std::string> files;
  std::vector<cv::Point> corners;
  std::vector<cv::UMat> images;
  std::vector<std::pair<cv::UMat, uchar>> masks;
  for (const auto& [file, placement] : placements) {
    cv::Mat pixels = cv::imread(records_dir + "/" + file, cv::IMREAD_COLOR);
    if (pixels.empty()) continue;
    if (prepare) pixels = prepare(pixels);
    // grid px (x east, y south, origin UTM (0, 0)) <- image px
    const cv::Matx33d grid_from_en(1 / gsd_m, 0, 0, 0, -1 / gsd_m, 0, 0, 0, 1);
    const cv::Matx33d h = grid_from_en * placement.en_from_px;
    std::vector<cv::Point2d> c = {{0, 0}, {double(pixels.cols), 0}, {double(pixels.cols), double(pixels.rows)},
                                  {0, double(pixels.rows)}};
    cv::perspectiveTransform(c, c, h);
    const cv::Rect box = cv::boundingRect(std::vector<cv::Point2f>(c.begin(), c.end()));
    const cv::Matx33d shift(1, 0, -box.x, 0, 1, -box.y, 0, 0, 1);
    cv::Mat warped, mask;
    cv::warpPerspective(pixels, warped, shift * h, box.size(), cv::INTER_AREA);
    cv::warpPerspective(cv::Mat(pixels.size(), CV_8U, cv::Scalar(255)), mask, shift * h, box.size(), cv::INTER_NEAREST);
    files.push_back(file);
    corners.push_back(box.tl());
    images.push_back(warped.getUMat(cv::ACCESS_READ).clone());
    masks.emplace_back(mask.getUMat(cv::ACCESS_READ).clone(), 255);
  }
  cv::detail::ChannelsCompensator compensator;
  compensator.feed(corners, images, masks);
  std::map<std::string, std::array<double, 3>> out;
  const std::vector<cv::Scalar> gains = compensator.gains();
  for (std::size_t i = 0; i < files.size() && i < gains.size(); ++i)
    out[files[i]] = {gains[i][0], gains[i][1], gains[i][2]};
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  std::string tiles_dir, output_dir, corrections_path, report, prefix = "tile", blend = "feather", gain_model = "image";
  et::RevisionConfig revision;
  bool gain_compensation = true, tile_adjustment = false, lighting_correction = true, image_adjustment = true;
  et::ImageAdjustmentConfig image_adjustment_config;
  int adjustment_passes = 1;
  CLI::App app(
      "Draws every tile of a dive again, per image, at the pose graph's final corrections: the records and images the\n"
      "tile writer kept in DIR/.exocet_images/ (~keep_images), the corrections it last received there\n"
      "(graph_corrections.csv) or --corrections. Tiles are written north-up on the same GSD grid, same index, into the\n"
      "output folder (which must exist and differ from DIR), their gains matched over the whole dive in index order;\n"
      "nothing is overwritten.",
      "recompose_tiles");
  app.add_option("--tiles", tiles_dir, "folder of the live tiles")->required()->check(CLI::ExistingDirectory);
  app.add_option("--output", output_dir, "existing folder for the recomposed tiles, not the tiles' own")
      ->required()
      ->check(CLI::ExistingDirectory);
  app.add_option("--corrections", corrections_path,
                 "graph corrections (CSV stamp_s,east_m,north_m); default DIR/.exocet_images/graph_corrections.csv")
      ->type_name("FILE.csv");
  app.add_option("--adjustment-passes", adjustment_passes,
                 "with --tile-adjustment: registrations of the tiles with each other, each on the tiles the previous one "
                 "moved, [1, 10]")
      ->check(CLI::Range(1, 10))
      ->capture_default_str();
  app.add_option("--prefix", prefix, "file prefix of the tiles")->capture_default_str();
  app.add_option("--blend", blend, "feather | multiband | none")->capture_default_str();
  app.add_option("--residual-window", revision.residual_window_images,
                 "images over which each image's residual to the graph is averaged (odd), 0: one similarity per tile")
      ->capture_default_str();
  app.add_flag("!--chain-orientation", revision.content_follows_heading,
               "the images keep the chain's orientation (turned with their tile's similarity) instead of turning to "
               "their poses' headings");
  app.add_flag("!--no-gain-compensation", gain_compensation, "keep the images' levels as drawn");
  ec::ImageGainsConfig image_gain_config;
  app.add_option("--image-gain-min-cells", image_gain_config.min_common_cells,
                 "common ground cells for a pair of images to be compared, [1, 100000]")
      ->capture_default_str();
  app.add_option("--gain-model", gain_model,
                 "image: a gain per image and channel over the dive's overlaps; tile: one per tile and channel; "
                 "opencv: OpenCV's stitcher's per-image, per-channel compensator (for comparison)")
      ->check(CLI::IsMember({"image", "tile", "opencv"}))
      ->capture_default_str();
  app.add_flag("!--no-lighting", lighting_correction,
               "draw the images as kept (the tile writer keeps them before its lighting correction)");
  app.add_flag("--tile-adjustment,!--no-tile-adjustment", tile_adjustment,
               "register the overlapping tiles with each other and move each by one similarity before the last "
               "drawing (default: the images placed by the graph only)");
  app.add_flag("--image-adjustment,!--no-image-adjustment", image_adjustment,
               "move each image by a ground shift that brings it into agreement with the images it overlaps (tie "
               "points; the pose graph's placement as a weak prior) before the gains and the drawing")
      ->capture_default_str();
  app.add_option("--image-ties", image_adjustment_config.tie_method,
                 "with --image-adjustment: patches (phase correlation of the two images drawn on their common ground) "
                 "| sift (SIFT keypoints)")
      ->check(CLI::IsMember({"patches", "sift"}))
      ->capture_default_str();
  app.add_option("--image-min-overlap", image_adjustment_config.min_overlap_fraction,
                 "with --image-adjustment: common ground of two images, over the smaller one, for them to be paired, "
                 "(0, 1]")
      ->capture_default_str();
  app.add_option("--image-pairs-per-pass", image_adjustment_config.max_cross_pairs_per_pass,
                 "with --image-adjustment: pairs of an image with each other pass it overlaps, [0, 50]")
      ->capture_default_str();
  app.add_option("--image-position-sigma-m", image_adjustment_config.prior_sigma_m,
                 "with --image-adjustment: how far an image's centre may move from the graph's placement (1-sigma, m), "
                 "(0, 100]")
      ->capture_default_str();
  app.add_option("--image-scale-sigma", image_adjustment_config.scale_prior_sigma,
                 "with --image-adjustment: how much an image's scale may change (1-sigma), (0, 1]")
      ->capture_default_str();
  app.add_option("--image-patch-px", image_adjustment_config.patch_px,
                 "with --image-ties patches: side of a patch (px), [16, 512]")
      ->capture_default_str();
  app.add_option("--image-min-ties", image_adjustment_config.min_ties,
                 "with --image-adjustment: tie points a pair of images needs, [3, 100000]")
      ->capture_default_str();
  app.add_option("--image-min-response", image_adjustment_config.min_response,
                 "with --image-ties patches: phase correlation peak a patch needs, [0, 1]")
      ->capture_default_str();
  app.add_option("--image-search-radius-px", image_adjustment_config.search_radius_px,
                 "with --image-adjustment: how far (image px) a tie point may be from where the graph's placements "
                 "put it, (0, 200]")
      ->capture_default_str();
  app.add_option("--report", report, "also write what was done as JSON")->type_name("FILE.json");
  app.footer("Exit status: 0 written, 2 bad input (the message names it), 1 a write failed.");
  if (const auto exit_status = exocet_common::parseCommandLine(app, argc, argv)) return *exit_status;
  const std::string invalid = revision.validate();
  if (!invalid.empty()) return badInput(invalid);
  const std::string invalid_adjustment = image_adjustment_config.validate();
  if (!invalid_adjustment.empty()) return badInput(invalid_adjustment);
  if (std::filesystem::equivalent(tiles_dir, output_dir)) return badInput("--output must differ from --tiles");
  const std::string records_dir = tiles_dir + "/.exocet_images";
  if (corrections_path.empty()) corrections_path = records_dir + "/graph_corrections.csv";

  et::PositionCorrectionTrack track;
  try {
    if (std::filesystem::exists(corrections_path))
      track = readCorrections(corrections_path);
    else
      std::cerr << "recompose_tiles: no graph corrections (" << corrections_path
                << "): the tiles are drawn at the fused navigation\n";
  } catch (const std::exception& e) {
    return badInput(e.what());
  }
  std::vector<et::TileRecord> records;
  std::error_code error;
  for (const auto& entry : std::filesystem::directory_iterator(records_dir, error)) {
    const std::string name = entry.path().filename().string();
    if (entry.path().extension() != ".json" || name.rfind(prefix + "_", 0) != 0) continue;
    const auto json = exocet_common::readJsonObjectFile<nlohmann::json>(entry.path().string());
    if (!json) return badInput("'" + entry.path().string() + "' is not a JSON object");
    try {
      records.push_back(et::tileRecordFromJson(*json));
    } catch (const std::exception& e) {
      return badInput("'" + entry.path().string() + "': " + e.what());
    }
  }
  if (error) return badInput("cannot list '" + records_dir + "': " + error.message());
  if (records.empty())
    return badInput("no tile record (" + prefix + "_NNNN.json) in '" + records_dir +
                    "': was the tile writer run with ~keep_images?");
  std::sort(records.begin(), records.end(),
            [](const et::TileRecord& a, const et::TileRecord& b) { return a.index < b.index; });

  ec::PlacedImageRenderConfig render;
  render.blend = blend;
  // The lighting field of the whole dive (the live one was still settling during the first tiles): every kept image
  // observed once, then each corrected with it.
  auto lighting = std::make_shared<ec::LightingCorrector>();
  std::function<cv::Mat(const cv::Mat&)> prepare;
  const std::string bad_gains = image_gain_config.validate();
  if (!bad_gains.empty()) return badInput(bad_gains);
  ec::ImageGains image_gains(image_gain_config);
  const bool per_image_gains = gain_compensation && gain_model == "image";
  const cv::Size gain_grid(image_gains.config().grid_columns, image_gains.config().grid_rows);
  if (lighting_correction || per_image_gains) {
    int observed = 0;
    for (const et::TileRecord& record : records)
      for (const et::RecordedImage& image : record.images) {
        if (image_gains.contains(image.file)) continue;  // consecutive tiles share an image
        const cv::Mat pixels = cv::imread(records_dir + "/" + image.file, cv::IMREAD_UNCHANGED);
        if (pixels.empty()) continue;
        if (lighting_correction && lighting->observe(pixels)) ++observed;
        if (per_image_gains) image_gains.add(image.file, ec::imageLevels(pixels, gain_grid.width, gain_grid.height));
      }
    if (!lighting_correction) {
    } else if (lighting->ready()) {
      prepare = [lighting](const cv::Mat& image) { return lighting->correct(image); };
      std::printf("recompose_tiles: lighting field from %d images\n", observed);
    } else {
      std::cerr << "recompose_tiles: too few images (" << observed << ") for a lighting field: drawn as kept\n";
    }
  }
  if (gain_model != "image")  // the peers' gains replace the images' own, which the live tile writer may have set
    for (et::TileRecord& record : records)
      for (et::RecordedImage& image : record.images) image.gain = {1.0, 1.0, 1.0};
  int adjusted = 0;
  ec::JointTileGains joint;
  // Passes: the tiles drawn at the graph (and their adjustment so far) into a scratch folder, their levels kept for
  // the gains, registered with each other; each pass's moves add up (the registration of tiles already moved
  // measures what is left).
  const int passes = tile_adjustment ? adjustment_passes : (gain_compensation && gain_model == "tile" ? 1 : 0);
  for (int pass = 0; pass < passes; ++pass) {
    const std::string scratch = output_dir + "/.recompose_pass";
    std::filesystem::remove_all(scratch, error);
    std::filesystem::create_directories(scratch, error);
    if (error) return badInput("cannot create '" + scratch + "': " + error.message());
    et::TileWriterConfig scratch_files;
    scratch_files.output_dir = scratch;
    scratch_files.prefix = prefix;
    scratch_files.write_world_file = false;
    et::GeoTiffTileWriter scratch_writer(scratch_files);
    std::map<std::string, std::size_t> record_of_path;
    for (std::size_t k = 0; k < records.size(); ++k) {
      const et::RevisedTile tile = et::renderTileAt(records[k], track, records_dir, render, revision, prepare);
      if (tile.raster.image.empty()) continue;
      if (gain_compensation && gain_model == "tile" && pass + 1 == passes) joint.add(records[k].index, tile.raster);
      if (!tile_adjustment) continue;
      const et::WrittenTile out = scratch_writer.writeAt(tile.raster, tile.record.metadata, records[k].index);
      if (out.ok) record_of_path[out.geotiff_path] = k;
    }
    if (tile_adjustment) {
      std::vector<std::string> paths;
      for (const auto& [path, k] : record_of_path) paths.push_back(path);
      const et::TileAdjustmentResult network = et::measureAndSolve(paths, et::TileAdjustmentConfig());
      if (!network.ok) {
        std::cerr << "recompose_tiles: the tiles could not be registered with each other (" << network.error
                  << "): drawn at the graph only\n";
      } else {
        double worst_px = 0;
        for (const auto& pair : network.pairs)
          worst_px = std::max(worst_px, pair.offset_en_m.norm() / network.tiles[pair.a].gsd_m);
        for (const et::AdjustedTile& t : network.tiles) {
          const auto k = record_of_path.find(t.path);
          if (k == record_of_path.end()) continue;
          et::applyTileAdjustment(&records[k->second], t.centre_en_m, t.shift_en_m, t.rotation_rad, t.scale_change);
          if (pass == 0) ++adjusted;
        }
        std::printf("recompose_tiles: pass %d: %zu overlapping pairs registered, largest offset %.2f px\n", pass + 1,
                    network.pairs.size(), worst_px);
      }
    }
    std::filesystem::remove_all(scratch, error);
  }

  // Where the final drawing puts each image: the graph's placements (and the tiles' adjustment), then each image's
  // shift into agreement with the images it overlaps.
  std::vector<std::vector<cv::Matx33d>> placements;
  for (const et::TileRecord& record : records) placements.push_back(et::placementsAt(record, track, revision));
  nlohmann::ordered_json image_adjustment_json = {{"done", false}};
  if (image_adjustment) {
    // One image per tile it is drawn in: consecutive tiles share an image, each placing it by its own chain, and the
    // shared image's two placements are then tied by its own pixels.
    std::vector<et::AdjustableImage> images;
    std::map<std::string, std::string> file_of;
    std::vector<std::vector<std::size_t>> index_of(records.size());
    for (std::size_t k = 0; k < records.size(); ++k) {
      const cv::Matx33d en_from_ground(1, 0, records[k].ground_origin_en_m.x(), 0, 1,
                                       records[k].ground_origin_en_m.y(), 0, 0, 1);
      for (std::size_t i = 0; i < records[k].images.size(); ++i) {
        const et::RecordedImage& image = records[k].images[i];
        et::AdjustableImage a;
        a.id = image.file + " in tile " + std::to_string(records[k].index);
        a.source = image.file;
        a.stamp_s = image.stamp_s;
        a.en_from_px = en_from_ground * placements[k][i];
        a.size_px = cv::Size(image.width_px, image.height_px);
        a.gsd_m = records[k].gsd_m;
        file_of[a.id] = image.file;
        index_of[k].push_back(images.size());
        images.push_back(a);
      }
    }
    const et::ImageAdjustment solved = et::adjustImages(
        images,
        [&records_dir, &file_of, &prepare](const std::string& id) {
          // As drawn: with the dive's lighting correction, whose field would otherwise pull the correlations.
          cv::Mat pixels = cv::imread(records_dir + "/" + file_of.at(id), cv::IMREAD_UNCHANGED);
          if (pixels.empty()) return pixels;
          if (prepare) pixels = prepare(pixels);
          if (pixels.channels() == 3) cv::cvtColor(pixels, pixels, cv::COLOR_BGR2GRAY);
          return pixels;
        },
        image_adjustment_config);
    if (!solved.problem.empty()) {
      std::cerr << "recompose_tiles: the images were not adjusted (" << solved.problem
                << "): drawn at the graph's placements\n";
    } else {
      for (std::size_t k = 0; k < records.size(); ++k)
        for (std::size_t i = 0; i < records[k].images.size(); ++i)
          placements[k][i] =
              et::movedPlacement(placements[k][i], solved.move_en[index_of[k][i]], records[k].ground_origin_en_m);
      int cross = 0;
      for (const et::ImagePairTies& p : solved.pairs) cross += p.cross_pass ? 1 : 0;
      std::printf("recompose_tiles: images adjusted: %zu images, %zu pairs measured (%d across passes) of %d tried, "
                  "%d left out, %d tie points; across passes the largest RMS disagreement %.2f px before, %.2f px left; images moved "
                  "by up to %.4f m and %.2f mrad\n",
                  images.size(), solved.pairs.size(), cross, solved.pairs_tried, solved.pairs_rejected, solved.ties,
                  solved.cross_before_max_px, solved.cross_after_max_px, solved.shift_max_m,
                  1e3 * solved.rotation_max_rad);
      image_adjustment_json = {{"done", true},
                               {"images", images.size()},
                               {"images_with_features", solved.images_with_features},
                               {"pairs_tried", solved.pairs_tried},
                               {"pairs", solved.pairs.size()},
                               {"pairs_rejected", solved.pairs_rejected},
                               {"cross_pass_pairs", cross},
                               {"tie_points", solved.ties},
                               {"cross_pass_rms_max_px_before", solved.cross_before_max_px},
                               {"cross_pass_rms_max_px_after", solved.cross_after_max_px},
                               {"shift_max_m", solved.shift_max_m},
                               {"rotation_max_rad", solved.rotation_max_rad}};
      nlohmann::ordered_json pairs = nlohmann::ordered_json::array(), shifts = nlohmann::ordered_json::object();
      for (const et::ImagePairTies& p : solved.pairs)
        pairs.push_back({{"a", images[p.a].id},
                         {"b", images[p.b].id},
                         {"cross_pass", p.cross_pass},
                         {"matches", p.matches},
                         {"ties", p.on_a_en_m.size()},
                         {"rms_before_px", p.before_px},
                         {"rms_after_px", p.after_px},
                         {"rejected", p.rejected},
                         {"same_image", p.same_image}});
      for (std::size_t i = 0; i < images.size(); ++i)
        shifts[images[i].id] = {{"shift_en_m", {solved.shift_en_m[i].x(), solved.shift_en_m[i].y()}},
                                {"rotation_rad", solved.rotation_rad[i]},
                                {"scale_change", solved.scale_change[i]},
                                {"file", file_of.at(images[i].id)},
                                {"en_from_px_before", std::vector<double>(images[i].en_from_px.val,
                                                                          images[i].en_from_px.val + 9)}};
      image_adjustment_json["pair_list"] = pairs;
      image_adjustment_json["image_moves"] = shifts;
    }
    if (!solved.problem.empty()) image_adjustment_json["problem"] = solved.problem;
  }

  et::TileWriterConfig files;
  files.output_dir = output_dir;
  files.prefix = prefix;
  et::GeoTiffTileWriter writer(files);
  const std::map<int, std::array<double, 3>> solved_gains = joint.solve();
  if (gain_compensation && gain_model != "tile") {
    // Each image's gain, from where the final drawing puts it.
    std::map<std::string, ec::ImagePlacement> image_placements;
    for (std::size_t k = 0; k < records.size(); ++k)
      et::addImagePlacements(records[k], placements[k], prepare ? lighting.get() : nullptr, gain_grid,
                             &image_placements);
    std::map<std::string, std::array<double, 3>> gain_of_file;
    if (gain_model == "image") {
      const ec::ImageGainSolution solution = image_gains.solve(image_placements);
      if (!solution.problem.empty())
        std::cerr << "recompose_tiles: no image gains (" << solution.problem << "): drawn with gain 1\n";
      else
        std::printf("recompose_tiles: gains of %zu images over %d overlapping pairs (%.2f m cells): largest level step "
                    "%.1f -> %.1f grey\n", solution.gain.size(), solution.pairs, solution.cell_size_m,
                    solution.step_before_grey, solution.step_after_grey);
      gain_of_file = solution.gain;
    } else {
      gain_of_file = openCvGains(image_placements, records_dir, prepare, 4.0 * records.front().gsd_m);
      std::printf("recompose_tiles: OpenCV's compensator: gains of %zu images\n", gain_of_file.size());
    }
    for (et::TileRecord& record : records)
      for (et::RecordedImage& image : record.images) {
        const auto g = gain_of_file.find(image.file);
        if (g != gain_of_file.end()) image.gain = g->second;
      }
  }
  nlohmann::ordered_json json;
  json["tiles"] = nlohmann::ordered_json::array();
  int written = 0, failed = 0;
  for (std::size_t k = 0; k < records.size(); ++k) {
    const et::TileRecord& record = records[k];
    et::RevisedTile tile = et::renderTileWith(record, placements[k], records_dir, render, prepare);
    if (tile.raster.image.empty()) {
      std::cerr << "recompose_tiles: tile " << record.index << " not drawn: " << tile.problem << "\n";
      ++failed;
      continue;
    }
    ec::TileGains g;
    g.channels = tile.raster.image.channels();
    if (gain_compensation && gain_model == "tile") {
      const auto solved = solved_gains.find(record.index);
      if (solved != solved_gains.end()) g.gain = g.far_gain = solved->second;
      tile.raster = ec::TileGainCompensator::apply(tile.raster, g);
    }
    tile.record.metadata.extra["recomposed"] = "final pose graph, per image";
    const et::WrittenTile out = writer.writeAt(tile.raster, tile.record.metadata, record.index);
    if (!out.ok) {
      std::cerr << "recompose_tiles: " << out.error << "\n";
      ++failed;
      continue;
    }
    ++written;
    std::printf("  %s: %zu images, moved by up to %.4f m%s\n", std::filesystem::path(out.geotiff_path).filename().c_str(),
                record.images.size(), tile.moved_max_m,
                tile.images_missing > 0 ? (", " + std::to_string(tile.images_missing) + " images missing").c_str() : "");
    json["tiles"].push_back({{"index", record.index},
                             {"images", record.images.size()},
                             {"images_missing", tile.images_missing},
                             {"moved_max_m", tile.moved_max_m},
                             {"gain", {g.gain[0], g.gain[1], g.gain[2]}}});
  }
  std::printf("recompose_tiles: wrote %d of %zu tiles to %s (%zu graph key frames)\n", written, records.size(),
              output_dir.c_str(), track.size());
  if (!report.empty()) {
    json["written"] = written;
    json["failed"] = failed;
    json["graph_key_frames"] = track.size();
    json["tiles_adjusted"] = adjusted;
    json["image_adjustment"] = image_adjustment_json;
    try {
      exocet_common::writeJsonFileAtomically(report, json);
    } catch (const std::exception& e) {
      std::cerr << "recompose_tiles: " << e.what() << "\n";
      return 1;
    }
  }
  return failed > 0 ? 1 : 0;
}
