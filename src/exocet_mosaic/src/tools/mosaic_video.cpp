// mosaic_video: geo-referenced GeoTIFF mosaic tiles from a seabed video in one command, the live chain
// (registration, fusion, composition, tiles) run in one process as fast as the CPU allows.
//   rosrun exocet_mosaic mosaic_video dive.mp4 --altitude 2.0 --output out/dive [--camera K.yaml]
//       [--origin-lat 43.07 --origin-lon 5.88 --heading 75] [--nav nav.csv] [--hfov DEG]
// Exit status: 0 done, 1 I/O failure or no tile made, 2 bad input (one line naming it), 130 interrupted.
#include <unistd.h>

#include <atomic>
#include <csignal>
#include <iostream>
#include <limits>

#include "exocet_common/command_line.h"
#include "exocet_mosaic/video/video_run.h"

namespace {

std::atomic<bool> g_stop{false};

void onSignal(int) {
  g_stop = true;  // the run stops reading, writes the open mosaic as a tile and the summary
}

}  // namespace

int main(int argc, char** argv) {
  using namespace exocet_mosaic::video;
  VideoRunOptions o;
  double origin_lat = 0, origin_lon = 0, heading = 0, start_time = 0, fps = 0;
  CLI::App app(
      "mosaic_video: geo-referenced GeoTIFF mosaic tiles from a downward seabed video: registration, fusion,\n"
      "composition and tiles of the live chain in one process, as fast as the CPU allows. Writes in --output the\n"
      "tiles (tile_NNNN.tif, .tfw), overview.png, track.csv, camera.yaml and summary.json.",
      "mosaic_video");
  app.add_option("VIDEO", o.video_path, "the video file (any format OpenCV's FFmpeg reads: mp4, avi, mkv...)")
      ->required();
  app.add_option("--altitude", o.altitude_m, "camera height above the seabed (m), in [0.1, 100]")
      ->type_name("M")
      ->required();
  app.add_option("--output", o.output_dir, "output folder: new, or empty (see --overwrite)")->type_name("DIR")->required();
  app.add_option("--camera", o.camera_path,
                 "intrinsics YAML (camera_calibration_parsers, or image_width/image_height/K/D) of the video's\n"
                 "image size; without it the clip self-calibrates, else a pinhole of --hfov")
      ->type_name("K.yaml");
  auto* lat = app.add_option("--origin-lat", origin_lat, "latitude of the first frame's camera (deg WGS 84): UTM tiles")
                  ->type_name("DEG");
  auto* lon = app.add_option("--origin-lon", origin_lon, "longitude of the first frame's camera (deg WGS 84)")
                  ->type_name("DEG");
  auto* hdg = app.add_option("--heading", heading,
                             "vehicle's true heading at the first frame (deg clockwise from north; the image top\n"
                             "points forward); 0 when not given")
                  ->type_name("DEG");
  app.add_option("--nav", o.nav_path,
                 "navigation CSV (dive_import's conventions: time, x/y/z or lat/lon, orientation, depth, altitude),\n"
                 "fused as dead reckoning, attitude and altitude; x, y are offsets from --origin-lat/lon when given")
      ->type_name("CSV");
  auto* start = app.add_option("--start-time", start_time,
                               "time of frame 0 on the navigation's clock (s; default: the first row's time)")
                    ->type_name("S");
  auto* rate = app.add_option("--fps", fps, "frame rate (default: the container's)")->type_name("HZ");
  app.add_option("--hfov", o.hfov_deg,
                 "horizontal field of view (deg, (1, 179)) of the pinhole used when there is no --camera and\n"
                 "self-calibration refuses; 60 deg suits most ROV survey cameras")
      ->type_name("DEG")
      ->capture_default_str();
  app.add_flag("--overwrite", o.overwrite, "replace this tool's files in a non-empty --output folder");
  app.add_flag("--progress", o.progress, "progress bar on stderr (default: only when stderr is a terminal)");
  app.add_option("--max-frames", o.max_frames, "stop after N frames (0: all)")->type_name("N")->capture_default_str();
  app.add_option("--selfcal-frames", o.selfcal_frames, "frames read by the self-calibration, [10, 100000]")
      ->type_name("N")
      ->capture_default_str();
  app.add_option("--registration-preset", o.registration_preset,
                 "config/registration preset name or .yaml path")->type_name("NAME")->capture_default_str();
  app.add_option("--registration-model", o.registration_model,
                 "motion model: homography (as the live chain), similarity, affine, translation")
      ->type_name("MODEL")
      ->check(CLI::IsMember({"homography", "similarity", "affine", "translation"}))
      ->capture_default_str();
  app.add_option("--tiles-preset", o.tiles_preset, "config/tiles preset name or .yaml path")
      ->type_name("NAME")
      ->capture_default_str();
  app.footer("Exit status: 0 done, 1 I/O failure or no tile made, 2 bad input, 130 interrupted (SIGINT/SIGTERM: the\n"
             "open mosaic is written as a last tile and summary.json says reason \"interrupted\").");
  if (const auto exit_status = exocet_common::parseCommandLine(app, argc, argv)) return *exit_status;
  if (lat->count()) o.origin_latitude_deg = origin_lat;
  if (lon->count()) o.origin_longitude_deg = origin_lon;
  if (hdg->count()) o.heading_deg = heading;
  if (start->count()) o.start_time_s = start_time;
  if (rate->count()) o.fps = fps;
  if (!o.progress) o.progress = ::isatty(STDERR_FILENO) != 0;

  struct sigaction action {};
  action.sa_handler = onSignal;
  sigemptyset(&action.sa_mask);
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);
  return runVideoMosaic(o, g_stop, std::cout, std::cerr);
}
