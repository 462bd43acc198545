#include "exocet_stereo/mesh/acquisition_reconstruction.h"

#include <filesystem>
#include <stdexcept>

#include "exocet_stereo/io/mesh_export.h"

namespace exocet_stereo {
namespace mesh {

std::string AcquisitionReconstructionConfig::validate() const {
  std::string s = depth.validate();
  const std::string f = fusion.validate();
  if (!f.empty()) s += (s.empty() ? "" : "; ") + f;
  const std::string t = texture ? texturing.validate() : std::string();
  if (!t.empty()) s += (s.empty() ? "" : "; ") + t;
  return s;
}

AcquisitionReconstruction reconstructPairs(const std::vector<CalibratedPair>& pairs,
                                           const AcquisitionReconstructionConfig& config,
                                           const ReconstructionProgress& progress) {
  const std::string problems = config.validate();
  if (!problems.empty()) throw std::invalid_argument("AcquisitionReconstructionConfig: " + problems);
  const auto report = [&progress](const std::string& stage, double fraction) {
    if (progress) progress(stage, fraction);
  };
  AcquisitionReconstruction result;
  // Dense stereo dominates the time: the pairs are 90 % of the progress.
  std::vector<TextureView> texture_views;
  for (size_t k = 0; k < pairs.size(); ++k) {
    report("pair " + std::to_string(k + 1) + " of " + std::to_string(pairs.size()), 0.9 * k / pairs.size());
    try {
      result.views.push_back(depthFromPair(pairs[k], config.depth));
      // The original left image (not the rectified one): no resampling, and its calibration is the pair's.
      texture_views.push_back(TextureView{pairs[k].left, pairs[k].K_left, pairs[k].world_T_left});
    } catch (const std::exception& e) {
      result.warnings.push_back("pair " + std::to_string(k + 1) + " left out: " + e.what());
    }
  }
  if (result.views.empty())
    throw std::runtime_error("no pair gave a depth map" +
                             (result.warnings.empty() ? std::string() : " (" + result.warnings.front() + ")"));
  report("fusing " + std::to_string(result.views.size()) + " depth maps", 0.9);
  result.cloud = fuseDepthMaps(result.views, config.fusion);
  if (result.cloud.size() == 0)
    throw std::runtime_error("the depth maps confirm no point: lower fusion.min_confirmations or widen the depth range");
  report("surface of " + std::to_string(result.cloud.size()) + " points", 0.95);
  CloudSurfaceConfig surface;
  surface.cell_m = config.fusion.voxel_m;
  surface.radius_m = 3.0 * config.fusion.voxel_m;
  result.surface = surfaceFromCloud(result.cloud, surface);
  if (config.texture && !result.surface.empty()) {
    report("texturing " + std::to_string(result.surface.triangles.size()) + " triangles", 0.97);
    try {
      result.surface = textureSurface(result.surface, texture_views, config.texturing, &result.texturing);
    } catch (const std::exception& e) {
      // An image the texturing cannot use must not cost the geometry.
      result.warnings.push_back(std::string("surface left untextured: ") + e.what());
    }
  }
  report("done", 1.0);
  return result;
}

std::vector<std::string> writeReconstruction(const AcquisitionReconstruction& result, const std::string& dir) {
  std::error_code error;
  std::filesystem::create_directories(dir, error);
  if (error) throw std::runtime_error("cannot create " + dir + ": " + error.message());
  const std::filesystem::path d(dir);
  std::vector<std::string> files{(d / "fused_cloud.ply").string()};
  io::writePointCloudPly(files.back(), result.cloud.points, result.cloud.colors);
  if (!result.surface.empty()) {
    for (const char* name : {"surface.ply", "surface.obj", "surface.wrl"}) files.push_back((d / name).string());
    io::writePly(files[1], result.surface);
    io::writeObj(files[2], result.surface);
    // Every writer puts the same atlas beside its file as "surface.png".
    const std::string png = io::writeVrml(files[3], result.surface);
    if (!png.empty()) files.push_back(png);
  }
  return files;
}

}  // namespace mesh
}  // namespace exocet_stereo
