/**
 * @file image_mesher.h
 * @brief The 2D4 report's surface model (section 3.2.5.1): a 2D Delaunay triangulation (cv::Subdiv2D) of the points of
 *        the reference image whose 3D position is known, lifted to 3D; triangles spanning a depth discontinuity and
 *        degenerate ones are removed; texture coordinates are the pixel positions over the image size (3.2.5.2).
 *        No ROS.
 */
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "exocet_stereo/geometry/pinhole_view.h"
#include "exocet_stereo/mesh/depth_map.h"
#include "exocet_stereo/mesh/textured_mesh.h"

namespace exocet_stereo {
namespace mesh {

/// Parameters of the mesher. validate() lists every bad field with its allowed range.
struct ImageMesherConfig {
  int grid_step_px = 4;  ///< subsampling of depth/disparity maps (every step-th pixel in x and y), [1, 256]
  /// A triangle whose longest 3D edge exceeds this fraction of its mean vertex depth spans a depth discontinuity
  /// (a grid step of s px at focal f gives about 1.4 s / f on a fronto-parallel surface), (0, 100].
  double max_edge_depth_ratio = 0.05;
  /// Longest over shortest 3D edge above this: a sliver across a discontinuity or a degenerate triangle; 0 = off,
  /// otherwise [1, 1e6].
  double max_edge_length_ratio = 20.0;
  double min_area_px2 = 1e-3;  ///< triangles smaller than this in the image are degenerate, [0, 1e6]
  /// Empty if usable, otherwise every bad field with its allowed range ("; "-joined).
  std::string validate() const;
};

/// What the mesher kept and removed.
struct MeshingStats {
  int input_points = 0;           ///< points offered
  int used_points = 0;            ///< after removing duplicates, non-finite and behind-camera points
  int delaunay_triangles = 0;     ///< triangles of the 2D Delaunay triangulation
  int removed_discontinuity = 0;  ///< removed by max_edge_depth_ratio / max_edge_length_ratio
  int removed_degenerate = 0;     ///< removed by min_area_px2 or a null 3D area
  int triangles = 0;              ///< kept
};

/**
 * @brief Meshes sparse points: pixels[i] in the reference image (of size image_size) sees world point points[i].
 *        Vertices are the used points referenced by a kept triangle (input order; a repeated pixel keeps its first
 *        point), texture coordinates
 *        (x + 0.5) / width, (y + 0.5) / height. The texture is left empty: attach the reference image.
 * @throws std::invalid_argument on mismatched lists, a bad size or an invalid config (message lists the fields).
 */
TexturedMesh meshFromPoints(const std::vector<Eigen::Vector2d>& pixels, const std::vector<Eigen::Vector3d>& points,
                            const geometry::PinholeView& view, const cv::Size& image_size,
                            const ImageMesherConfig& config, MeshingStats* stats = nullptr);

/**
 * @brief Meshes a subsampled grid of a depth map (metres along the optical axis, NaN unknown) seen by view; image
 *        (optional, same size) becomes the texture and gives the vertex colours.
 */
TexturedMesh meshFromDepth(const cv::Mat& depth_m, const geometry::PinholeView& view, const cv::Mat& image,
                           const ImageMesherConfig& config, MeshingStats* stats = nullptr);

/// meshFromDepth() of depthFromDisparity(): view is the LEFT rectified view of the pair.
TexturedMesh meshFromDisparity(const cv::Mat& disparity_px, const RectifiedPairGeometry& pair,
                               const geometry::PinholeView& view, const cv::Mat& image, const ImageMesherConfig& config,
                               MeshingStats* stats = nullptr);

}  // namespace mesh
}  // namespace exocet_stereo
