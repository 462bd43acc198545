// dive_import: images + navigation CSV (or an altitude) + camera intrinsics -> a dive bag with the simulator's layout,
// and beside it the replay's arguments (OUT.bag.replay.json).
// Usage and conventions: dive_import --help (text in dive/dive_import.cpp), README.md (section "Importing a real dive:
// dive_import").

#include <csignal>
#include <iostream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "exocet_common/json_file.h"
#include "exocet_mosaic/dive/dive_import.h"
#include "exocet_mosaic/ros/dive_bag_writer.h"

namespace {

volatile std::sig_atomic_t g_signal = 0;
void onSignal(int signal) { g_signal = signal; }

struct Interrupted {
  int signal;
};

/// Checks for SIGINT/SIGTERM between records: unwinding then destroys the bag writer, which removes the
/// temporary bag, so that an interrupted import leaves nothing behind.
class InterruptibleBagSink final : public exocet_mosaic::dive::DiveRecordSink {
 public:
  explicit InterruptibleBagSink(exocet_mosaic::DiveBagWriter* writer) : sink_(writer) {}
  void writeDatum(const exocet_common::GeoReference& d, double stamp_s) override {
    check();
    sink_.writeDatum(d, stamp_s);
  }
  void writeStaticTransforms(const std::vector<exocet_mosaic::dive::StaticTransform>& t, double stamp_s) override {
    check();
    sink_.writeStaticTransforms(t, stamp_s);
  }
  void writeCameraFrame(const exocet_mosaic::dive::CameraFrame& f, const exocet_common::CameraModel& c) override {
    check();
    sink_.writeCameraFrame(f, c);
  }
  void writeNavOdometry(const exocet_mosaic::dive::PoseRecord& p) override {
    check();
    sink_.writeNavOdometry(p);
  }
  void writeDepth(const exocet_mosaic::dive::DepthRecord& d) override {
    check();
    sink_.writeDepth(d);
  }
  void writeAltitude(const exocet_mosaic::dive::AltitudeRecord& a) override {
    check();
    sink_.writeAltitude(a);
  }

 private:
  static void check() {
    if (g_signal != 0) throw Interrupted{g_signal};
  }
  exocet_mosaic::dive::DiveRecordSinkFor<exocet_mosaic::DiveBagWriter> sink_;
};

/// The replay's arguments beside the bag (replay_dive reads them), written whole or not at all.
void writeReplaySidecar(const std::string& bag_path, const std::vector<exocet_mosaic::dive::ReplayArgument>& args) {
  nlohmann::ordered_json arguments = nlohmann::ordered_json::object();
  for (const auto& a : args) arguments[a.name] = a.value;
  nlohmann::ordered_json sidecar;
  sidecar["description"] =
      "replay.launch arguments for this bag, written by dive_import; replay_dive BAG OUTDIR uses them, "
      "ARG:=VALUE on its command line overrides them";
  sidecar["replay_arguments"] = arguments;
  exocet_common::writeJsonFileAtomically(exocet_mosaic::dive::replaySidecarPath(bag_path), sidecar);
}

/// A folder for the tiles beside the bag: "dive.bag" -> "dive_tiles".
std::string tilesFolderFor(const std::string& bag_path) {
  const auto slash = bag_path.find_last_of('/');
  const auto dot = bag_path.find_last_of('.');
  const bool has_extension = dot != std::string::npos && (slash == std::string::npos || dot > slash + 1);
  return (has_extension ? bag_path.substr(0, dot) : bag_path) + "_tiles";
}

}  // namespace

int main(int argc, char** argv) {
  namespace dive = exocet_mosaic::dive;
  std::signal(SIGINT, onSignal);
  std::signal(SIGTERM, onSignal);
  try {
    const dive::DiveImportOptions options =
        dive::parseDiveImportArguments(std::vector<std::string>(argv + 1, argv + argc));
    if (options.help) {
      std::cout << dive::diveImportUsage();
      return 0;
    }
    const dive::DiveImport dive = dive::prepareDiveImport(options);
    for (const auto& warning : dive.warnings) std::cerr << "dive_import: warning: " << warning << "\n";

    exocet_mosaic::DiveBagWriter::Options bag_options;
    bag_options.image_storage = exocet_mosaic::parseImageStorage(options.image_storage);
    bag_options.world_frame = dive.navigation.world_frame;
    exocet_mosaic::DiveBagWriter writer(options.output_path, bag_options);
    InterruptibleBagSink sink(&writer);
    const dive::DiveImportSummary summary = dive::writeDiveImport(dive, &sink);
    writer.commit();
    const std::vector<dive::ReplayArgument> replay = dive::replayArguments(dive);
    writeReplaySidecar(options.output_path, replay);
    for (const auto& warning : summary.warnings()) std::cerr << "dive_import: warning: " << warning << "\n";
    std::cout << summary.line(options.output_path) << "\n";
    std::cout << "dive_import: replay it with (arguments also in " << dive::replaySidecarPath(options.output_path)
              << ", which replay_dive reads):\n  "
              << dive::replayCommand(options.output_path, tilesFolderFor(options.output_path), replay) << "\n";
    if (dive.hasNavigation() && summary.altitude_records == 0)
      std::cout << "dive_import: the navigation has no altitude: add camera_height_m:=M (the camera's height above "
                   "the seabed) or seabed_depth_m:=M (with /nav/depth) to the replay\n";
    if (!dive.hasNavigation() && !options.origin)
      std::cout << "dive_import: no start point (--origin-lat/--origin-lon): the tiles will be in the local frame "
                   "'map' (metres), not geo-referenced\n";
    std::cout << std::flush;
    return 0;
  } catch (const dive::DiveImportError& e) {
    std::cerr << "dive_import: error: " << e.what() << "\n";
    return e.exitCode();
  } catch (const Interrupted& interrupted) {
    std::cerr << "dive_import: interrupted by signal " << interrupted.signal << "; no bag written\n";
    return 128 + interrupted.signal;
  } catch (const std::exception& e) {
    // The bag writer's and rosbag's failures: disk full, rename refused, ...
    std::cerr << "dive_import: error: " << e.what() << "\n";
    return 1;
  }
}
