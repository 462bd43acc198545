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

#include "exocet_common/atomic_file.h"
#include "exocet_mosaic/ros/dive_bag_writer.h"
#include "exocet_mosaic/ros/dive_topics.h"
#include "exocet_mosaic/sim/dive_description.h"
#include "exocet_mosaic/sim/geo_reference.h"
#include "exocet_mosaic/sim/image_seabed.h"
#include "exocet_common/command_line.h"

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

std::string csvNumber(double v, int precision) {
  std::ostringstream ss;
  ss << std::fixed << std::setprecision(precision) << v;
  return ss.str();
}

int run(const std::string& config_path, const std::string& output, const std::vector<std::string>& overrides,
        bool print_config, bool quiet) {
  const DiveDescription dive =
      config_path.empty() ? parseDiveDescription("", overrides, ".") : loadDiveDescription(config_path, overrides);
  if (print_config) {
    std::cout << toYaml(dive);
    return 0;
  }
  if (output.empty()) throw std::invalid_argument("--output FILE.bag is required");
  if (output.size() < 5 || output.substr(output.size() - 4) != ".bag")
    throw std::invalid_argument("--output '" + output + "' must end in .bag");
  const std::string base = output.substr(0, output.size() - 4);
  const std::string writable = exocet_common::checkWritableDestination(output);
  if (!writable.empty()) throw std::runtime_error(writable);

  Seabed seabed = makeSeabed(dive.seabed, dive.synthesis.seed);
  DiveSynthesizer synth(dive.synthesis, seabed.texture.get(), seabed.relief.get());
  const DiveSynthesisConfig& cfg = dive.synthesis;
  if (const auto* picture = dynamic_cast<const ImageSeabed*>(seabed.texture.get())) {
    // A picture ends somewhere: refuse a dive that would film past its edge rather than render filler.
    for (double t = 0.0; t <= synth.duration_s() + 1e-9; t += 0.5) {
      if (!picture->covers(synth.footprintOnReferencePlane(t)))
        throw std::invalid_argument("the camera leaves the seabed image '" + dive.seabed.image +
                                    "' at t = " + std::to_string(t) +
                                    " s: enlarge seabed.image_pixel_size_m, move "
                                    "seabed.image_center_x_m/_y_m or shorten the trajectory");
    }
  }

  DiveBagWriter::Options options;
  options.image_storage = parseImageStorage(dive.image_storage);
  options.jpeg_quality = dive.jpeg_quality;
  options.compress_chunks = dive.compress_chunks;
  DiveBagWriter writer(output, options);
  writer.writeDatum(cfg.geo, cfg.start_time_unix_s);
  StaticTransform camera{frames::kBaseLink, frames::kCameraOptical, cfg.rig.baseFromCamera()};
  StaticTransform altimeter{frames::kBaseLink, frames::kAltimeter, Eigen::Isometry3d::Identity()};
  altimeter.parent_from_child.linear() = Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitY()).toRotationMatrix();
  StaticTransform usbl{frames::kBaseLink, frames::kUsbl, Eigen::Isometry3d::Identity()};
  writer.writeStaticTransforms({camera, altimeter, usbl}, cfg.start_time_unix_s);

  std::ostringstream truth_csv;
  truth_csv << "frame,stamp_s,dropped,easting_m,northing_m,up_m,roll_deg,pitch_deg,yaw_deg,cam_easting_m,"
               "cam_northing_m,cam_up_m,cam_qx,cam_qy,cam_qz,cam_qw,camera_altitude_m,gsd_m,latitude_deg,"
               "longitude_deg,depth_m\n";
  const auto start = std::chrono::steady_clock::now();
  int last_percent = -1;
  DiveSink sink;
  sink.navigation.imu = [&](const ImuRecord& r) { writer.writeImu(r); };
  sink.navigation.dvl = [&](const DvlRecord& r) { writer.writeDvl(r); };
  sink.navigation.dead_reckoning = [&](const PoseRecord& r) { writer.writeNavOdometry(r); };
  sink.navigation.depth = [&](const DepthRecord& r) { writer.writeDepth(r); };
  sink.navigation.altitude = [&](const AltitudeRecord& r) { writer.writeAltitude(r); };
  sink.navigation.usbl = [&](const FixRecord& r) { writer.writeUsbl(r); };
  sink.ground_truth = [&](const PoseRecord& r) { writer.writeGroundTruth(r); };
  sink.frame = [&](const FrameTruth& f) {
    if (!f.dropped) writer.writeCameraFrame(f.frame, cfg.rig.camera);
    writer.writeGroundTruthCamera(f.frame.stamp_s, f.world_from_camera, f.camera_altitude_m);
    const VehicleState& v = f.vehicle;
    const Eigen::Vector3d base = synth.toWorld(v.position_m);
    const Eigen::Vector3d cam = f.world_from_camera.translation();
    const Eigen::Quaterniond q(f.world_from_camera.rotation());
    truth_csv << f.frame.index << ',' << csvNumber(f.frame.stamp_s, 6) << ',' << (f.dropped ? 1 : 0) << ','
              << csvNumber(base.x(), 4) << ',' << csvNumber(base.y(), 4) << ',' << csvNumber(base.z(), 4) << ','
              << csvNumber(v.roll_rad * 180 / M_PI, 5) << ',' << csvNumber(v.pitch_rad * 180 / M_PI, 5) << ','
              << csvNumber(v.yaw_rad * 180 / M_PI, 5) << ',' << csvNumber(cam.x(), 4) << ',' << csvNumber(cam.y(), 4)
              << ',' << csvNumber(cam.z(), 4) << ',' << csvNumber(q.x(), 9) << ',' << csvNumber(q.y(), 9) << ','
              << csvNumber(q.z(), 9) << ',' << csvNumber(q.w(), 9) << ',' << csvNumber(f.camera_altitude_m, 5) << ','
              << csvNumber(f.ground_sample_distance_m, 7) << ',' << csvNumber(f.latlon_deg.x(), 9) << ','
              << csvNumber(f.latlon_deg.y(), 9) << ',' << csvNumber(-base.z(), 4) << '\n';
  };
  sink.progress = [&](int done, int total) {
    if (g_interrupted) throw Interrupted();
    const int percent = 100 * done / total;
    if (!quiet && (percent / 10 != last_percent / 10 || done == total)) {
      last_percent = percent;
      const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      std::cerr << "dive_synth: " << done << "/" << total << " frames (" << percent << "%), " << std::setprecision(3)
                << done / std::max(s, 1e-9) << " frames/s\n";
    }
  };
  synth.run(sink);

  std::ostringstream marks_csv;
  marks_csv << "id,x_m,y_m,easting_m,northing_m,up_m,latitude_deg,longitude_deg,size_m\n";
  for (const Landmark& m : synth.renderer().landmarks()) {
    const Eigen::Vector3d w = synth.toWorld(Eigen::Vector3d(m.x_m, m.y_m, seabed.relief->heightAt_m(m.x_m, m.y_m)));
    const Eigen::Vector2d ll = gridToLatLon(cfg.geo, w.x(), w.y());
    marks_csv << m.id << ',' << csvNumber(m.x_m, 4) << ',' << csvNumber(m.y_m, 4) << ',' << csvNumber(w.x(), 4) << ','
              << csvNumber(w.y(), 4) << ',' << csvNumber(w.z(), 4) << ',' << csvNumber(ll.x(), 9) << ','
              << csvNumber(ll.y(), 9) << ',' << csvNumber(m.size_m, 3) << '\n';
  }
  exocet_common::writeFileAtomically(base + ".ground_truth.csv", truth_csv.str());
  exocet_common::writeFileAtomically(base + ".landmarks.csv", marks_csv.str());
  exocet_common::writeFileAtomically(
      base + ".config.yaml", "# Written by dive_synth: the complete description of " + output +
                                 "\n# Reproduce with: dive_synth --config THIS_FILE --output OUT.bag\n" + toYaml(dive));
  writer.commit();
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::cout << "dive_synth: wrote " << output << " (" << synth.frameCount() << " frames, " << std::setprecision(4)
            << synth.duration_s() << " s of dive, " << writer.messageCount() << " messages, EPSG:" << cfg.geo.epsg
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
  shortcut("--preset", "pal|hd", key("camera.preset"), "720x576 or 1920x1080 camera");
  shortcut("--trajectory", "KIND", key("trajectory.kind"), "lawnmower | out_and_back | waypoints");
  shortcut(
      "--waypoints", "FILE.csv",
      [](const std::string& v) {
        return std::vector<std::string>{"trajectory.kind=waypoints", "trajectory.waypoints_csv=" + v};
      },
      "waypoints (header x_m,y_m[,altitude_m][,speed_mps]); implies --trajectory waypoints");
  flag("--relief", {"seabed.relief=true"}, "seabed with relief (rocks, mounds, slopes) instead of a plane");
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
  shortcut("--threads", "N", key("threads"), "rendering threads (the output does not depend on it)");
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
