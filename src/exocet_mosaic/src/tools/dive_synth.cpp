// dive_synth: synthesizes a dive of a downward camera over a seabed, with navigation and ground truth, into a bag.
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <iomanip>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include "exocet_mosaic/ros/synthetic_dive_bag.h"
#include "exocet_mosaic/sim/dive_description.h"

namespace {

using namespace exocet_mosaic;
using namespace exocet_mosaic::sim;

std::atomic<bool> g_interrupted{false};
void onSignal(int) { g_interrupted = true; }

struct Interrupted {};

const char* kUsage = R"(dive_synth: synthesize a dive (downward camera over a seabed, navigation sensors, ground truth) into a bag.

Usage: dive_synth [--config DIVE.yaml] --output OUT.bag [options]

Outputs (each written under a temporary name and renamed when complete):
  OUT.bag                  camera images + camera_info, /nav/* sensors, /nav/datum, /tf_static, /ground_truth/*
  OUT.ground_truth.csv     one row per camera frame: vehicle and camera pose (UTM), altitude, GSD, lat/lon
  OUT.landmarks.csv        surveyed seabed targets (checker squares) with their UTM and WGS 84 positions
  OUT.config.yaml          the complete description used (every key), to reproduce or edit the dive

Options (each is a shortcut for --set; the YAML keys and their units are in config/dives/README.md):
  --config FILE            dive description (YAML); without it, the defaults (a PAL lawnmower survey)
  --output FILE.bag        the bag to write (required unless --print-config)
  --seed N                 seed of every random draw: same arguments and seed give a byte-identical bag
  --duration S             stop after S seconds (0: the whole trajectory)
  --preset pal|hd          720x576 or 1920x1080 camera
  --trajectory KIND        lawnmower | out_and_back | waypoints
  --waypoints FILE.csv     waypoints (header x_m,y_m[,altitude_m][,speed_mps]); implies --trajectory waypoints
  --relief                 seabed with relief (rocks, mounds, slopes) instead of a plane
  --seabed-image FILE      render a georeferenced picture of the seabed (top row = north)...
  --seabed-pixel-size M    ...whose pixels measure M metres on the ground
  --ideal                  no light cone, vignetting, attenuation, backscatter, noise, snow or blur
  --encoding ENC           bgr8 | rgb8 | mono8 | mono16 | bayer_rggb8
  --image-storage KIND     raw | jpeg | png (jpeg/png go to /camera/image_raw/compressed)
  --threads N              frames rendered at once, one per thread (the output does not depend on it)
  --set KEY=VALUE          set any key of the description, e.g. --set trajectory.altitude_m=3.5
  --print-config           print the complete description and exit
  --quiet                  no progress lines
  --help                   this text

Exit status: 0 done, 2 bad arguments or description (the message names the key and its allowed range),
1 I/O failure, 130 interrupted (nothing is left under the output names).
)";

int run(int argc, char** argv) {
  std::string config_path, output;
  std::vector<std::string> overrides;
  bool print_config = false, quiet = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&](const char* name) -> std::string {
      if (i + 1 >= argc) throw std::invalid_argument(std::string(name) + " needs a value");
      return argv[++i];
    };
    if (a == "--help" || a == "-h") {
      std::cout << kUsage;
      return 0;
    } else if (a == "--config") {
      config_path = value("--config");
    } else if (a == "--output") {
      output = value("--output");
    } else if (a == "--seed") {
      overrides.push_back("seed=" + value("--seed"));
    } else if (a == "--duration") {
      overrides.push_back("duration_s=" + value("--duration"));
    } else if (a == "--preset") {
      overrides.push_back("camera.preset=" + value("--preset"));
    } else if (a == "--trajectory") {
      overrides.push_back("trajectory.kind=" + value("--trajectory"));
    } else if (a == "--waypoints") {
      overrides.push_back("trajectory.kind=waypoints");
      overrides.push_back("trajectory.waypoints_csv=" + value("--waypoints"));
    } else if (a == "--relief") {
      overrides.push_back("seabed.relief=true");
    } else if (a == "--seabed-image") {
      overrides.push_back("seabed.kind=image");
      overrides.push_back("seabed.image=" + value("--seabed-image"));
    } else if (a == "--seabed-pixel-size") {
      overrides.push_back("seabed.image_pixel_size_m=" + value("--seabed-pixel-size"));
    } else if (a == "--ideal") {
      for (const char* o : {"imaging.light_cone_strength=0", "imaging.vignetting=0", "imaging.attenuation_per_m=[0,0,0]",
                            "imaging.backscatter=0", "imaging.noise_sigma_dn=0", "imaging.shot_noise_dn=0",
                            "imaging.marine_snow_per_m3=0", "imaging.motion_blur_exposure_s=0", "imaging.segments=[]"})
        overrides.push_back(o);
    } else if (a == "--encoding") {
      overrides.push_back("camera.encoding=" + value("--encoding"));
    } else if (a == "--image-storage") {
      overrides.push_back("output.image_storage=" + value("--image-storage"));
    } else if (a == "--threads") {
      overrides.push_back("threads=" + value("--threads"));
    } else if (a == "--set") {
      overrides.push_back(value("--set"));
    } else if (a == "--print-config") {
      print_config = true;
    } else if (a == "--quiet") {
      quiet = true;
    } else {
      throw std::invalid_argument("unknown argument '" + a + "' (see --help)");
    }
  }
  const DiveDescription dive =
      config_path.empty() ? parseDiveDescription("", overrides, ".") : loadDiveDescription(config_path, overrides);
  if (print_config) {
    std::cout << toYaml(dive);
    return 0;
  }
  if (output.empty()) throw std::invalid_argument("--output FILE.bag is required");
  const auto start = std::chrono::steady_clock::now();
  int last_percent = -1;
  const auto progress = [&](int done, int total) {
    if (g_interrupted) throw Interrupted();
    const int percent = 100 * done / total;
    if (!quiet && (percent / 10 != last_percent / 10 || done == total)) {
      last_percent = percent;
      const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      std::cerr << "dive_synth: " << done << "/" << total << " frames (" << percent << "%), " << std::setprecision(3)
                << done / std::max(s, 1e-9) << " frames/s\n";
    }
  };
  const SyntheticDiveSummary written = writeSyntheticDive(dive, output, progress);
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::cout << "dive_synth: wrote " << output << " (" << written.frames << " frames, " << std::setprecision(4)
            << written.duration_s << " s of dive, " << written.messages << " messages, EPSG:" << written.epsg
            << ") in " << std::setprecision(3) << s << " s\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  std::signal(SIGINT, onSignal);
  std::signal(SIGTERM, onSignal);
  try {
    return run(argc, argv);
  } catch (const Interrupted&) {
    std::cerr << "dive_synth: interrupted; no output was left under the final names\n";
    return 130;
  } catch (const std::invalid_argument& e) {
    std::cerr << "dive_synth: error: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "dive_synth: error: " << e.what() << "\n";
    return 1;
  }
}
