/**
 * @file textured_mesh.h
 * @brief A triangular surface mesh textured by one reference image (2D4 report sections 3.2.5.1-3.2.5.2): 3D vertices,
 *        triangles as vertex index triples, per-vertex texture coordinates and optional per-vertex colours. No ROS.
 */
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

namespace exocet_stereo {
namespace mesh {

/**
 * @brief Textured triangle mesh. Texture coordinates follow the IMAGE convention: u = (x + 0.5) / width to the right,
 *        v = (y + 0.5) / height DOWNWARD, both in [0, 1]; exporters flip v for formats whose origin is bottom-left
 *        (VRML, OBJ). Triangles are wound counter-clockwise as seen from the reference camera (normal towards it).
 */
struct TexturedMesh {
  std::vector<Eigen::Vector3d> vertices;    ///< world units (metres in practice)
  std::vector<Eigen::Vector3i> triangles;   ///< indices into vertices
  std::vector<Eigen::Vector2d> tex_coords;  ///< one per vertex (or empty: no texture mapping), in [0, 1]
  std::vector<cv::Vec3b> colors;            ///< one per vertex, RGB (or empty)
  cv::Mat texture;                          ///< texture image, BGR or grey CV_8U (may be empty)
  std::string texture_path;                 ///< texture file, used when texture is empty (may be empty)

  /// True without vertices or without triangles.
  bool empty() const { return vertices.empty() || triangles.empty(); }
  /// True if a texture image is attached (in memory or by path) and every vertex has texture coordinates.
  bool hasTexture() const {
    return (!texture.empty() || !texture_path.empty()) && tex_coords.size() == vertices.size() && !vertices.empty();
  }
  /// Empty if consistent, otherwise every problem ("; "-joined): index out of range, list sizes, coordinates
  /// outside [0, 1], non-finite vertices.
  std::string validate() const;
};

}  // namespace mesh
}  // namespace exocet_stereo
