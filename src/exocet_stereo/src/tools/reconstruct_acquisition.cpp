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

#include "exocet_common/command_line.h"
#include "exocet_stereo/dense/dense_stereo.h"
#include "exocet_stereo/mesh/acquisition_reconstruction.h"
#include "exocet_stereo/ros/acquisition_bag.h"

int main(int argc, char** argv) {
  using namespace exocet_stereo;
  std::string bag_path, output_dir;
  mesh::AcquisitionReconstructionConfig config;
  CLI::App app(
      "reconstruct_acquisition: the offline reconstruction of an acquisition bag, written as fused_cloud.ply,\n"
      "surface.ply, surface.obj and surface.wrl (with their texture atlas surface.png) into the output folder.",
      "reconstruct_acquisition");
  app.add_option("--bag", bag_path,
                 "exocet_servo's acquisition_sequencer_node bag (left|right/image_raw, camera_info, pose\nper stop)")
      ->type_name("ACQUISITION.bag")
      ->required()
      ->check(CLI::ExistingFile);
  app.add_option("--output-dir", output_dir, "folder of the PLY, OBJ and VRML files")->type_name("DIR")->required();
  app.add_option("--method", config.depth.method, "dense stereo method of the depth maps")
      ->check(CLI::IsMember(dense::denseStereoMethods()))
      ->capture_default_str();
  app.add_option("--min-depth-m", config.depth.min_depth_m, "nearest depth searched (metres), in (0, --max-depth-m)")
      ->type_name("M")
      ->capture_default_str();
  app.add_option("--max-depth-m", config.depth.max_depth_m, "farthest depth searched (metres), at most 1e4")
      ->type_name("M")
      ->capture_default_str();
  app.add_option("--voxel-m", config.fusion.voxel_m,
                 "voxel of the fused cloud and cell of the surface (metres), in "
                 "(0, 1e3]")
      ->type_name("M")
      ->capture_default_str();
  app.add_option("--min-confirmations", config.fusion.min_confirmations,
                 "other depth maps that must confirm a point, in [0, 64]")
      ->type_name("N")
      ->capture_default_str();
  app.add_option("--texture", config.texture, "1: texture the surface from the left images; 0: vertex colours only")
      ->type_name("0|1")
      ->check(CLI::IsMember({"0", "1"}))
      ->default_str("1");
  app.add_option("--atlas-scale", config.texturing.atlas_scale,
                 "downscaling of the left images in the texture atlas, in (0, 1]")
      ->type_name("S")
      ->capture_default_str();
  if (const auto exit_status = exocet_common::parseCommandLine(app, argc, argv)) return *exit_status;
  const std::string problems = config.validate();
  if (!problems.empty()) {
    std::cerr << "reconstruct_acquisition: " << problems << "\n";
    return exocet_common::kExitBadInput;
  }

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
