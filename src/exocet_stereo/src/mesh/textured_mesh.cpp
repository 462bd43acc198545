#include "exocet_stereo/mesh/textured_mesh.h"

#include <sstream>

namespace exocet_stereo {
namespace mesh {

std::string TexturedMesh::validate() const {
  std::vector<std::string> problems;
  const int n = static_cast<int>(vertices.size());
  for (size_t i = 0; i < vertices.size(); ++i) {
    if (!vertices[i].allFinite()) {
      problems.push_back("vertex " + std::to_string(i) + " is not finite");
      break;
    }
  }
  for (size_t i = 0; i < triangles.size(); ++i) {
    const Eigen::Vector3i& t = triangles[i];
    if (t.minCoeff() < 0 || t.maxCoeff() >= n) {
      problems.push_back("triangle " + std::to_string(i) + " has an index outside [0, " + std::to_string(n - 1) + "]");
      break;
    }
  }
  if (!tex_coords.empty() && tex_coords.size() != vertices.size()) {
    problems.push_back("tex_coords has " + std::to_string(tex_coords.size()) + " entries, expected 0 or " +
                       std::to_string(n) + " (one per vertex)");
  }
  for (size_t i = 0; i < tex_coords.size(); ++i) {
    const Eigen::Vector2d& uv = tex_coords[i];
    if (!(uv.x() >= 0.0 && uv.x() <= 1.0 && uv.y() >= 0.0 && uv.y() <= 1.0)) {
      problems.push_back("tex_coords " + std::to_string(i) + " is outside [0, 1]");
      break;
    }
  }
  if (!colors.empty() && colors.size() != vertices.size()) {
    problems.push_back("colors has " + std::to_string(colors.size()) + " entries, expected 0 or " + std::to_string(n) +
                       " (one per vertex)");
  }
  if (!texture.empty() && texture.depth() != CV_8U) {
    problems.push_back("texture must be 8-bit (CV_8UC1 or CV_8UC3)");
  }
  std::ostringstream out;
  for (size_t i = 0; i < problems.size(); ++i) out << (i ? "; " : "") << problems[i];
  return out.str();
}

}  // namespace mesh
}  // namespace exocet_stereo
