/**
 * @file mesh_export.h
 * @brief Writers for textured meshes (2D4 report section 3.2.5.3: VRML "for easy visualization and exchange"):
 *        VRML 2.0 (.wrl, Shape + ImageTexture + IndexedFaceSet), ASCII PLY (coloured vertices, faces), Wavefront OBJ
 *        + MTL (map_Kd), and an ASCII PLY point-cloud writer. The texture is written beside the mesh as
 *        "<mesh stem>.png" and referenced by its file name (relative), so the folder can be moved.
 */
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "exocet_stereo/mesh/textured_mesh.h"

namespace exocet_stereo {
namespace io {

/**
 * @brief VRML 2.0: one Shape whose appearance is an ImageTexture (url = the PNG beside) and whose geometry is an
 *        IndexedFaceSet (coord, coordIndex, texCoord, texCoordIndex; v flipped to VRML's bottom-left origin).
 *        Without texture, per-vertex colours (if any) are written as a Color node.
 * @return the texture file written (full path), empty if none.
 * @throws std::invalid_argument on an empty or inconsistent mesh; std::runtime_error if a file cannot be written
 *         (missing or read-only folder) or the texture_path cannot be read.
 */
std::string writeVrml(const std::string& wrl_path, const mesh::TexturedMesh& mesh);

/**
 * @brief ASCII PLY: "vertex" (x y z, and red green blue uchar when the mesh has colours or a texture to sample them
 *        from) and "face" (vertex_indices). The texture, if any, is written beside and named in a "comment
 *        TextureFile" line (MeshLab's convention), with per-face "texcoord" lists.
 * @return the texture file written, empty if none. @throws as writeVrml().
 */
std::string writePly(const std::string& ply_path, const mesh::TexturedMesh& mesh);

/**
 * @brief Wavefront OBJ ("mtllib", "usemtl", "v", "vt" with v flipped, "f v/vt") and its MTL ("<stem>.mtl",
 *        "map_Kd <stem>.png") beside it.
 * @return the texture file written, empty if none. @throws as writeVrml().
 */
std::string writeObj(const std::string& obj_path, const mesh::TexturedMesh& mesh);

/**
 * @brief ASCII PLY point cloud (x y z, plus red green blue when colors has one RGB entry per point).
 * @throws std::invalid_argument on no points or a colour count mismatch; std::runtime_error if unwritable.
 */
void writePointCloudPly(const std::string& ply_path, const std::vector<Eigen::Vector3d>& points,
                        const std::vector<cv::Vec3b>& colors = {});

}  // namespace io
}  // namespace exocet_stereo
