#include "exocet_stereo/mesh/surface_texturing.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <map>
#include <sstream>
#include <stdexcept>
#include <unordered_map>
#include <utility>

#include <Eigen/Dense>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>

namespace exocet_stereo {
namespace mesh {

namespace {

constexpr float kInfF = std::numeric_limits<float>::infinity();
/// The gains are pulled towards 1 with this weight relative to the pairwise agreement: it keeps the system well posed
/// (agreement alone is scale-free) without preventing the views from agreeing.
constexpr double kGainPrior = 0.02;
constexpr double kMinGain = 0.25, kMaxGain = 4.0;
constexpr int kPaletteCellPx = 3;  // a flat colour sampled bilinearly at the centre of a 3x3 cell is exact

double cross2(const Eigen::Vector2d& a, const Eigen::Vector2d& b) { return a.x() * b.y() - a.y() * b.x(); }
double signedArea2(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& c) {
  return cross2(b - a, c - a);
}

/// Every vertex seen by one view: pixel position and depth (Z in the camera frame; <= 0 behind the camera).
struct Projection {
  std::vector<Eigen::Vector2d> px;
  std::vector<double> z;
};

Projection projectVertices(const std::vector<Eigen::Vector3d>& vertices, const TextureView& view) {
  const Eigen::Isometry3d camera_T_world = view.world_T_camera.inverse();
  Projection p;
  p.px.resize(vertices.size());
  p.z.resize(vertices.size());
  for (size_t i = 0; i < vertices.size(); ++i) {
    const Eigen::Vector3d c = camera_T_world * vertices[i];
    p.z[i] = c.z();
    const Eigen::Vector3d h = view.K * c;
    p.px[i] = c.z() > 0.0 ? Eigen::Vector2d(h.head<2>() / h.z()) : Eigen::Vector2d(-1e9, -1e9);
  }
  return p;
}

/// Nearest depth of the mesh at every pixel centre: the triangles in front of the camera rasterised with a
/// perspective-correct depth (1 / z is linear in the image).
cv::Mat zBuffer(const std::vector<Eigen::Vector3i>& triangles, const Projection& p, const cv::Size& size) {
  cv::Mat zbuf(size, CV_32FC1, cv::Scalar(kInfF));
  for (const Eigen::Vector3i& t : triangles) {
    const double za = p.z[t[0]], zb = p.z[t[1]], zc = p.z[t[2]];
    if (!(za > 1e-9 && zb > 1e-9 && zc > 1e-9)) continue;
    const Eigen::Vector2d &a = p.px[t[0]], &b = p.px[t[1]], &c = p.px[t[2]];
    const double area = signedArea2(a, b, c);
    if (std::abs(area) < 1e-12) continue;
    const int x0 = std::max(0, static_cast<int>(std::ceil(std::min({a.x(), b.x(), c.x()}))));
    const int x1 = std::min(size.width - 1, static_cast<int>(std::floor(std::max({a.x(), b.x(), c.x()}))));
    const int y0 = std::max(0, static_cast<int>(std::ceil(std::min({a.y(), b.y(), c.y()}))));
    const int y1 = std::min(size.height - 1, static_cast<int>(std::floor(std::max({a.y(), b.y(), c.y()}))));
    for (int y = y0; y <= y1; ++y) {
      float* row = zbuf.ptr<float>(y);
      for (int x = x0; x <= x1; ++x) {
        const Eigen::Vector2d q(x, y);
        const double wa = signedArea2(q, b, c) / area, wb = signedArea2(a, q, c) / area, wc = 1.0 - wa - wb;
        if (wa < -1e-9 || wb < -1e-9 || wc < -1e-9) continue;
        const float depth = static_cast<float>(1.0 / (wa / za + wb / zb + wc / zc));
        if (depth < row[x]) row[x] = depth;
      }
    }
  }
  return zbuf;
}

/// Bilinear sample of an 8-bit image (1 or 3 channels) at pixel-centre coordinates, clamped to the border; BGR order.
cv::Vec3d sampleBilinear(const cv::Mat& image, double x, double y) {
  x = std::clamp(x, 0.0, image.cols - 1.0);
  y = std::clamp(y, 0.0, image.rows - 1.0);
  const int x0 = std::min(static_cast<int>(x), image.cols - 2 < 0 ? 0 : image.cols - 2);
  const int y0 = std::min(static_cast<int>(y), image.rows - 2 < 0 ? 0 : image.rows - 2);
  const int x1 = std::min(x0 + 1, image.cols - 1), y1 = std::min(y0 + 1, image.rows - 1);
  const double fx = x - x0, fy = y - y0;
  const auto at = [&image](int yy, int xx) {
    if (image.channels() == 3) {
      const cv::Vec3b v = image.at<cv::Vec3b>(yy, xx);
      return cv::Vec3d(v[0], v[1], v[2]);
    }
    const double g = image.at<uchar>(yy, xx);
    return cv::Vec3d(g, g, g);
  };
  return (1 - fy) * ((1 - fx) * at(y0, x0) + fx * at(y0, x1)) + fy * ((1 - fx) * at(y1, x0) + fx * at(y1, x1));
}

double intensity(const cv::Vec3d& bgr) { return (bgr[0] + bgr[1] + bgr[2]) / 3.0; }

void checkInputs(const TexturedMesh& surface, const std::vector<TextureView>& views,
                 const SurfaceTexturingConfig& config) {
  const std::string problems = config.validate();
  if (!problems.empty()) throw std::invalid_argument("SurfaceTexturingConfig: " + problems);
  if (surface.empty())
    throw std::invalid_argument("textureSurface: the surface is empty (" + std::to_string(surface.vertices.size()) +
                                " vertices, " + std::to_string(surface.triangles.size()) + " triangles)");
  const std::string bad = surface.validate();
  if (!bad.empty()) throw std::invalid_argument("textureSurface: inconsistent surface: " + bad);
  if (views.empty()) throw std::invalid_argument("textureSurface: no view to take the texture from");
  for (size_t v = 0; v < views.size(); ++v) {
    const TextureView& view = views[v];
    const std::string name = "textureSurface: view " + std::to_string(v);
    if (view.image.empty() || view.image.depth() != CV_8U || (view.image.channels() != 1 && view.image.channels() != 3))
      throw std::invalid_argument(name + ": image must be a non-empty CV_8UC1 or CV_8UC3 (BGR)");
    const double det = view.K.determinant();
    if (!view.K.allFinite() || !(std::abs(det) > 1e-12))
      throw std::invalid_argument(name + ": K is not an invertible intrinsic matrix");
    if (!view.world_T_camera.matrix().allFinite()) throw std::invalid_argument(name + ": world_T_camera is not finite");
  }
}

/// Pairs of triangles sharing an edge (every pair along a non-manifold edge), as adjacency lists (CSR).
void triangleAdjacency(const std::vector<Eigen::Vector3i>& triangles, std::vector<int>* offsets,
                       std::vector<int>* neighbours) {
  std::unordered_map<uint64_t, int> first_of_edge;
  first_of_edge.reserve(triangles.size() * 2);
  std::vector<std::pair<int, int>> pairs;
  pairs.reserve(triangles.size() * 3 / 2);
  for (size_t t = 0; t < triangles.size(); ++t) {
    for (int k = 0; k < 3; ++k) {
      const uint32_t a = triangles[t][k], b = triangles[t][(k + 1) % 3];
      const uint64_t key = (static_cast<uint64_t>(std::min(a, b)) << 32) | std::max(a, b);
      const auto it = first_of_edge.emplace(key, static_cast<int>(t));
      if (!it.second) pairs.emplace_back(it.first->second, static_cast<int>(t));
    }
  }
  offsets->assign(triangles.size() + 1, 0);
  for (const auto& p : pairs) {
    ++(*offsets)[p.first + 1];
    ++(*offsets)[p.second + 1];
  }
  for (size_t t = 0; t < triangles.size(); ++t) (*offsets)[t + 1] += (*offsets)[t];
  neighbours->resize(offsets->back());
  std::vector<int> fill(offsets->begin(), offsets->end() - 1);
  for (const auto& p : pairs) {
    (*neighbours)[fill[p.first]++] = p.second;
    (*neighbours)[fill[p.second]++] = p.first;
  }
}

/// One gain per used view: least squares agreement of the views' mean intensities over the vertices each pair sees,
/// with a weak pull towards 1; then scaled so that the median gain over the textured triangles is 1 (the level of
/// the majority of the texture is kept: one darker view is brought up rather than every other one down).
std::vector<double> viewGains(const TexturedMesh& surface, const std::vector<TextureView>& views,
                              const std::vector<Projection>& projections, const std::vector<int>& candidate_offsets,
                              const std::vector<int>& candidate_views, const std::vector<int>& used,
                              const std::vector<long>& triangles_per_view) {
  const int n_views = static_cast<int>(views.size());
  std::vector<int> compact(n_views, -1);
  for (size_t k = 0; k < used.size(); ++k) compact[used[k]] = static_cast<int>(k);
  // The used views that see each vertex (through any triangle around it).
  std::vector<std::vector<int>> seen_by(surface.vertices.size());
  for (size_t t = 0; t < surface.triangles.size(); ++t) {
    for (int c = candidate_offsets[t]; c < candidate_offsets[t + 1]; ++c) {
      if (compact[candidate_views[c]] < 0) continue;
      for (int k = 0; k < 3; ++k) seen_by[surface.triangles[t][k]].push_back(candidate_views[c]);
    }
  }
  const int m = static_cast<int>(used.size());
  std::vector<double> sum_first(m * m, 0.0), sum_second(m * m, 0.0), count(m * m, 0.0);
  std::vector<double> level(n_views, 0.0);
  for (size_t i = 0; i < seen_by.size(); ++i) {
    std::vector<int>& s = seen_by[i];
    if (s.size() < 2) continue;
    std::sort(s.begin(), s.end());
    s.erase(std::unique(s.begin(), s.end()), s.end());
    for (size_t k = 0; k < s.size(); ++k) {
      const Eigen::Vector2d& p = projections[s[k]].px[i];
      level[s[k]] = intensity(sampleBilinear(views[s[k]].image, p.x(), p.y()));
    }
    for (size_t a = 0; a < s.size(); ++a) {
      for (size_t b = a + 1; b < s.size(); ++b) {
        const int cell = compact[s[a]] * m + compact[s[b]];
        sum_first[cell] += level[s[a]];
        sum_second[cell] += level[s[b]];
        count[cell] += 1.0;
      }
    }
  }
  double total = 0.0, total_count = 0.0;
  for (int c = 0; c < m * m; ++c) {
    total += sum_first[c] + sum_second[c];
    total_count += 2.0 * count[c];
  }
  std::vector<double> gains(n_views, 1.0);
  if (total_count == 0.0 || total <= 0.0) return gains;
  const double scale = total_count / total;  // normalised intensities are about 1
  Eigen::MatrixXd normal = Eigen::MatrixXd::Zero(m, m);
  Eigen::VectorXd rhs = Eigen::VectorXd::Zero(m);
  std::vector<double> involvement(m, 0.0);
  for (int a = 0; a < m; ++a) {
    for (int b = a + 1; b < m; ++b) {
      const double n = count[a * m + b];
      if (n < 3.0) continue;
      const double mu_a = sum_first[a * m + b] / n * scale, mu_b = sum_second[a * m + b] / n * scale;
      // Residual g_a mu_a - g_b mu_b, weight n.
      normal(a, a) += n * mu_a * mu_a;
      normal(b, b) += n * mu_b * mu_b;
      normal(a, b) -= n * mu_a * mu_b;
      normal(b, a) -= n * mu_a * mu_b;
      involvement[a] += n;
      involvement[b] += n;
    }
  }
  for (int a = 0; a < m; ++a) {
    const double w = kGainPrior * std::max(1.0, involvement[a]);
    normal(a, a) += w;
    rhs(a) += w;
  }
  const Eigen::VectorXd g = normal.ldlt().solve(rhs);
  if (!g.allFinite() || g.minCoeff() <= 0.0) return gains;
  std::vector<std::pair<double, long>> weighted;
  long total_triangles = 0;
  for (int a = 0; a < m; ++a) {
    weighted.emplace_back(g(a), triangles_per_view[used[a]]);
    total_triangles += triangles_per_view[used[a]];
  }
  std::sort(weighted.begin(), weighted.end());
  double median = weighted.back().first;
  long below = 0;
  for (const auto& w : weighted) {
    below += w.second;
    if (2 * below >= total_triangles) {
      median = w.first;
      break;
    }
  }
  for (int a = 0; a < m; ++a) gains[used[a]] = std::clamp(g(a) / median, kMinGain, kMaxGain);
  return gains;
}

/// Sizes of the atlas: the used images in a grid of cells, the flat colours below in 3x3 cells.
struct AtlasLayout {
  double scale = 1.0;
  int cols = 0, rows = 0, cell_w = 0, cell_h = 0;
  int width = 0, height = 0, palette_y = 0, palette_per_row = 1;
  std::vector<cv::Size> tiles;  ///< per used view
};

AtlasLayout layoutAtlas(const std::vector<TextureView>& views, const std::vector<int>& used, size_t palette_size,
                        double scale, int max_side) {
  AtlasLayout layout;
  const int n = static_cast<int>(used.size());
  for (int attempt = 0; attempt < 8; ++attempt) {
    layout.scale = scale;
    layout.cols = n == 0 ? 0 : static_cast<int>(std::ceil(std::sqrt(static_cast<double>(n))));
    layout.rows = n == 0 ? 0 : (n + layout.cols - 1) / layout.cols;
    layout.tiles.clear();
    layout.cell_w = layout.cell_h = 0;
    for (int v : used) {
      const cv::Size tile(std::max(1, static_cast<int>(std::lround(views[v].image.cols * scale))),
                          std::max(1, static_cast<int>(std::lround(views[v].image.rows * scale))));
      layout.tiles.push_back(tile);
      layout.cell_w = std::max(layout.cell_w, tile.width);
      layout.cell_h = std::max(layout.cell_h, tile.height);
    }
    const int grid_w = layout.cols * layout.cell_w, grid_h = layout.rows * layout.cell_h;
    const int min_palette_w = static_cast<int>(std::min<size_t>(palette_size, 256)) * kPaletteCellPx;
    layout.width = std::max({grid_w, min_palette_w, 1});
    layout.palette_per_row = std::max(1, layout.width / kPaletteCellPx);
    const int palette_rows = static_cast<int>((palette_size + layout.palette_per_row - 1) / layout.palette_per_row);
    layout.palette_y = grid_h;
    layout.height = std::max(1, grid_h + palette_rows * kPaletteCellPx);
    if (layout.width <= max_side && layout.height <= max_side) break;
    const double room_h = std::max(1.0, max_side - palette_rows * kPaletteCellPx - 1.0);
    scale *= 0.99 * std::min(max_side / std::max(1.0, static_cast<double>(grid_w)),
                             room_h / std::max(1.0, static_cast<double>(grid_h)));
  }
  if (layout.width > max_side || layout.height > max_side)
    throw std::invalid_argument("textureSurface: " + std::to_string(n) + " images and " + std::to_string(palette_size) +
                                " flat colours do not fit an atlas of " + std::to_string(max_side) +
                                " px: raise max_atlas_side_px");
  return layout;
}

cv::Vec3b quantised(const cv::Vec3b& rgb) {
  // Nearest multiple of 8: few palette cells, invisible steps on a flat, untextured patch.
  const auto q = [](uchar c) { return static_cast<uchar>(std::min(255, (c + 4) / 8 * 8)); };
  return cv::Vec3b(q(rgb[0]), q(rgb[1]), q(rgb[2]));
}

}  // namespace

std::string SurfaceTexturingConfig::validate() const {
  std::vector<std::string> bad;
  if (!(max_angle_deg > 0.0 && max_angle_deg < 90.0)) bad.push_back("max_angle_deg must be in (0, 90)");
  if (!(margin_px >= 0.0 && margin_px <= 1000.0)) bad.push_back("margin_px must be in [0, 1000]");
  if (!(occlusion_tolerance > 0.0 && occlusion_tolerance <= 1.0))
    bad.push_back("occlusion_tolerance must be in (0, 1]");
  if (!(smoothing_lambda >= 0.0 && smoothing_lambda <= 100.0)) bad.push_back("smoothing_lambda must be in [0, 100]");
  if (icm_passes < 0 || icm_passes > 100) bad.push_back("icm_passes must be in [0, 100]");
  if (!(atlas_scale > 0.0 && atlas_scale <= 1.0)) bad.push_back("atlas_scale must be in (0, 1]");
  if (max_atlas_side_px < 256 || max_atlas_side_px > 32768) bad.push_back("max_atlas_side_px must be in [256, 32768]");
  std::ostringstream s;
  for (size_t i = 0; i < bad.size(); ++i) s << (i ? "; " : "") << bad[i];
  return s.str();
}

TexturedMesh textureSurface(const TexturedMesh& surface, const std::vector<TextureView>& views,
                            const SurfaceTexturingConfig& config, SurfaceTexturingStats* stats,
                            std::vector<int>* triangle_views) {
  checkInputs(surface, views, config);
  const auto& vertices = surface.vertices;
  const auto& triangles = surface.triangles;
  const int n_views = static_cast<int>(views.size());
  const size_t n_triangles = triangles.size();

  std::vector<Eigen::Vector3d> centroids(n_triangles), normals(n_triangles);
  for (size_t t = 0; t < n_triangles; ++t) {
    const Eigen::Vector3d &a = vertices[triangles[t][0]], &b = vertices[triangles[t][1]],
                          &c = vertices[triangles[t][2]];
    centroids[t] = (a + b + c) / 3.0;
    const Eigen::Vector3d n = (b - a).cross(c - a);
    normals[t] = n.norm() > 0.0 ? Eigen::Vector3d(n.normalized()) : Eigen::Vector3d::Zero();
  }

  // Candidate views of every triangle, and their score (projected area, px^2; 0 = not a candidate). The views are
  // independent: one per thread.
  std::vector<Projection> projections(n_views);
  std::vector<std::vector<float>> scores(n_views);
  const double cos_max = std::cos(config.max_angle_deg * M_PI / 180.0);
  cv::parallel_for_(cv::Range(0, n_views), [&](const cv::Range& range) {
    for (int v = range.start; v < range.end; ++v) {
      const TextureView& view = views[v];
      const Projection& p = projections[v] = projectVertices(vertices, view);
      const cv::Size size = view.image.size();
      const cv::Mat zbuf = config.check_occlusion ? zBuffer(triangles, p, size) : cv::Mat();
      const Eigen::Isometry3d camera_T_world = view.world_T_camera.inverse();
      const Eigen::Vector3d centre = view.world_T_camera.translation();
      const double x_max = size.width - 1.0 - config.margin_px, y_max = size.height - 1.0 - config.margin_px;
      std::vector<float>& score = scores[v];
      score.assign(n_triangles, 0.0f);
      for (size_t t = 0; t < n_triangles; ++t) {
        bool inside = true;
        for (int k = 0; k < 3 && inside; ++k) {
          const int i = triangles[t][k];
          const Eigen::Vector2d& q = p.px[i];
          inside = p.z[i] > 0.0 && q.x() >= config.margin_px && q.x() <= x_max && q.y() >= config.margin_px &&
                   q.y() <= y_max;
        }
        if (!inside) continue;
        if (!(normals[t].dot((centre - centroids[t]).normalized()) > cos_max)) continue;
        if (config.check_occlusion) {
          const Eigen::Vector3d c = camera_T_world * centroids[t];
          const Eigen::Vector3d h = view.K * c;
          const int x = std::clamp(static_cast<int>(std::lround(h.x() / h.z())), 0, size.width - 1);
          const int y = std::clamp(static_cast<int>(std::lround(h.y() / h.z())), 0, size.height - 1);
          // Nothing rasterised there (a sliver between pixel centres) hides nothing.
          if (c.z() > zbuf.at<float>(y, x) * (1.0 + config.occlusion_tolerance)) continue;
        }
        const double area =
            0.5 * std::abs(signedArea2(p.px[triangles[t][0]], p.px[triangles[t][1]], p.px[triangles[t][2]]));
        score[t] = static_cast<float>(std::max(area, 1e-9));
      }
    }
  });

  // Candidates per triangle (CSR), best first guess.
  std::vector<int> offsets(n_triangles + 1, 0), candidate_views;
  std::vector<float> candidate_scores, best_score(n_triangles, 0.0f);
  std::vector<int> labels(n_triangles, -1);
  for (size_t t = 0; t < n_triangles; ++t) {
    for (int v = 0; v < n_views; ++v) {
      const float s = scores[v][t];
      if (s <= 0.0f) continue;
      candidate_views.push_back(v);
      candidate_scores.push_back(s);
      if (s > best_score[t]) {
        best_score[t] = s;
        labels[t] = v;
      }
    }
    offsets[t + 1] = static_cast<int>(candidate_views.size());
  }
  scores.clear();
  scores.shrink_to_fit();

  // Potts smoothing by iterated conditional modes: each triangle in turn takes the label of least cost given its
  // neighbours' current labels.
  std::vector<int> adjacency_offsets, adjacency;
  triangleAdjacency(triangles, &adjacency_offsets, &adjacency);
  int icm_changes = 0;
  if (config.smoothing_lambda > 0.0) {
    for (int pass = 0; pass < config.icm_passes; ++pass) {
      int changes = 0;
      for (size_t t = 0; t < n_triangles; ++t) {
        if (offsets[t + 1] - offsets[t] < 2) continue;
        const auto cost = [&](int c) {
          int other = 0;
          for (int j = adjacency_offsets[t]; j < adjacency_offsets[t + 1]; ++j)
            other += labels[adjacency[j]] != candidate_views[c] ? 1 : 0;
          return -candidate_scores[c] / best_score[t] + config.smoothing_lambda * other;
        };
        int best = -1;
        double best_cost = std::numeric_limits<double>::infinity();
        for (int c = offsets[t]; c < offsets[t + 1]; ++c) {
          const double e = cost(c);
          // Ties keep the current label: ICM must not oscillate.
          if (e < best_cost - 1e-12 || (std::abs(e - best_cost) <= 1e-12 && candidate_views[c] == labels[t])) {
            best_cost = e;
            best = c;
          }
        }
        if (candidate_views[best] != labels[t]) {
          labels[t] = candidate_views[best];
          ++changes;
        }
      }
      icm_changes += changes;
      if (changes == 0) break;
    }
  }

  SurfaceTexturingStats s;
  s.icm_changes = icm_changes;
  s.triangles_per_view.assign(n_views, 0);
  s.gains.assign(n_views, 1.0);
  for (size_t t = 0; t < n_triangles; ++t) {
    if (labels[t] >= 0) {
      ++s.triangles_per_view[labels[t]];
      ++s.textured_triangles;
    } else {
      ++s.untextured_triangles;
    }
  }
  for (size_t t = 0; t < n_triangles; ++t)
    for (int j = adjacency_offsets[t]; j < adjacency_offsets[t + 1]; ++j) {
      const int u = adjacency[j];
      if (u > static_cast<int>(t) && labels[t] >= 0 && labels[u] >= 0 && labels[t] != labels[u]) ++s.seam_edges;
    }
  std::vector<int> used;
  for (int v = 0; v < n_views; ++v)
    if (s.triangles_per_view[v] > 0) used.push_back(v);
  s.views_used = static_cast<int>(used.size());
  if (config.adjust_gains && used.size() >= 2)
    s.gains = viewGains(surface, views, projections, offsets, candidate_views, used, s.triangles_per_view);

  // Flat colours of the untextured triangles: their vertices' mean colour, or the configured grey.
  const bool vertex_colors = surface.colors.size() == vertices.size();
  std::vector<cv::Vec3b> flat_rgb(n_triangles);
  std::map<int, int> palette_index;  // packed quantised RGB -> cell
  std::vector<cv::Vec3b> palette;
  for (size_t t = 0; t < n_triangles; ++t) {
    if (labels[t] >= 0) continue;
    cv::Vec3b rgb = config.untextured_rgb;
    if (vertex_colors) {
      cv::Vec3i sum(0, 0, 0);
      for (int k = 0; k < 3; ++k) sum += cv::Vec3i(surface.colors[triangles[t][k]]);
      rgb = cv::Vec3b(sum[0] / 3, sum[1] / 3, sum[2] / 3);
    }
    flat_rgb[t] = rgb;
    const cv::Vec3b q = quantised(rgb);
    const int key = (q[0] << 16) | (q[1] << 8) | q[2];
    if (palette_index.emplace(key, static_cast<int>(palette.size())).second) palette.push_back(q);
  }

  // The atlas.
  const AtlasLayout layout = layoutAtlas(views, used, palette.size(), config.atlas_scale, config.max_atlas_side_px);
  bool colour = false;
  for (int v : used) colour = colour || views[v].image.channels() == 3;
  for (const cv::Vec3b& c : palette) colour = colour || c[0] != c[1] || c[1] != c[2];
  cv::Mat atlas(layout.height, layout.width, colour ? CV_8UC3 : CV_8UC1, cv::Scalar::all(0));
  std::vector<cv::Point> tile_origin(n_views, cv::Point(0, 0));
  std::vector<int> tile_of(n_views, -1);
  for (size_t k = 0; k < used.size(); ++k) {
    tile_of[used[k]] = static_cast<int>(k);
    const TextureView& view = views[used[k]];
    cv::Mat tile;
    if (layout.tiles[k] == view.image.size()) {
      tile = view.image;
    } else {
      cv::resize(view.image, tile, layout.tiles[k], 0.0, 0.0, cv::INTER_AREA);
    }
    if (colour && tile.channels() == 1) cv::cvtColor(tile, tile, cv::COLOR_GRAY2BGR);
    tile.convertTo(tile, -1, s.gains[used[k]]);  // saturates
    tile_origin[used[k]] =
        cv::Point(static_cast<int>(k % layout.cols) * layout.cell_w, static_cast<int>(k / layout.cols) * layout.cell_h);
    tile.copyTo(atlas(cv::Rect(tile_origin[used[k]], layout.tiles[k])));
  }
  std::vector<cv::Point> palette_centre(palette.size());
  for (size_t i = 0; i < palette.size(); ++i) {
    const cv::Point corner(static_cast<int>(i % layout.palette_per_row) * kPaletteCellPx,
                           layout.palette_y + static_cast<int>(i / layout.palette_per_row) * kPaletteCellPx);
    const cv::Vec3b& rgb = palette[i];
    const cv::Scalar value = colour ? cv::Scalar(rgb[2], rgb[1], rgb[0]) : cv::Scalar(rgb[0]);
    atlas(cv::Rect(corner, cv::Size(kPaletteCellPx, kPaletteCellPx))).setTo(value);
    palette_centre[i] = corner + cv::Point(kPaletteCellPx / 2, kPaletteCellPx / 2);
  }

  // Corners duplicated: vertex 3 t + k is corner k of triangle t.
  TexturedMesh out;
  out.vertices.reserve(3 * n_triangles);
  out.triangles.reserve(n_triangles);
  out.tex_coords.reserve(3 * n_triangles);
  out.colors.reserve(3 * n_triangles);
  const double aw = atlas.cols, ah = atlas.rows;
  for (size_t t = 0; t < n_triangles; ++t) {
    const int base = static_cast<int>(3 * t);
    out.triangles.emplace_back(base, base + 1, base + 2);
    const int v = labels[t];
    for (int k = 0; k < 3; ++k) {
      const int i = triangles[t][k];
      out.vertices.push_back(vertices[i]);
      if (v >= 0) {
        // Pixel x of the view -> atlas pixel origin + (x + 0.5) * tile / image - 0.5 (pixel-centre convention).
        const Eigen::Vector2d& q = projections[v].px[i];
        const cv::Size& tile = layout.tiles[tile_of[v]];
        const double sx = static_cast<double>(tile.width) / views[v].image.cols;
        const double sy = static_cast<double>(tile.height) / views[v].image.rows;
        const double ax = tile_origin[v].x + (q.x() + 0.5) * sx, ay = tile_origin[v].y + (q.y() + 0.5) * sy;
        out.tex_coords.emplace_back(ax / aw, ay / ah);
        const cv::Vec3d bgr = sampleBilinear(atlas, ax - 0.5, ay - 0.5);
        out.colors.emplace_back(cv::saturate_cast<uchar>(bgr[2]), cv::saturate_cast<uchar>(bgr[1]),
                                cv::saturate_cast<uchar>(bgr[0]));
      } else {
        const cv::Vec3b q = quantised(flat_rgb[t]);
        const cv::Point& centre = palette_centre[palette_index.at((q[0] << 16) | (q[1] << 8) | q[2])];
        out.tex_coords.emplace_back((centre.x + 0.5) / aw, (centre.y + 0.5) / ah);
        out.colors.push_back(vertex_colors ? surface.colors[i] : flat_rgb[t]);
      }
    }
  }
  out.texture = atlas;

  s.atlas_width_px = atlas.cols;
  s.atlas_height_px = atlas.rows;
  s.atlas_scale = layout.scale;
  if (stats) *stats = s;
  if (triangle_views) *triangle_views = labels;
  return out;
}

}  // namespace mesh
}  // namespace exocet_stereo
