/**
 * @file cloud_surface.h
 * @brief A surface of a fused, oriented point cloud (issue 7): the zero level set of the implicit moving least
 *        squares function of the points and their normals (Kolluri 2005, after Hoppe et al. 1992's signed distance to
 *        the tangent planes), f(x) = sum_i w_i n_i . (x - p_i) / sum_i w_i with gaussian weights w_i, sampled on a
 *        sparse grid around the points and polygonised by marching tetrahedra (six per cube, Kuhn split, so
 *        neighbouring cubes agree). Grid nodes with too few points in reach are undefined and no triangle touches
 *        them: the surface stops where the data stop instead of closing over holes (unlike Poisson). Vertices are
 *        shared between triangles; their colours are the weighted colours of the points. No ROS.
 *
 * PCL (Poisson, greedy projection) is not a dependency of the project: this small, standard method does the job.
 */
#pragma once

#include <string>

#include "exocet_stereo/mesh/cloud_fusion.h"
#include "exocet_stereo/mesh/textured_mesh.h"

namespace exocet_stereo {
namespace mesh {

/// Parameters of the surface. validate() lists every bad field with its allowed range.
struct CloudSurfaceConfig {
  double cell_m = 0.002;  ///< grid spacing (about the cloud's voxel size), (0, 1e3]
  /// Reach of the points: weight exp(-(d / (radius_m / 2))^2), none beyond radius_m; [cell_m, 100 cell_m].
  double radius_m = 0.005;
  int min_neighbours = 4;  ///< a grid node with fewer points within radius_m is undefined, [1, 10000]
  /// Connected pieces with fewer triangles than this are dropped (floating specks), [0, 1e9].
  int min_component_triangles = 20;
  /// Empty if usable, otherwise every bad field with its allowed range ("; "-joined).
  std::string validate() const;
};

/// What the surface extraction did.
struct CloudSurfaceStats {
  long nodes = 0;              ///< grid nodes evaluated
  long defined_nodes = 0;      ///< with at least min_neighbours points in reach
  long removed_triangles = 0;  ///< in pieces smaller than min_component_triangles
  long triangles = 0;          ///< kept
};

/**
 * @brief Surface of an oriented cloud (points and unit normals, e.g. fuseDepthMaps()'s output). The mesh has no
 *        texture mapping; it has per-vertex colours when the cloud has colours. Triangles face the side the normals
 *        point to (the cameras').
 * @throws std::invalid_argument on an invalid config or a cloud whose normals (or colours) do not match its points.
 */
TexturedMesh surfaceFromCloud(const FusedCloud& cloud, const CloudSurfaceConfig& config,
                              CloudSurfaceStats* stats = nullptr);

}  // namespace mesh
}  // namespace exocet_stereo
