// Benchmark of the dive simulator: frames rendered per second on one thread, PAL and HD, with the sample dive's
// underwater effects (light cone, attenuation, noise, marine snow) over a relief. Writes dive_synth.json.
#include <chrono>
#include <iostream>
#include <string>

#include <nlohmann/json.hpp>

#include "exocet_mosaic/sim/dive_description.h"
#include "exocet_common/json_file.h"
#include "exocet_common/command_line.h"

namespace {
using namespace exocet_mosaic::sim;

struct Figures {
  double fps = 0.0;
  int frames = 0;
  double seconds = 0.0;
};

Figures measure(const std::string& preset, bool relief, int frames) {
  std::vector<std::string> overrides = {
      "camera.preset=" + preset, "camera.fps=10", "trajectory.kind=out_and_back", "trajectory.line_length_m=60",
      "trajectory.speed_mps=0.5", std::string("seabed.relief=") + (relief ? "true" : "false"),
      "imaging.light_cone_strength=0.7", "imaging.vignetting=0.4", "imaging.attenuation_per_m=[0.3,0.1,0.08]",
      "imaging.backscatter=0.15", "imaging.noise_sigma_dn=2", "imaging.marine_snow_per_m3=15",
      "duration_s=" + std::to_string(frames / 10.0 + 0.05), "threads=1"};
  const DiveDescription dive = parseDiveDescription("", overrides, ".");
  Seabed seabed = makeSeabed(dive.seabed, dive.synthesis.seed);
  DiveSynthesizer synth(dive.synthesis, seabed.texture.get(), seabed.relief.get());
  DiveSink sink;  // frames are rendered and dropped: this measures the simulator, not the disk
  const auto start = std::chrono::steady_clock::now();
  synth.run(sink);
  Figures f;
  f.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  f.frames = synth.frameCount();
  f.fps = f.frames / f.seconds;
  return f;
}
}  // namespace

int main(int argc, char** argv) {
  exocet_common::BenchmarkPaths paths;
  CLI::App app(
      "bench_dive_synth: frames rendered per second by the dive simulator on one thread, PAL and HD, flat\n"
      "and with relief. Writes OUTPUT_DIR/dive_synth.json.",
      "bench_dive_synth");
  exocet_common::addBenchmarkPathOptions(app, &paths, false);
  if (const auto exit_status = exocet_common::parseCommandLine(app, argc, argv)) return *exit_status;
  const Figures pal = measure("pal", false, 150);
  const Figures pal_relief = measure("pal", true, 150);
  const Figures hd = measure("hd", false, 40);
  const Figures hd_relief = measure("hd", true, 40);
  std::cout << "dive_synth rendering, one thread (frames/s, including tile generation along the track):\n"
            << "  720x576   flat seabed: " << pal.fps << "   with relief: " << pal_relief.fps << "\n"
            << "  1920x1080 flat seabed: " << hd.fps << "   with relief: " << hd_relief.fps << "\n";
  const std::string path = paths.output_dir + "/dive_synth.json";
  nlohmann::ordered_json json;
  json["fps_pal"] = pal.fps;
  json["fps_hd"] = hd.fps;
  json["fps_pal_relief"] = pal_relief.fps;
  json["fps_hd_relief"] = hd_relief.fps;
  json["frames_pal"] = pal.frames;
  json["frames_hd"] = hd.frames;
  json["threads"] = 1;
  try {
    exocet_common::writeJsonFileAtomically(path, json);
  } catch (const std::exception& e) {
    std::cerr << "bench_dive_synth: " << e.what() << "\n";
    return 1;
  }
  std::cout << "wrote " << path << "\n";
  return 0;
}
