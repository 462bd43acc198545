// reconstruct_acquisition: the offline reconstruction of an acquisition (2D4 report, section 3, carried on to every
// pair and a dense surface). Reads the bag written by exocet_servo's acquisition_sequencer_node, turns each stereo
// pair into a depth map (rectification, dense stereo over a depth range), fuses the depth maps of all pairs into one
// cloud, builds its surface, textures it from the left images and writes fused_cloud.ply, surface.ply, surface.obj
// and surface.wrl (with their texture atlas surface.png) into the output folder. Progress on stdout. The node
// reconstruction_node does the same and shows the result in rviz.
#include <chrono>
#include <iostream>
#include <string>
#include <vector>

#include "exocet_stereo/mesh/acquisition_reconstruction.h"
#include "exocet_stereo/ros/acquisition_bag.h"

namespace {

int usage(const std::string& error) {
  if (!error.empty()) std::cerr << "reconstruct_acquisition: " << error << "\n";
  std::cerr << "usage: reconstruct_acquisition --bag ACQUISITION.bag --output-dir DIR [--method sgm] "
               "[--min-depth-m 0.4] [--max-depth-m 1.0] [--voxel-m 0.002] [--min-confirmations 1] [--texture 1] "
               "[--atlas-scale 1.0]\n"
               "  --texture 0 keeps the surface untextured (vertex colours only); --atlas-scale (0, 1] downscales the "
               "left images in the texture atlas.\n"
               "  The bag: exocet_servo's acquisition_sequencer_node (left|right/image_raw, camera_info, pose per "
               "stop).\n";
  return error.empty() ? 0 : 2;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace exocet_stereo;
  std::string bag_path, output_dir;
  mesh::AcquisitionReconstructionConfig config;
  try {
    for (int i = 1; i < argc; ++i) {
      const std::string arg = argv[i];
      if (arg == "--help" || arg == "-h") return usage("");
      if (i + 1 >= argc) return usage("option " + arg + " needs a value");
      const std::string value = argv[++i];
      if (arg == "--bag") bag_path = value;
      else if (arg == "--output-dir") output_dir = value;
      else if (arg == "--method") config.depth.method = value;
      else if (arg == "--min-depth-m") config.depth.min_depth_m = std::stod(value);
      else if (arg == "--max-depth-m") config.depth.max_depth_m = std::stod(value);
      else if (arg == "--voxel-m") config.fusion.voxel_m = std::stod(value);
      else if (arg == "--min-confirmations") config.fusion.min_confirmations = std::stoi(value);
      else if (arg == "--texture" && (value == "0" || value == "1")) config.texture = value == "1";
      else if (arg == "--texture") return usage("--texture must be 0 or 1");
      else if (arg == "--atlas-scale") config.texturing.atlas_scale = std::stod(value);
      else return usage("unknown option " + arg);
    }
  } catch (const std::exception&) {
    return usage("a numeric option has a value that is not a number");
  }
  if (bag_path.empty() || output_dir.empty()) return usage("--bag and --output-dir are required");
  const std::string problems = config.validate();
  if (!problems.empty()) return usage(problems);

  const auto start = std::chrono::steady_clock::now();
  const auto elapsed = [&start] {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  };
  try {
    std::vector<std::string> warnings;
    const std::vector<mesh::CalibratedPair> pairs = readAcquisitionBag(bag_path, &warnings);
    for (const std::string& w : warnings) std::cerr << "reconstruct_acquisition: " << w << "\n";
    if (pairs.empty()) {
      std::cerr << "reconstruct_acquisition: " << bag_path << " holds no complete stop (left|right image_raw, "
                << "camera_info and pose at one stamp)\n";
      return 1;
    }
    std::cout << "reconstruct_acquisition: " << pairs.size() << " stereo pairs in " << bag_path << "\n";
    const mesh::AcquisitionReconstruction result =
        mesh::reconstructPairs(pairs, config, [&](const std::string& stage, double fraction) {
          std::cout << "  " << static_cast<int>(100.0 * fraction + 0.5) << " %: " << stage << " (" << elapsed()
                    << " s)\n";
        });
    for (const std::string& w : result.warnings) std::cerr << "reconstruct_acquisition: " << w << "\n";
    std::cout << "  fused cloud " << result.cloud.size() << " points; surface " << result.surface.vertices.size()
              << " vertices, " << result.surface.triangles.size() << " triangles\n";
    if (result.surface.hasTexture()) {
      std::cout << "  texture: " << result.texturing.textured_triangles << " triangles from "
                << result.texturing.views_used << " views, " << result.texturing.untextured_triangles
                << " seen by none; atlas " << result.texturing.atlas_width_px << "x"
                << result.texturing.atlas_height_px << " px, " << result.texturing.seam_edges << " seam edges\n";
    }
    const std::vector<std::string> files = mesh::writeReconstruction(result, output_dir);
    std::cout << "reconstruct_acquisition: wrote";
    for (const std::string& f : files) std::cout << " " << f;
    std::cout << " (" << elapsed() << " s)\n";
  } catch (const std::exception& e) {
    std::cerr << "reconstruct_acquisition: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
