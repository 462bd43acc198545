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

#include "exocet_common/atomic_file.h"
#include "exocet_mosaic/ros/dive_bag_writer.h"
#include "exocet_mosaic/ros/dive_topics.h"
#include "exocet_mosaic/sim/dive_description.h"
#include "exocet_mosaic/sim/geo_reference.h"
#include "exocet_mosaic/sim/image_seabed.h"

namespace {

using namespace exocet_mosaic;
using namespace exocet_mosaic::sim;

std::atomic<bool> g_interrupted{false};
void onSignal(int) { g_interrupted = true; }

struct Interrupted {};

const char* kUsage =
    R"(dive_synth: synthesize a dive (downward camera over a seabed, navigation sensors, ground truth) into a bag.

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
  --threads N              rendering threads (the output does not depend on it)
  --set KEY=VALUE          set any key of the description, e.g. --set trajectory.altitude_m=3.5
  --print-config           print the complete description and exit
  --quiet                  no progress lines
  --help                   this text

Exit status: 0 done, 2 bad arguments or description (the message names the key and its allowed range),
1 I/O failure, 130 interrupted (nothing is left under the output names).
)";

std::string csvNumber(double v, int precision) {
  std::ostringstream ss;
  ss << std::fixed << std::setprecision(precision) << v;
  return ss.str();
}

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
      for (const char* o :
           {"imaging.light_cone_strength=0", "imaging.vignetting=0", "imaging.attenuation_per_m=[0,0,0]",
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
