// Mesh export: every format is written and RELOADED by an independent test-local parser (PLY, OBJ/MTL, VRML
// IndexedFaceSet); counts, coordinates, faces, texture coordinates and the texture image must round-trip.
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <gtest/gtest.h>
#include <Eigen/LU>
#include <opencv2/imgcodecs.hpp>

#include "exocet_common/testing/temp_dir.h"
#include "exocet_stereo/io/mesh_export.h"
#include "exocet_stereo/mesh/image_mesher.h"

namespace fs = std::filesystem;
namespace mesh = exocet_stereo::mesh;
namespace xio = exocet_stereo::io;
using exocet_stereo::geometry::PinholeView;

namespace {

constexpr int kWidth = 160;
constexpr int kHeight = 120;

/// Fresh empty folder under the temp dir, removed at the end of the test.
using TempDir = exocet_common::testing::TempDir;

/// Sphere-cap mesh (analytic depth) with a random colour texture.
mesh::TexturedMesh makeMesh() {
  PinholeView view;
  view.K << 200, 0, 80, 0, 200, 60, 0, 0, 1;
  view.t = Eigen::Vector3d(0.2, 0.1, 0.3);
  const Eigen::Vector3d centre(0, 0, 3);
  cv::Mat depth(kHeight, kWidth, CV_64F);
  for (int y = 0; y < kHeight; ++y) {
    for (int x = 0; x < kWidth; ++x) {
      const Eigen::Vector3d r = view.K.inverse() * Eigen::Vector3d(x, y, 1);
      const double b = -2 * r.dot(centre), c = centre.squaredNorm() - 1.0, disc = b * b - 4 * r.squaredNorm() * c;
      depth.at<double>(y, x) = disc < 0 ? NAN : (-b - std::sqrt(disc)) / (2 * r.squaredNorm());
    }
  }
  cv::Mat image(kHeight, kWidth, CV_8UC3);
  cv::randu(image, 0, 255);
  mesh::ImageMesherConfig config;
  config.grid_step_px = 5;
  return mesh::meshFromDepth(depth, view, image, config);
}

std::string slurp(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// ---------------- Test-local PLY parser (ASCII; vertex x y z [red green blue], face lists) ----------------
struct Ply {
  std::vector<Eigen::Vector3d> vertices;
  std::vector<cv::Vec3b> colors;
  std::vector<std::vector<int>> faces;
  std::vector<std::vector<double>> face_texcoords;
  std::string texture_file;
};

Ply readPly(const std::string& path) {
  std::ifstream in(path);
  Ply ply;
  std::string line, element;
  size_t n_vertices = 0, n_faces = 0;
  std::vector<std::string> vertex_props, face_lists;
  std::getline(in, line);
  EXPECT_EQ(line, "ply");
  while (std::getline(in, line) && line != "end_header") {
    std::istringstream s(line);
    std::string word;
    s >> word;
    if (word == "format") {
      std::string format;
      s >> format;
      EXPECT_EQ(format, "ascii");
    } else if (word == "comment") {
      std::string key;
      s >> key;
      if (key == "TextureFile") s >> ply.texture_file;
    } else if (word == "element") {
      s >> element;
      (element == "vertex" ? n_vertices : n_faces) = 0;
      s >> (element == "vertex" ? n_vertices : n_faces);
    } else if (word == "property") {
      std::string type, a, b, name;
      s >> type;
      if (type == "list") {
        s >> a >> b >> name;
        face_lists.push_back(name);
      } else {
        s >> name;
        vertex_props.push_back(name);
      }
    }
  }
  EXPECT_EQ(line, "end_header");
  for (size_t i = 0; i < n_vertices; ++i) {
    std::vector<double> values(vertex_props.size());
    for (double& v : values) in >> v;
    ply.vertices.emplace_back(values[0], values[1], values[2]);
    if (vertex_props.size() == 6) ply.colors.emplace_back(values[3], values[4], values[5]);
  }
  for (size_t i = 0; i < n_faces; ++i) {
    for (size_t l = 0; l < face_lists.size(); ++l) {
      int count = 0;
      in >> count;
      if (face_lists[l] == "vertex_indices") {
        std::vector<int> face(count);
        for (int& v : face) in >> v;
        ply.faces.push_back(face);
      } else {
        std::vector<double> tc(count);
        for (double& v : tc) in >> v;
        ply.face_texcoords.push_back(tc);
      }
    }
  }
  EXPECT_TRUE(static_cast<bool>(in)) << "truncated PLY " << path;
  return ply;
}

// ---------------- Test-local OBJ + MTL parser ----------------
struct Obj {
  std::vector<Eigen::Vector3d> vertices;
  std::vector<Eigen::Vector2d> tex;
  std::vector<std::vector<std::pair<int, int>>> faces;  // (v, vt) 0-based, vt -1 if absent
  std::string mtllib, usemtl;
};

Obj readObj(const std::string& path) {
  std::ifstream in(path);
  Obj obj;
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream s(line);
    std::string tag;
    s >> tag;
    if (tag == "v") {
      Eigen::Vector3d v;
      s >> v.x() >> v.y() >> v.z();
      obj.vertices.push_back(v);
    } else if (tag == "vt") {
      Eigen::Vector2d t;
      s >> t.x() >> t.y();
      obj.tex.push_back(t);
    } else if (tag == "f") {
      std::vector<std::pair<int, int>> face;
      std::string corner;
      while (s >> corner) {
        const size_t slash = corner.find('/');
        const int v = std::stoi(corner.substr(0, slash)) - 1;
        const int vt = slash == std::string::npos ? -1 : std::stoi(corner.substr(slash + 1)) - 1;
        face.emplace_back(v, vt);
      }
      obj.faces.push_back(face);
    } else if (tag == "mtllib") {
      s >> obj.mtllib;
    } else if (tag == "usemtl") {
      s >> obj.usemtl;
    }
  }
  return obj;
}

/// map_Kd of material `name` in an MTL file, empty if none.
std::string mtlMapKd(const std::string& path, const std::string& name) {
  std::ifstream in(path);
  std::string line, current, map;
  while (std::getline(in, line)) {
    std::istringstream s(line);
    std::string tag;
    s >> tag;
    if (tag == "newmtl") s >> current;
    if (tag == "map_Kd" && current == name) s >> map;
  }
  return map;
}

// ---------------- Test-local VRML IndexedFaceSet reader ----------------
/// Numbers of the first "[ ... ]" array after `key` (commas are separators), empty if the key is missing.
std::vector<double> vrmlArray(const std::string& text, const std::string& key) {
  const size_t at = text.find(key);
  if (at == std::string::npos) return {};
  const size_t open = text.find('[', at), close = text.find(']', open);
  std::string inside = text.substr(open + 1, close - open - 1);
  for (char& c : inside) {
    if (c == ',') c = ' ';
  }
  std::istringstream s(inside);
  std::vector<double> values;
  double v;
  while (s >> v) values.push_back(v);
  return values;
}

std::string vrmlUrl(const std::string& text) {
  const size_t at = text.find("ImageTexture");
  if (at == std::string::npos) return "";
  const size_t q1 = text.find('"', text.find("url", at)), q2 = text.find('"', q1 + 1);
  return text.substr(q1 + 1, q2 - q1 - 1);
}

void expectTexture(const std::string& path, const cv::Mat& expected) {
  ASSERT_TRUE(fs::exists(path)) << path;
  const cv::Mat loaded = cv::imread(path, cv::IMREAD_UNCHANGED);
  ASSERT_EQ(loaded.size(), expected.size());
  EXPECT_EQ(cv::norm(loaded, expected, cv::NORM_INF), 0.0);  // PNG is lossless
}

double maxVertexError(const std::vector<Eigen::Vector3d>& a, const std::vector<Eigen::Vector3d>& b) {
  double e = 0;
  for (size_t i = 0; i < a.size() && i < b.size(); ++i) e = std::max(e, (a[i] - b[i]).cwiseAbs().maxCoeff());
  return e;
}

}  // namespace

TEST(MeshExport, VrmlRoundTrip) {
  const mesh::TexturedMesh m = makeMesh();
  ASSERT_GT(m.triangles.size(), 500u);
  TempDir dir;
  const std::string png = xio::writeVrml(dir.file("cap.wrl"), m);
  EXPECT_EQ(png, dir.file("cap.png"));
  const std::string text = slurp(dir.file("cap.wrl"));
  EXPECT_EQ(text.rfind("#VRML V2.0 utf8", 0), 0u);
  EXPECT_EQ(vrmlUrl(text), "cap.png");
  expectTexture(dir.file(vrmlUrl(text)), m.texture);

  const std::vector<double> coords = vrmlArray(text, "coord Coordinate");
  const std::vector<double> index = vrmlArray(text, "coordIndex");
  const std::vector<double> tex = vrmlArray(text, "texCoord TextureCoordinate");
  const std::vector<double> tex_index = vrmlArray(text, "texCoordIndex");
  ASSERT_EQ(coords.size(), 3 * m.vertices.size());
  ASSERT_EQ(index.size(), 4 * m.triangles.size());
  ASSERT_EQ(tex.size(), 2 * m.vertices.size());
  EXPECT_EQ(tex_index, index);
  double e_xyz = 0, e_uv = 0;
  for (size_t i = 0; i < m.vertices.size(); ++i) {
    e_xyz = std::max(
        e_xyz,
        (Eigen::Vector3d(coords[3 * i], coords[3 * i + 1], coords[3 * i + 2]) - m.vertices[i]).cwiseAbs().maxCoeff());
    e_uv = std::max(e_uv, std::abs(tex[2 * i] - m.tex_coords[i].x()));
    e_uv = std::max(e_uv, std::abs(tex[2 * i + 1] - (1.0 - m.tex_coords[i].y())));  // VRML origin bottom-left
  }
  EXPECT_LT(e_xyz, 1e-12);
  EXPECT_LT(e_uv, 1e-9);
  for (size_t t = 0; t < m.triangles.size(); ++t) {
    for (int k = 0; k < 3; ++k) ASSERT_EQ(index[4 * t + k], m.triangles[t][k]);
    ASSERT_EQ(index[4 * t + 3], -1);
  }
}

TEST(MeshExport, PlyRoundTrip) {
  const mesh::TexturedMesh m = makeMesh();
  TempDir dir;
  xio::writePly(dir.file("cap.ply"), m);
  const Ply ply = readPly(dir.file("cap.ply"));
  ASSERT_EQ(ply.vertices.size(), m.vertices.size());
  ASSERT_EQ(ply.faces.size(), m.triangles.size());
  EXPECT_LT(maxVertexError(ply.vertices, m.vertices), 1e-12);
  EXPECT_EQ(ply.colors, m.colors);
  for (size_t t = 0; t < m.triangles.size(); ++t) {
    ASSERT_EQ(ply.faces[t], std::vector<int>({m.triangles[t][0], m.triangles[t][1], m.triangles[t][2]}));
  }
  ASSERT_EQ(ply.face_texcoords.size(), m.triangles.size());
  EXPECT_NEAR(ply.face_texcoords[0][0], m.tex_coords[m.triangles[0][0]].x(), 1e-6);  // float texcoord property
  EXPECT_EQ(ply.texture_file, "cap.png");
  expectTexture(dir.file("cap.png"), m.texture);
}

TEST(MeshExport, ObjMtlRoundTrip) {
  const mesh::TexturedMesh m = makeMesh();
  TempDir dir;
  xio::writeObj(dir.file("cap.obj"), m);
  const Obj obj = readObj(dir.file("cap.obj"));
  ASSERT_EQ(obj.vertices.size(), m.vertices.size());
  ASSERT_EQ(obj.tex.size(), m.vertices.size());
  ASSERT_EQ(obj.faces.size(), m.triangles.size());
  EXPECT_LT(maxVertexError(obj.vertices, m.vertices), 1e-12);
  double e_uv = 0;
  for (size_t i = 0; i < obj.tex.size(); ++i) {
    e_uv = std::max(e_uv, (obj.tex[i] - Eigen::Vector2d(m.tex_coords[i].x(), 1.0 - m.tex_coords[i].y())).norm());
  }
  EXPECT_LT(e_uv, 1e-9);
  for (size_t t = 0; t < m.triangles.size(); ++t) {
    ASSERT_EQ(obj.faces[t].size(), 3u);
    for (int k = 0; k < 3; ++k) {
      ASSERT_EQ(obj.faces[t][k].first, m.triangles[t][k]);
      ASSERT_EQ(obj.faces[t][k].second, m.triangles[t][k]);
    }
  }
  EXPECT_EQ(obj.mtllib, "cap.mtl");
  const std::string map = mtlMapKd(dir.file(obj.mtllib), obj.usemtl);
  EXPECT_EQ(map, "cap.png");
  expectTexture(dir.file(map), m.texture);
}

TEST(MeshExport, TextureFromPathAndUntexturedMesh) {
  mesh::TexturedMesh m = makeMesh();
  TempDir dir;
  ASSERT_TRUE(cv::imwrite(dir.file("source.png"), m.texture));
  const cv::Mat texture = m.texture.clone();
  m.texture = cv::Mat();
  m.texture_path = dir.file("source.png");
  const std::string png = xio::writeObj(dir.file("from_path.obj"), m);
  EXPECT_EQ(png, dir.file("from_path.png"));
  expectTexture(png, texture);

  m.texture_path = dir.file("missing.png");
  EXPECT_THROW(xio::writeObj(dir.file("bad.obj"), m), std::runtime_error);

  m.texture_path.clear();
  m.tex_coords.clear();
  EXPECT_EQ(xio::writeObj(dir.file("plain.obj"), m), "");
  const Obj obj = readObj(dir.file("plain.obj"));
  EXPECT_TRUE(obj.tex.empty());
  ASSERT_EQ(obj.faces.size(), m.triangles.size());
  EXPECT_EQ(obj.faces[0][0].second, -1);
  EXPECT_EQ(mtlMapKd(dir.file("plain.mtl"), obj.usemtl), "");
  EXPECT_EQ(xio::writeVrml(dir.file("plain.wrl"), m), "");
  const std::string text = slurp(dir.file("plain.wrl"));
  EXPECT_EQ(text.find("ImageTexture"), std::string::npos);
  EXPECT_EQ(vrmlArray(text, "coordIndex").size(), 4 * m.triangles.size());
  EXPECT_EQ(vrmlArray(text, "color Color").size(), 3 * m.vertices.size());
  EXPECT_FALSE(fs::exists(dir.file("plain.png")));
}

TEST(MeshExport, PointCloudPlyRoundTrip) {
  const mesh::TexturedMesh m = makeMesh();
  TempDir dir;
  xio::writePointCloudPly(dir.file("cloud.ply"), m.vertices, m.colors);
  const Ply ply = readPly(dir.file("cloud.ply"));
  ASSERT_EQ(ply.vertices.size(), m.vertices.size());
  EXPECT_LT(maxVertexError(ply.vertices, m.vertices), 1e-12);
  EXPECT_EQ(ply.colors, m.colors);
  EXPECT_TRUE(ply.faces.empty());
  xio::writePointCloudPly(dir.file("plain.ply"), m.vertices);
  EXPECT_TRUE(readPly(dir.file("plain.ply")).colors.empty());
  EXPECT_THROW(xio::writePointCloudPly(dir.file("x.ply"), {}), std::invalid_argument);
  EXPECT_THROW(xio::writePointCloudPly(dir.file("x.ply"), m.vertices, {cv::Vec3b(1, 2, 3)}), std::invalid_argument);
}

TEST(MeshExport, ClearErrors) {
  const mesh::TexturedMesh m = makeMesh();
  const std::string missing = "/nonexistent_exocet_folder/sub/cap";
  for (const std::string ext : {".wrl", ".ply", ".obj"}) {
    try {
      if (ext == ".wrl") xio::writeVrml(missing + ext, m);
      if (ext == ".ply") xio::writePly(missing + ext, m);
      if (ext == ".obj") xio::writeObj(missing + ext, m);
      ADD_FAILURE() << "no error for " << ext;
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find("does not exist"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("/nonexistent_exocet_folder/sub"), std::string::npos) << e.what();
    }
  }
  EXPECT_THROW(xio::writePointCloudPly(missing + ".ply", m.vertices), std::runtime_error);

  TempDir dir;
  mesh::TexturedMesh empty;
  try {
    xio::writeVrml(dir.file("empty.wrl"), empty);
    ADD_FAILURE() << "no error for an empty mesh";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("empty"), std::string::npos) << e.what();
  }
  EXPECT_THROW(xio::writePly(dir.file("empty.ply"), empty), std::invalid_argument);
  EXPECT_THROW(xio::writeObj(dir.file("empty.obj"), empty), std::invalid_argument);
  mesh::TexturedMesh broken = m;
  broken.triangles[0][1] = static_cast<int>(m.vertices.size());
  EXPECT_THROW(xio::writePly(dir.file("broken.ply"), broken), std::invalid_argument);
  EXPECT_FALSE(fs::exists(dir.file("empty.wrl")));  // nothing written on a refused mesh
}
