// dive_synth: synthesizes a dive of a downward camera over a seabed, with navigation and ground truth, into a bag.
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <functional>
#include <iomanip>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include "exocet_common/command_line.h"
#include "exocet_mosaic/ros/synthetic_dive_bag.h"
#include "exocet_mosaic/sim/dive_description.h"

namespace {

using namespace exocet_mosaic;
using namespace exocet_mosaic::sim;

std::atomic<bool> g_interrupted{false};
void onSignal(int) { g_interrupted = true; }

struct Interrupted {};

const char kDescription[] =
    "dive_synth: synthesize a dive (downward camera over a seabed, navigation sensors, ground truth) into a bag.\n"
    "\n"
    "Outputs (each written under a temporary name and renamed when complete):\n"
    "  OUT.bag                  camera images + camera_info, /nav/* sensors, /nav/datum, /tf_static, /ground_truth/*\n"
    "  OUT.ground_truth.csv     one row per camera frame: vehicle and camera pose (UTM), altitude, GSD, lat/lon\n"
    "  OUT.landmarks.csv        surveyed seabed targets (checker squares) with their UTM and WGS 84 positions\n"
    "  OUT.config.yaml          the complete description used (every key), to reproduce or edit the dive\n"
    "\n"
    "Each option below but --config, --output, --print-config and --quiet is a shortcut for --set, applied in the\n"
    "order given; the YAML keys, their units and ranges are in config/dives/README.md.";

const char kFooter[] =
    "Exit status: 0 done, 2 bad arguments or description (the message names the key and its allowed range),\n"
    "1 I/O failure, 130 interrupted (nothing is left under the output names).";

int run(const std::string& config_path, const std::string& output, const std::vector<std::string>& overrides,
        bool print_config, bool quiet) {
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
  std::string config_path, output;
  std::vector<std::string> overrides;  // in command-line order: a later setting of a key wins
  bool print_config = false, quiet = false;
  CLI::App app(kDescription, "dive_synth");
  app.add_option("--config", config_path, "dive description (YAML); without it, the defaults (a PAL lawnmower survey)")
      ->check(CLI::ExistingFile);
  app.add_option("--output", output, "the bag to write (required unless --print-config)")->type_name("FILE.bag");
  // A shortcut appends its settings as it is parsed (trigger_on_parse), so that they keep their place among --set's.
  using Settings = std::function<std::vector<std::string>(const std::string&)>;
  const auto shortcut = [&](const std::string& name, const std::string& value_name, const Settings& settings,
                            const std::string& what) {
    app.add_option_function<std::string>(
           name,
           [&overrides, settings](const std::string& value) {
             for (const std::string& setting : settings(value)) overrides.push_back(setting);
           },
           what)
        ->type_name(value_name)
        ->trigger_on_parse()
        ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
  };
  const auto key = [](const std::string& name) -> Settings {
    return [name](const std::string& value) { return std::vector<std::string>{name + "=" + value}; };
  };
  const auto flag = [&](const std::string& name, const std::vector<std::string>& settings, const std::string& what) {
    app.add_flag_callback(
           name, [&overrides, settings] { overrides.insert(overrides.end(), settings.begin(), settings.end()); }, what)
        ->trigger_on_parse();
  };
  shortcut("--seed", "N", key("seed"), "seed of every random draw: same arguments and seed give a byte-identical bag");
  shortcut("--duration", "S", key("duration_s"), "stop after S seconds (0: the whole trajectory)");
  shortcut("--preset", "pal|hd|uhd", key("camera.preset"), "720x576, 1920x1080 or 3840x2160 camera");
  shortcut("--trajectory", "KIND", key("trajectory.kind"), "lawnmower | out_and_back | waypoints");
  shortcut(
      "--waypoints", "FILE.csv",
      [](const std::string& v) {
        return std::vector<std::string>{"trajectory.kind=waypoints", "trajectory.waypoints_csv=" + v};
      },
      "waypoints (header x_m,y_m[,altitude_m][,speed_mps]); implies --trajectory waypoints");
  flag("--relief", {"seabed.relief=true"}, "seabed with relief (rocks, mounds, slopes) instead of a plane");
  shortcut("--objects", "wreck|boulders", key("seabed.objects"),
           "objects 0.2-0.6 m tall with steep sides on the seabed: piled amphorae and blocks, or boulders");
  shortcut(
      "--seabed-image", "FILE",
      [](const std::string& v) {
        return std::vector<std::string>{"seabed.kind=image", "seabed.image=" + v};
      },
      "render a georeferenced picture of the seabed (top row = north)...");
  shortcut("--seabed-pixel-size", "M", key("seabed.image_pixel_size_m"),
           "...whose pixels measure M metres on the ground");
  flag("--ideal",
       {"imaging.light_cone_strength=0", "imaging.vignetting=0", "imaging.attenuation_per_m=[0,0,0]",
        "imaging.backscatter=0", "imaging.noise_sigma_dn=0", "imaging.shot_noise_dn=0", "imaging.marine_snow_per_m3=0",
        "imaging.motion_blur_exposure_s=0", "imaging.segments=[]"},
       "no light cone, vignetting, attenuation, backscatter, noise, snow or blur");
  shortcut("--encoding", "ENC", key("camera.encoding"), "bgr8 | rgb8 | mono8 | mono16 | bayer_rggb8");
  shortcut("--image-storage", "KIND", key("output.image_storage"),
           "raw | jpeg | png (jpeg/png go to /camera/image_raw/compressed)");
  shortcut("--threads", "N", key("threads"), "frames rendered at once, one per thread (the output does not depend on it)");
  shortcut(
      "--set", "KEY=VALUE", [](const std::string& v) { return std::vector<std::string>{v}; },
      "set any key of the description, e.g. --set trajectory.altitude_m=3.5");
  app.add_flag("--print-config", print_config, "print the complete description and exit");
  app.add_flag("--quiet", quiet, "no progress lines");
  app.footer(kFooter);
  if (const auto exit_status = exocet_common::parseCommandLine(app, argc, argv)) return *exit_status;

  std::signal(SIGINT, onSignal);
  std::signal(SIGTERM, onSignal);
  try {
    return run(config_path, output, overrides, print_config, quiet);
  } catch (const Interrupted&) {
    std::cerr << "dive_synth: interrupted; no output was left under the final names\n";
    return 130;
  } catch (const std::invalid_argument& e) {
    std::cerr << "dive_synth: error: " << e.what() << "\n";
    return exocet_common::kExitBadInput;
  } catch (const std::exception& e) {
    std::cerr << "dive_synth: error: " << e.what() << "\n";
    return 1;
  }
}
