/**
 * @file acquisition_reconstruction.h
 * @brief The offline reconstruction of an acquisition: every calibrated stereo pair to a depth map (pair_depth.h),
 * the depth maps fused into one cloud (cloud_fusion.h), its surface (cloud_surface.h) textured from the pairs' left
 * images (surface_texturing.h), and the files (fused cloud PLY; surface PLY, OBJ, VRML and their texture atlas PNG).
 * Shared by the command-line tool and the node. No ROS.
 */
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "exocet_stereo/mesh/cloud_fusion.h"
#include "exocet_stereo/mesh/cloud_surface.h"
#include "exocet_stereo/mesh/pair_depth.h"
#include "exocet_stereo/mesh/surface_texturing.h"
#include "exocet_stereo/mesh/textured_mesh.h"

namespace exocet_stereo {
namespace mesh {

/// Parameters of the whole reconstruction; validate() lists every bad field with its allowed range.
struct AcquisitionReconstructionConfig {
  PairDepthConfig depth = [] {
    PairDepthConfig c;
    c.min_depth_m = 0.4;  // an object 0.5-0.8 m in front of the rig on the arm
    c.max_depth_m = 1.0;
    return c;
  }();
  CloudFusionConfig fusion = [] {
    CloudFusionConfig c;
    c.voxel_m = 0.002;
    c.depth_tolerance = 0.005;
    c.min_confirmations = 1;
    return c;
  }();
  /// Texture the surface from the left images of the pairs that gave a depth map (off: geometry and vertex colours).
  bool texture = true;
  SurfaceTexturingConfig texturing;
  /// The surface's grid follows the fusion's voxel: cell = voxel, reach = 3 voxels.
  std::string validate() const;
};

/// What came out.
struct AcquisitionReconstruction {
  std::vector<DepthView> views;       ///< one per pair that gave a depth map
  FusedCloud cloud;
  TexturedMesh surface;               ///< empty when the cloud was too sparse for one; textured if config.texture
  SurfaceTexturingStats texturing;    ///< zeros when not textured
  std::vector<std::string> warnings;  ///< pairs left out, and why
};

/// Progress: what is being done, and the fraction of the whole done so far, [0, 1].
using ReconstructionProgress = std::function<void(const std::string& stage, double fraction)>;

/**
 * @brief Reconstructs the pairs. A pair that fails (no baseline, bad images) is left out with a warning.
 * @throws std::invalid_argument on an invalid config; std::runtime_error when no pair gives a depth map or the
 *         depth maps confirm no point (the message says what to change).
 */
AcquisitionReconstruction reconstructPairs(const std::vector<CalibratedPair>& pairs,
                                           const AcquisitionReconstructionConfig& config,
                                           const ReconstructionProgress& progress = nullptr);

/// Writes fused_cloud.ply and, with a surface, surface.ply, surface.obj (+ surface.mtl) and surface.wrl into `dir`
/// (created), and surface.png, their texture atlas, when the surface is textured.
/// @return the files written (not the MTL). @throws std::runtime_error when a file cannot be written.
std::vector<std::string> writeReconstruction(const AcquisitionReconstruction& result, const std::string& dir);

}  // namespace mesh
}  // namespace exocet_stereo
