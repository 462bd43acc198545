#include "exocet_stereo/mesh/cloud_surface.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <numeric>
#include <sstream>
#include <stdexcept>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include <opencv2/core/utility.hpp>

namespace exocet_stereo {
namespace mesh {

namespace {

/// Integer grid index packed in 64 bits (three 21-bit fields, +-1e6 cells per axis).
constexpr int64_t kOffset = 1 << 20;
using Index3 = Eigen::Matrix<int64_t, 3, 1>;

bool inRange(const Index3& i) { return (i.array() >= -kOffset).all() && (i.array() < kOffset).all(); }
uint64_t pack(const Index3& i) {
  return (static_cast<uint64_t>(i.x() + kOffset) << 42) | (static_cast<uint64_t>(i.y() + kOffset) << 21) |
         static_cast<uint64_t>(i.z() + kOffset);
}
Index3 cellOf(const Eigen::Vector3d& p, double cell_m) {
  return Index3(static_cast<int64_t>(std::floor(p.x() / cell_m)), static_cast<int64_t>(std::floor(p.y() / cell_m)),
                static_cast<int64_t>(std::floor(p.z() / cell_m)));
}

/// Points bucketed by cubes of edge `radius`: a query visits the 27 cubes around it.
class PointGrid {
 public:
  PointGrid(const std::vector<Eigen::Vector3d>& points, double radius) : points_(points), radius_(radius) {
    for (size_t i = 0; i < points.size(); ++i) {
      const Index3 c = cellOf(points[i], radius_);
      if (inRange(c)) buckets_[pack(c)].push_back(static_cast<int>(i));
    }
  }
  /// Calls visit(index, squared distance) for every point within the radius of x.
  template <typename Visit>
  void forNeighbours(const Eigen::Vector3d& x, Visit visit) const {
    const Index3 c = cellOf(x, radius_);
    const double r2 = radius_ * radius_;
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const Index3 n = c + Index3(dx, dy, dz);
          if (!inRange(n)) continue;
          const auto it = buckets_.find(pack(n));
          if (it == buckets_.end()) continue;
          for (int i : it->second) {
            const double d2 = (points_[i] - x).squaredNorm();
            if (d2 <= r2) visit(i, d2);
          }
        }
  }

 private:
  const std::vector<Eigen::Vector3d>& points_;
  double radius_;
  std::unordered_map<uint64_t, std::vector<int>> buckets_;
};

struct PairHash {
  size_t operator()(const std::pair<uint64_t, uint64_t>& p) const {
    return std::hash<uint64_t>()(p.first * 0x9E3779B97F4A7C15ull ^ (p.second + 0x7F4A7C159E3779B9ull));
  }
};

/// Union-find over vertices, to find the connected pieces of the mesh.
class DisjointSets {
 public:
  explicit DisjointSets(size_t n) : parent_(n) { std::iota(parent_.begin(), parent_.end(), 0); }
  int find(int i) {
    while (parent_[i] != i) i = parent_[i] = parent_[parent_[i]];
    return i;
  }
  void unite(int a, int b) { parent_[find(a)] = find(b); }

 private:
  std::vector<int> parent_;
};

// Cube corner c = dx + 2 dy + 4 dz. The six tetrahedra of the Kuhn split all share the diagonal 0-7: each is a path
// 0 -> 7 changing one axis at a time, so every cube splits its faces the same way and neighbours match.
constexpr int kTetrahedra[6][4] = {{0, 1, 3, 7}, {0, 2, 3, 7}, {0, 2, 6, 7}, {0, 4, 6, 7}, {0, 4, 5, 7}, {0, 1, 5, 7}};

}  // namespace

std::string CloudSurfaceConfig::validate() const {
  std::vector<std::string> bad;
  if (!(cell_m > 0.0 && cell_m <= 1e3)) bad.push_back("cell_m must be in (0, 1e3]");
  if (!(radius_m >= cell_m && radius_m <= 100.0 * cell_m)) bad.push_back("radius_m must be in [cell_m, 100 cell_m]");
  if (min_neighbours < 1 || min_neighbours > 10000) bad.push_back("min_neighbours must be in [1, 10000]");
  if (min_component_triangles < 0 || min_component_triangles > 1000000000)
    bad.push_back("min_component_triangles must be in [0, 1e9]");
  std::ostringstream s;
  for (size_t i = 0; i < bad.size(); ++i) s << (i ? "; " : "") << bad[i];
  return s.str();
}

TexturedMesh surfaceFromCloud(const FusedCloud& cloud, const CloudSurfaceConfig& config, CloudSurfaceStats* stats) {
  const std::string problems = config.validate();
  if (!problems.empty()) throw std::invalid_argument("CloudSurfaceConfig: " + problems);
  if (cloud.normals.size() != cloud.points.size())
    throw std::invalid_argument("surfaceFromCloud: " + std::to_string(cloud.normals.size()) + " normals for " +
                                std::to_string(cloud.points.size()) + " points (one unit normal per point needed)");
  if (!cloud.colors.empty() && cloud.colors.size() != cloud.points.size())
    throw std::invalid_argument("surfaceFromCloud: colours must be empty or one per point");
  CloudSurfaceStats total;
  TexturedMesh mesh;
  if (cloud.points.empty()) {
    if (stats) *stats = total;
    return mesh;
  }
  const double cell = config.cell_m;
  const PointGrid grid(cloud.points, config.radius_m);
  const double inv_sigma2 = 4.0 / (config.radius_m * config.radius_m);  // sigma = radius / 2

  // Cells around the points (each point's cell and its 26 neighbours): the zero level lies within them.
  std::unordered_set<uint64_t> cell_set;
  std::vector<Index3> cells;
  for (const Eigen::Vector3d& p : cloud.points) {
    const Index3 c = cellOf(p, cell);
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const Index3 n = c + Index3(dx, dy, dz);
          if (inRange(n) && inRange(n + Index3(1, 1, 1)) && cell_set.insert(pack(n)).second) cells.push_back(n);
        }
  }
  std::sort(cells.begin(), cells.end(), [](const Index3& a, const Index3& b) { return pack(a) < pack(b); });
  // Their corner nodes, each evaluated once.
  std::unordered_map<uint64_t, int> node_index;
  std::vector<Index3> nodes;
  for (const Index3& c : cells)
    for (int k = 0; k < 8; ++k) {
      const Index3 n = c + Index3(k & 1, (k >> 1) & 1, (k >> 2) & 1);
      if (node_index.emplace(pack(n), static_cast<int>(nodes.size())).second) nodes.push_back(n);
    }
  std::vector<double> value(nodes.size(), NAN);
  cv::parallel_for_(cv::Range(0, static_cast<int>(nodes.size())), [&](const cv::Range& range) {
    for (int i = range.start; i < range.end; ++i) {
      const Eigen::Vector3d x = nodes[i].cast<double>() * cell;
      double sum_w = 0.0, sum_wf = 0.0;
      int count = 0;
      grid.forNeighbours(x, [&](int j, double d2) {
        const double w = std::exp(-d2 * inv_sigma2);
        sum_w += w;
        sum_wf += w * cloud.normals[j].dot(x - cloud.points[j]);
        ++count;
      });
      if (count >= config.min_neighbours && sum_w > 0.0) value[i] = sum_wf / sum_w;
    }
  });
  total.nodes = static_cast<long>(nodes.size());
  for (double v : value) total.defined_nodes += std::isfinite(v) ? 1 : 0;

  // Marching tetrahedra. A vertex lies on a grid edge whose ends differ in sign; it is shared through the edge key.
  std::unordered_map<std::pair<uint64_t, uint64_t>, int, PairHash> edge_vertex;
  std::vector<Eigen::Vector3i> triangles;
  auto vertexOnEdge = [&](int a, int b) {
    const uint64_t ka = pack(nodes[a]), kb = pack(nodes[b]);
    const auto key = ka < kb ? std::make_pair(ka, kb) : std::make_pair(kb, ka);
    const auto it = edge_vertex.find(key);
    if (it != edge_vertex.end()) return it->second;
    const double fa = value[a], fb = value[b];
    const double t = fa / (fa - fb);
    const Eigen::Vector3d pa = nodes[a].cast<double>() * cell, pb = nodes[b].cast<double>() * cell;
    const int index = static_cast<int>(mesh.vertices.size());
    mesh.vertices.push_back(pa + t * (pb - pa));
    edge_vertex.emplace(key, index);
    return index;
  };
  for (const Index3& c : cells) {
    std::array<int, 8> corner;
    bool defined = true;
    for (int k = 0; k < 8 && defined; ++k) {
      corner[k] = node_index.at(pack(c + Index3(k & 1, (k >> 1) & 1, (k >> 2) & 1)));
      defined = std::isfinite(value[corner[k]]);
    }
    if (!defined) continue;
    for (const auto& tet : kTetrahedra) {
      std::vector<int> outside, inside;  // f >= 0: the side the normals point to
      for (int k : tet) (value[corner[k]] >= 0.0 ? outside : inside).push_back(corner[k]);
      if (outside.empty() || inside.empty()) continue;
      std::vector<int> polygon;
      if (outside.size() == 1 || inside.size() == 1) {
        const int lone = outside.size() == 1 ? outside[0] : inside[0];
        const std::vector<int>& others = outside.size() == 1 ? inside : outside;
        for (int o : others) polygon.push_back(vertexOnEdge(lone, o));
      } else {  // two and two: a quad, edges in cyclic order
        polygon = {vertexOnEdge(outside[0], inside[0]), vertexOnEdge(outside[0], inside[1]),
                   vertexOnEdge(outside[1], inside[1]), vertexOnEdge(outside[1], inside[0])};
      }
      // Orientation: the triangle's normal must point from the inside nodes to the outside ones.
      Eigen::Vector3d towards_outside = Eigen::Vector3d::Zero();
      for (int o : outside) towards_outside += nodes[o].cast<double>() / outside.size();
      for (int i : inside) towards_outside -= nodes[i].cast<double>() / inside.size();
      for (size_t k = 1; k + 1 < polygon.size(); ++k) {
        Eigen::Vector3i tri(polygon[0], polygon[k], polygon[k + 1]);
        const Eigen::Vector3d& a = mesh.vertices[tri[0]];
        const Eigen::Vector3d n = (mesh.vertices[tri[1]] - a).cross(mesh.vertices[tri[2]] - a);
        if (!(n.norm() > 1e-12 * cell * cell)) continue;  // degenerate (a node exactly on the level)
        if (n.dot(towards_outside) < 0.0) std::swap(tri[1], tri[2]);
        triangles.push_back(tri);
      }
    }
  }

  // Drop small connected pieces (specks of noise), then the vertices no triangle uses.
  DisjointSets sets(mesh.vertices.size());
  for (const auto& t : triangles) {
    sets.unite(t[0], t[1]);
    sets.unite(t[1], t[2]);
  }
  std::unordered_map<int, int> piece_size;
  for (const auto& t : triangles) ++piece_size[sets.find(t[0])];
  std::vector<int> remap(mesh.vertices.size(), -1);
  std::vector<Eigen::Vector3d> used;
  for (const auto& t : triangles) {
    if (piece_size[sets.find(t[0])] < config.min_component_triangles) {
      ++total.removed_triangles;
      continue;
    }
    Eigen::Vector3i kept;
    for (int k = 0; k < 3; ++k) {
      if (remap[t[k]] < 0) {
        remap[t[k]] = static_cast<int>(used.size());
        used.push_back(mesh.vertices[t[k]]);
      }
      kept[k] = remap[t[k]];
    }
    mesh.triangles.push_back(kept);
  }
  mesh.vertices = std::move(used);
  total.triangles = static_cast<long>(mesh.triangles.size());

  if (!cloud.colors.empty()) {
    mesh.colors.resize(mesh.vertices.size());
    cv::parallel_for_(cv::Range(0, static_cast<int>(mesh.vertices.size())), [&](const cv::Range& range) {
      for (int i = range.start; i < range.end; ++i) {
        Eigen::Vector3d sum = Eigen::Vector3d::Zero();
        double sum_w = 0.0;
        grid.forNeighbours(mesh.vertices[i], [&](int j, double d2) {
          const double w = std::exp(-d2 * inv_sigma2);
          sum += w * Eigen::Vector3d(cloud.colors[j][0], cloud.colors[j][1], cloud.colors[j][2]);
          sum_w += w;
        });
        if (sum_w > 0.0) sum /= sum_w;
        mesh.colors[i] = cv::Vec3b(cv::saturate_cast<uint8_t>(sum.x()), cv::saturate_cast<uint8_t>(sum.y()),
                                   cv::saturate_cast<uint8_t>(sum.z()));
      }
    });
  }
  if (stats) *stats = total;
  return mesh;
}

}  // namespace mesh
}  // namespace exocet_stereo
