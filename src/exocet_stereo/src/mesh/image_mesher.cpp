#include "exocet_stereo/mesh/image_mesher.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <sstream>
#include <stdexcept>
#include <utility>

#include <Eigen/Geometry>
#include <opencv2/imgproc.hpp>

namespace exocet_stereo {
namespace mesh {

std::string ImageMesherConfig::validate() const {
  std::ostringstream out;
  const char* sep = "";
  if (grid_step_px < 1 || grid_step_px > 256) {
    out << sep << "grid_step_px = " << grid_step_px << " must be in [1, 256]";
    sep = "; ";
  }
  if (!(max_edge_depth_ratio > 0.0 && max_edge_depth_ratio <= 100.0)) {
    out << sep << "max_edge_depth_ratio = " << max_edge_depth_ratio << " must be in (0, 100]";
    sep = "; ";
  }
  if (!(max_edge_length_ratio == 0.0 || (max_edge_length_ratio >= 1.0 && max_edge_length_ratio <= 1e6))) {
    out << sep << "max_edge_length_ratio = " << max_edge_length_ratio << " must be 0 (off) or in [1, 1e6]";
    sep = "; ";
  }
  if (!(min_area_px2 >= 0.0 && min_area_px2 <= 1e6)) {
    out << sep << "min_area_px2 = " << min_area_px2 << " must be in [0, 1e6]";
  }
  return out.str();
}

namespace {

constexpr int kSubdivMarginFactor = 50;

/// The mesh plus, for each of its vertices, the index of the input point it came from.
struct MeshWithSources {
  TexturedMesh mesh;
  std::vector<int> source;
};

MeshWithSources buildMesh(const std::vector<Eigen::Vector2d>& pixels, const std::vector<Eigen::Vector3d>& points,
                          const geometry::PinholeView& view, const cv::Size& image_size,
                          const ImageMesherConfig& config, MeshingStats* stats_out) {
  if (pixels.size() != points.size()) {
    throw std::invalid_argument("image mesher: " + std::to_string(pixels.size()) + " pixels but " +
                                std::to_string(points.size()) + " points (one point per pixel expected)");
  }
  if (image_size.width <= 0 || image_size.height <= 0) {
    throw std::invalid_argument("image mesher: image size must be positive");
  }
  const std::string bad = config.validate();
  if (!bad.empty()) throw std::invalid_argument("image mesher config: " + bad);

  MeshingStats stats;
  stats.input_points = static_cast<int>(pixels.size());

  // Usable points: finite, in front of the camera, one per (float) pixel: Subdiv2D merges duplicates anyway, and the
  // float key is how its triangle list (coordinates only) is mapped back to our indices.
  std::map<std::pair<float, float>, int> index_of;
  float min_x = 0.f, min_y = 0.f, max_x = static_cast<float>(image_size.width),
        max_y = static_cast<float>(image_size.height);
  std::vector<int> used;
  for (size_t i = 0; i < pixels.size(); ++i) {
    if (!pixels[i].allFinite() || !points[i].allFinite() || view.depth(points[i]) <= 0.0) continue;
    const std::pair<float, float> key(static_cast<float>(pixels[i].x()), static_cast<float>(pixels[i].y()));
    if (!index_of.emplace(key, static_cast<int>(i)).second) continue;
    used.push_back(static_cast<int>(i));
    min_x = std::min(min_x, key.first);
    min_y = std::min(min_y, key.second);
    max_x = std::max(max_x, key.first);
    max_y = std::max(max_y, key.second);
  }
  stats.used_points = static_cast<int>(used.size());

  MeshWithSources result;
  if (used.size() >= 3) {
    // Subdiv2D starts from a super-triangle whose corners lie about 3 rect sizes away; near-collinear hull points
    // then form triangles with those virtual corners instead of with each other, and thin hull triangles go missing.
    // A rect much larger than the points pushes the corners far enough for the true Delaunay hull (still exact in
    // float for images up to ~10^4 px).
    const int extent = static_cast<int>(std::ceil(std::max(max_x - min_x, max_y - min_y))) + 4;
    const int margin = kSubdivMarginFactor * extent;
    const cv::Rect rect(static_cast<int>(std::floor(min_x)) - margin, static_cast<int>(std::floor(min_y)) - margin,
                        extent + 2 * margin, extent + 2 * margin);
    cv::Subdiv2D subdiv(rect);
    for (int i : used) subdiv.insert(cv::Point2f(static_cast<float>(pixels[i].x()), static_cast<float>(pixels[i].y())));
    std::vector<cv::Vec6f> triangle_list;
    subdiv.getTriangleList(triangle_list);

    const Eigen::Vector3d centre = view.centre();
    std::vector<int> new_index(points.size(), -1);
    for (const cv::Vec6f& t : triangle_list) {
      int idx[3];
      bool known = true;
      for (int k = 0; k < 3; ++k) {
        const auto it = index_of.find({t[2 * k], t[2 * k + 1]});
        if (it == index_of.end()) {
          known = false;  // a virtual outer vertex of Subdiv2D
          break;
        }
        idx[k] = it->second;
      }
      if (!known) continue;
      ++stats.delaunay_triangles;

      const Eigen::Vector2d &a2 = pixels[idx[0]], &b2 = pixels[idx[1]], &c2 = pixels[idx[2]];
      const double area_px2 = 0.5 * std::abs((b2 - a2).x() * (c2 - a2).y() - (b2 - a2).y() * (c2 - a2).x());
      const Eigen::Vector3d &a = points[idx[0]], &b = points[idx[1]], &c = points[idx[2]];
      const double e0 = (b - a).norm(), e1 = (c - b).norm(), e2 = (a - c).norm();
      const double e_max = std::max({e0, e1, e2}), e_min = std::min({e0, e1, e2});
      Eigen::Vector3d normal = (b - a).cross(c - a);
      // Null 3D area relative to the edge scale: collinear or coincident 3D points.
      if (area_px2 < config.min_area_px2 || e_min <= 0.0 || normal.norm() <= 1e-12 * e_max * e_max) {
        ++stats.removed_degenerate;
        continue;
      }
      const double mean_depth = (view.depth(a) + view.depth(b) + view.depth(c)) / 3.0;
      if (e_max > config.max_edge_depth_ratio * mean_depth ||
          (config.max_edge_length_ratio > 0.0 && e_max > config.max_edge_length_ratio * e_min)) {
        ++stats.removed_discontinuity;
        continue;
      }
      if (normal.dot(centre - a) < 0.0) std::swap(idx[1], idx[2]);  // face the reference camera
      Eigen::Vector3i tri;
      for (int k = 0; k < 3; ++k) {
        if (new_index[idx[k]] < 0) {
          new_index[idx[k]] = static_cast<int>(result.source.size());
          result.source.push_back(idx[k]);
        }
        tri[k] = new_index[idx[k]];
      }
      result.mesh.triangles.push_back(tri);
    }
    // Renumber in input order (stable, readable files); first-use order was only for the single pass above.
    std::vector<int> order(result.source.size());
    for (size_t k = 0; k < order.size(); ++k) order[k] = static_cast<int>(k);
    std::sort(order.begin(), order.end(), [&](int l, int r) { return result.source[l] < result.source[r]; });
    std::vector<int> rank(order.size());
    std::vector<int> sorted_source(order.size());
    for (size_t k = 0; k < order.size(); ++k) {
      rank[order[k]] = static_cast<int>(k);
      sorted_source[k] = result.source[order[k]];
    }
    result.source = sorted_source;
    for (Eigen::Vector3i& tri : result.mesh.triangles) {
      for (int k = 0; k < 3; ++k) tri[k] = rank[tri[k]];
    }
  }
  stats.triangles = static_cast<int>(result.mesh.triangles.size());

  const double w = image_size.width, h = image_size.height;
  for (int i : result.source) {
    result.mesh.vertices.push_back(points[i]);
    // Pixel centres: pixel x covers [x - 0.5, x + 0.5], so the image spans u in [0, 1] exactly.
    result.mesh.tex_coords.emplace_back(std::clamp((pixels[i].x() + 0.5) / w, 0.0, 1.0),
                                        std::clamp((pixels[i].y() + 0.5) / h, 0.0, 1.0));
  }
  if (stats_out) *stats_out = stats;
  return result;
}

}  // namespace

TexturedMesh meshFromPoints(const std::vector<Eigen::Vector2d>& pixels, const std::vector<Eigen::Vector3d>& points,
                            const geometry::PinholeView& view, const cv::Size& image_size,
                            const ImageMesherConfig& config, MeshingStats* stats) {
  return buildMesh(pixels, points, view, image_size, config, stats).mesh;
}

TexturedMesh meshFromDepth(const cv::Mat& depth_m, const geometry::PinholeView& view, const cv::Mat& image,
                           const ImageMesherConfig& config, MeshingStats* stats) {
  const std::string bad = config.validate();
  if (!bad.empty()) throw std::invalid_argument("image mesher config: " + bad);
  const PointCloud cloud = backProjectDepth(depth_m, view, image, config.grid_step_px);
  MeshWithSources result = buildMesh(cloud.pixels, cloud.points, view, depth_m.size(), config, stats);
  if (!image.empty()) {
    result.mesh.texture = image;
    for (int i : result.source) result.mesh.colors.push_back(cloud.colors[i]);
  }
  return std::move(result.mesh);
}

TexturedMesh meshFromDisparity(const cv::Mat& disparity_px, const RectifiedPairGeometry& pair,
                               const geometry::PinholeView& view, const cv::Mat& image, const ImageMesherConfig& config,
                               MeshingStats* stats) {
  return meshFromDepth(depthFromDisparity(disparity_px, pair), view, image, config, stats);
}

}  // namespace mesh
}  // namespace exocet_stereo
