#include "exocet_stereo/io/mesh_export.h"

#include <algorithm>
#include <fstream>
#include <iomanip>
#include <limits>
#include <stdexcept>

#include <filesystem>
#include <opencv2/imgcodecs.hpp>

namespace exocet_stereo {
namespace io {

namespace fs = std::filesystem;

namespace {

constexpr int kCoordinateDigits = std::numeric_limits<double>::max_digits10;  // exact round trip of doubles
constexpr int kTexDigits = 10;

void checkMesh(const char* writer, const mesh::TexturedMesh& mesh) {
  if (mesh.empty()) {
    throw std::invalid_argument(std::string(writer) + ": mesh is empty (" + std::to_string(mesh.vertices.size()) +
                                " vertices, " + std::to_string(mesh.triangles.size()) +
                                " triangles; at least 3 vertices and 1 triangle needed)");
  }
  const std::string bad = mesh.validate();
  if (!bad.empty()) throw std::invalid_argument(std::string(writer) + ": inconsistent mesh: " + bad);
}

/// Opens path for writing, or throws naming the folder: the usual cause is a missing or read-only folder.
void openOut(const std::string& path, std::ofstream& out) {
  out.open(path);
  if (!out) {
    std::error_code ec;
    fs::path folder = fs::absolute(fs::path(path), ec).parent_path();
    if (ec) folder = fs::path(path).parent_path();
    const bool exists = fs::is_directory(folder, ec);
    throw std::runtime_error("cannot write '" + path + "': folder '" + folder.string() +
                             (exists ? "' is not writable" : "' does not exist"));
  }
  out << std::setprecision(kCoordinateDigits);
}

void closeOut(const std::string& path, std::ofstream& out) {
  out.close();
  if (!out) throw std::runtime_error("error while writing '" + path + "' (disk full?)");
}

/// The texture image (in memory, else read from texture_path), empty if the mesh has no texture mapping.
cv::Mat textureImage(const mesh::TexturedMesh& mesh) {
  if (!mesh.hasTexture()) return cv::Mat();
  if (!mesh.texture.empty()) return mesh.texture;
  cv::Mat image = cv::imread(mesh.texture_path, cv::IMREAD_UNCHANGED);
  if (image.empty()) throw std::runtime_error("cannot read the mesh texture '" + mesh.texture_path + "'");
  return image;
}

/// Writes the texture as "<mesh stem>.png" beside mesh_path; returns its full path (empty without texture).
std::string writeTexture(const std::string& mesh_path, const cv::Mat& texture) {
  if (texture.empty()) return "";
  const std::string png = fs::path(mesh_path).replace_extension(".png").string();
  bool ok = false;
  try {
    ok = cv::imwrite(png, texture);
  } catch (const cv::Exception& e) {
    throw std::runtime_error("cannot write texture '" + png + "': " + e.what());
  }
  if (!ok) throw std::runtime_error("cannot write texture '" + png + "' (folder missing or not writable?)");
  return png;
}

std::string fileName(const std::string& path) { return fs::path(path).filename().string(); }

/// Per-vertex RGB: the mesh's colours, else sampled from the texture at the texture coordinates, else none.
std::vector<cv::Vec3b> vertexColors(const mesh::TexturedMesh& mesh, const cv::Mat& texture) {
  if (!mesh.colors.empty()) return mesh.colors;
  std::vector<cv::Vec3b> colors;
  if (texture.empty() || (texture.type() != CV_8UC3 && texture.type() != CV_8UC1)) return colors;
  for (const Eigen::Vector2d& uv : mesh.tex_coords) {
    const int x = std::clamp(static_cast<int>(uv.x() * texture.cols), 0, texture.cols - 1);
    const int y = std::clamp(static_cast<int>(uv.y() * texture.rows), 0, texture.rows - 1);
    if (texture.type() == CV_8UC3) {
      const cv::Vec3b bgr = texture.at<cv::Vec3b>(y, x);
      colors.emplace_back(bgr[2], bgr[1], bgr[0]);
    } else {
      const uchar g = texture.at<uchar>(y, x);
      colors.emplace_back(g, g, g);
    }
  }
  return colors;
}

}  // namespace

std::string writeVrml(const std::string& wrl_path, const mesh::TexturedMesh& mesh) {
  checkMesh("writeVrml", mesh);
  const cv::Mat texture = textureImage(mesh);
  std::ofstream out;
  openOut(wrl_path, out);
  const std::string png = writeTexture(wrl_path, texture);
  out << "#VRML V2.0 utf8\n# Exocet textured mesh: " << mesh.vertices.size() << " vertices, " << mesh.triangles.size()
      << " triangles\nShape {\n  appearance Appearance {\n";
  if (!png.empty()) {
    out << "    texture ImageTexture { url \"" << fileName(png) << "\" }\n";
  } else {
    out << "    material Material { diffuseColor 0.8 0.8 0.8 }\n";
  }
  out << "  }\n  geometry IndexedFaceSet {\n    solid FALSE\n    ccw TRUE\n    coord Coordinate {\n      point [\n";
  for (const Eigen::Vector3d& v : mesh.vertices) out << "        " << v.x() << ' ' << v.y() << ' ' << v.z() << ",\n";
  out << "      ]\n    }\n    coordIndex [\n";
  for (const Eigen::Vector3i& t : mesh.triangles) out << "      " << t[0] << ", " << t[1] << ", " << t[2] << ", -1,\n";
  out << "    ]\n";
  if (!png.empty()) {
    out << std::setprecision(kTexDigits) << "    texCoord TextureCoordinate {\n      point [\n";
    // VRML's texture origin is the bottom-left corner.
    for (const Eigen::Vector2d& uv : mesh.tex_coords) out << "        " << uv.x() << ' ' << 1.0 - uv.y() << ",\n";
    out << "      ]\n    }\n    texCoordIndex [\n";
    for (const Eigen::Vector3i& t : mesh.triangles)
      out << "      " << t[0] << ", " << t[1] << ", " << t[2] << ", -1,\n";
    out << "    ]\n";
  } else if (!mesh.colors.empty()) {
    out << std::setprecision(6) << "    colorPerVertex TRUE\n    color Color {\n      color [\n";
    for (const cv::Vec3b& c : mesh.colors) {
      out << "        " << c[0] / 255.0 << ' ' << c[1] / 255.0 << ' ' << c[2] / 255.0 << ",\n";
    }
    out << "      ]\n    }\n";
  }
  out << "  }\n}\n";
  closeOut(wrl_path, out);
  return png;
}

std::string writePly(const std::string& ply_path, const mesh::TexturedMesh& mesh) {
  checkMesh("writePly", mesh);
  const cv::Mat texture = textureImage(mesh);
  std::ofstream out;
  openOut(ply_path, out);
  const std::string png = writeTexture(ply_path, texture);
  const std::vector<cv::Vec3b> colors = vertexColors(mesh, texture);
  out << "ply\nformat ascii 1.0\ncomment Exocet textured mesh\n";
  if (!png.empty()) out << "comment TextureFile " << fileName(png) << '\n';
  out << "element vertex " << mesh.vertices.size() << "\nproperty double x\nproperty double y\nproperty double z\n";
  if (!colors.empty()) out << "property uchar red\nproperty uchar green\nproperty uchar blue\n";
  out << "element face " << mesh.triangles.size() << "\nproperty list uchar int vertex_indices\n";
  if (!png.empty()) out << "property list uchar float texcoord\n";
  out << "end_header\n";
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    const Eigen::Vector3d& v = mesh.vertices[i];
    out << v.x() << ' ' << v.y() << ' ' << v.z();
    if (!colors.empty()) out << ' ' << int(colors[i][0]) << ' ' << int(colors[i][1]) << ' ' << int(colors[i][2]);
    out << '\n';
  }
  for (const Eigen::Vector3i& t : mesh.triangles) {
    out << "3 " << t[0] << ' ' << t[1] << ' ' << t[2];
    if (!png.empty()) {
      out << " 6" << std::setprecision(kTexDigits);
      // MeshLab's texcoord convention: origin bottom-left, like OBJ.
      for (int k = 0; k < 3; ++k) out << ' ' << mesh.tex_coords[t[k]].x() << ' ' << 1.0 - mesh.tex_coords[t[k]].y();
      out << std::setprecision(kCoordinateDigits);
    }
    out << '\n';
  }
  closeOut(ply_path, out);
  return png;
}

std::string writeObj(const std::string& obj_path, const mesh::TexturedMesh& mesh) {
  checkMesh("writeObj", mesh);
  const cv::Mat texture = textureImage(mesh);
  const std::string mtl_path = fs::path(obj_path).replace_extension(".mtl").string();
  std::ofstream out;
  openOut(obj_path, out);
  std::ofstream mtl;
  openOut(mtl_path, mtl);
  const std::string png = writeTexture(obj_path, texture);

  mtl << "# Exocet textured mesh material\nnewmtl exocet_texture\nKa 1 1 1\nKd 1 1 1\nKs 0 0 0\nd 1\nillum 1\n";
  if (!png.empty()) mtl << "map_Kd " << fileName(png) << '\n';
  closeOut(mtl_path, mtl);

  out << "# Exocet textured mesh: " << mesh.vertices.size() << " vertices, " << mesh.triangles.size()
      << " triangles\nmtllib " << fileName(mtl_path) << "\nusemtl exocet_texture\n";
  const bool with_colors = !mesh.colors.empty();
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    const Eigen::Vector3d& v = mesh.vertices[i];
    out << "v " << v.x() << ' ' << v.y() << ' ' << v.z();
    // "v x y z r g b" (colours in [0, 1]) is the widespread extension read by MeshLab and Open3D.
    if (with_colors) {
      out << std::setprecision(6) << ' ' << mesh.colors[i][0] / 255.0 << ' ' << mesh.colors[i][1] / 255.0 << ' '
          << mesh.colors[i][2] / 255.0 << std::setprecision(kCoordinateDigits);
    }
    out << '\n';
  }
  if (!png.empty()) {
    out << std::setprecision(kTexDigits);
    for (const Eigen::Vector2d& uv : mesh.tex_coords) out << "vt " << uv.x() << ' ' << 1.0 - uv.y() << '\n';
  }
  for (const Eigen::Vector3i& t : mesh.triangles) {
    out << 'f';
    for (int k = 0; k < 3; ++k) {
      out << ' ' << t[k] + 1;  // OBJ indices are 1-based
      if (!png.empty()) out << '/' << t[k] + 1;
    }
    out << '\n';
  }
  closeOut(obj_path, out);
  return png;
}

void writePointCloudPly(const std::string& ply_path, const std::vector<Eigen::Vector3d>& points,
                        const std::vector<cv::Vec3b>& colors) {
  if (points.empty()) throw std::invalid_argument("writePointCloudPly: no points to write");
  if (!colors.empty() && colors.size() != points.size()) {
    throw std::invalid_argument("writePointCloudPly: " + std::to_string(colors.size()) + " colours for " +
                                std::to_string(points.size()) + " points (expected 0 or one per point)");
  }
  std::ofstream out;
  openOut(ply_path, out);
  out << "ply\nformat ascii 1.0\ncomment Exocet point cloud\nelement vertex " << points.size()
      << "\nproperty double x\nproperty double y\nproperty double z\n";
  if (!colors.empty()) out << "property uchar red\nproperty uchar green\nproperty uchar blue\n";
  out << "end_header\n";
  for (size_t i = 0; i < points.size(); ++i) {
    out << points[i].x() << ' ' << points[i].y() << ' ' << points[i].z();
    if (!colors.empty()) out << ' ' << int(colors[i][0]) << ' ' << int(colors[i][1]) << ' ' << int(colors[i][2]);
    out << '\n';
  }
  closeOut(ply_path, out);
}

}  // namespace io
}  // namespace exocet_stereo
