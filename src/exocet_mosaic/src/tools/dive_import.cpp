// dive_import: images + navigation CSV + camera intrinsics -> a dive bag with the simulator's layout.
// Usage and conventions: dive_import --help (text in dive/dive_import.cpp), README.md (section "Importing a real dive:
// dive_import").

#include <csignal>
#include <iostream>
#include <string>
#include <vector>

#include "exocet_mosaic/ros/dive_bag_writer.h"
#include "exocet_mosaic/dive/dive_import.h"

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
    for (const auto& warning : summary.warnings()) std::cerr << "dive_import: warning: " << warning << "\n";
    std::cout << summary.line(options.output_path) << std::endl;
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
