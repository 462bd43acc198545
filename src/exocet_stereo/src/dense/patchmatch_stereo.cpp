// PatchMatch Stereo with slanted support windows (Bleyer, Rhemann & Rother, BMVC 2011); see patchmatch_stereo.h.
#include "exocet_stereo/dense/patchmatch_stereo.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "exocet_stereo/dense/post_processing.h"

namespace exocet_stereo {
namespace dense {
namespace {

constexpr int kFeatures = 5;  // B, G, R, d/dx grey, d/dy grey

/// One view's precomputed data: 8-bit colour (for the support weights) and float colour + gradients (for the cost).
struct View {
  int rows = 0, cols = 0;
  std::vector<uint8_t> color;   // 3 per pixel
  std::vector<float> features;  // kFeatures per pixel
};

View makeView(const cv::Mat& image) {
  cv::Mat bgr;
  if (image.channels() == 1)
    cv::cvtColor(image, bgr, cv::COLOR_GRAY2BGR);  // grey counts three times so that tau_col keeps its meaning
  else
    bgr = image;
  cv::Mat gray, gray_f, gx, gy;
  cv::cvtColor(bgr, gray, cv::COLOR_BGR2GRAY);
  gray.convertTo(gray_f, CV_32F);
  // Central differences (half of [-1 0 1]), so tau_grad is in grey levels per pixel.
  cv::Sobel(gray_f, gx, CV_32F, 1, 0, 1, 0.5, 0.0, cv::BORDER_REPLICATE);
  cv::Sobel(gray_f, gy, CV_32F, 0, 1, 1, 0.5, 0.0, cv::BORDER_REPLICATE);
  View view;
  view.rows = image.rows;
  view.cols = image.cols;
  view.color.resize(static_cast<size_t>(view.rows) * view.cols * 3);
  view.features.resize(static_cast<size_t>(view.rows) * view.cols * kFeatures);
  for (int y = 0; y < view.rows; ++y) {
    const uint8_t* row = bgr.ptr<uint8_t>(y);
    for (int x = 0; x < view.cols; ++x) {
      const size_t i = static_cast<size_t>(y) * view.cols + x;
      float* f = &view.features[i * kFeatures];
      for (int c = 0; c < 3; ++c) {
        view.color[i * 3 + c] = row[3 * x + c];
        f[c] = row[3 * x + c];
      }
      f[3] = gx.at<float>(y, x);
      f[4] = gy.at<float>(y, x);
    }
  }
  return view;
}

struct Plane {
  float a = 0.0f, b = 0.0f, c = 0.0f;
  float at(float x, float y) const { return a * x + b * y + c; }
};

/// Plane through disparity z at (x, y) with unit normal n (nz > 0) in (x, y, d) space.
Plane planeFromPointNormal(float x, float y, float z, float nx, float ny, float nz) {
  Plane p;
  p.a = -nx / nz;
  p.b = -ny / nz;
  p.c = z - p.a * x - p.b * y;
  return p;
}

// Post-processing: regions of fewer pixels than this, whose planes no neighbour continues within the tolerance, are
// isolated wrong planes (removeSmallPlaneRegions()). The result is flat over 8-20 px and 0.5-0.8 px on the four
// Middlebury scenes. A plain disparity-difference speckle filter would break steep slanted surfaces into speckles.
constexpr int kMinPlaneRegionPx = 12;
constexpr double kPlaneRegionTolerancePx = 0.7;

// Post-processing: a mismatched pixel that the right view does not decide takes the higher (foreground) of its two
// neighbouring planes only if that one costs this much less; nearer ties go to the background, as in the paper. The
// ratio trades Tsukuba against Venus and Teddy; it is chosen on the four Middlebury scenes (docs/benchmarks.md).
constexpr double kForegroundCostRatio = 0.97;

// Planes steeper than this (|n_z| below) are never proposed: they would map one pixel onto many in the other view.
constexpr float kMinNormalZ = 0.1f;

/// Counter-based random numbers: a pure function of (seed, view, iteration, pixel), so threads do not change results.
class PixelRng {
 public:
  PixelRng(int seed, int view, int iteration, int x, int y) {
    state_ = mix(static_cast<uint64_t>(static_cast<uint32_t>(seed)) * 0x9E3779B97F4A7C15ULL ^
                 (static_cast<uint64_t>(view) << 56) ^ (static_cast<uint64_t>(iteration) << 48) ^
                 (static_cast<uint64_t>(y) << 24) ^ static_cast<uint64_t>(x));
  }
  /// Uniform in [lo, hi).
  float uniform(float lo, float hi) {
    state_ += 0x9E3779B97F4A7C15ULL;
    const double u = static_cast<double>(mix(state_) >> 11) * (1.0 / 9007199254740992.0);
    return static_cast<float>(lo + (hi - lo) * u);
  }

 private:
  static uint64_t mix(uint64_t z) {  // splitmix64 finaliser
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    return z ^ (z >> 31);
  }
  uint64_t state_;
};

/// A window pixel q of the current centre: position, support weight and q's features in the centre's view.
struct Sample {
  float x, y, w;
  int row_offset;  // y * cols, index of row y in the other view
  const float* f;  // q's features in the centre's view
};

/// Optimisation state and cost of one view against the other.
class ViewSolver {
 public:
  ViewSolver(const DenseStereoConfig& config, const View& self, const View& other, int view_index)
      : config_(config), self_(self), other_(other), view_index_(view_index), sign_(view_index == 0 ? 1.0f : -1.0f) {
    weight_table_.resize(3 * 255 + 1);
    for (size_t i = 0; i < weight_table_.size(); ++i)
      weight_table_[i] = static_cast<float>(std::exp(-static_cast<double>(i) / config.pm_gamma));
    alpha_ = static_cast<float>(config.pm_alpha);
    tau_color_ = static_cast<float>(config.pm_tau_color);
    tau_gradient_ = static_cast<float>(config.pm_tau_gradient);
    max_disparity_ = static_cast<float>(config.max_disparity_px);
    planes_.resize(static_cast<size_t>(self.rows) * self.cols);
    costs_.assign(planes_.size(), std::numeric_limits<float>::infinity());
  }

  int rows() const { return self_.rows; }
  int cols() const { return self_.cols; }
  /// x in the other view = x - sign * d (left view: +1, right view: -1).
  float sign() const { return sign_; }
  const std::vector<Plane>& planes() const { return planes_; }

  /// Full window cost of `plane` at (x, y) (the optimisation's cost, without early exit).
  float planeCost(int x, int y, const Plane& plane) const {
    thread_local std::vector<Sample> window;
    gatherWindow(x, y, &window);
    return cost(window, plane, std::numeric_limits<float>::infinity());
  }

  /// Random plane per pixel and its cost (rows are independent).
  void initialise() {
    cv::parallel_for_(cv::Range(0, rows()), [this](const cv::Range& range) {
      std::vector<Sample> window;
      for (int y = range.start; y < range.end; ++y)
        for (int x = 0; x < cols(); ++x) {
          PixelRng rng(config_.pm_seed, view_index_, -1, x, y);
          const float z = rng.uniform(0.0f, max_disparity_);
          float nx, ny, nz, norm;
          do {  // uniform unit normal on the front hemisphere, not too steep
            nx = rng.uniform(-1.0f, 1.0f), ny = rng.uniform(-1.0f, 1.0f), nz = rng.uniform(0.0f, 1.0f);
            norm = std::sqrt(nx * nx + ny * ny + nz * nz);
          } while (norm > 1.0f || norm < 1e-3f || nz / norm < kMinNormalZ);
          const size_t i = index(x, y);
          planes_[i] =
              planeFromPointNormal(static_cast<float>(x), static_cast<float>(y), z, nx / norm, ny / norm, nz / norm);
          gatherWindow(x, y, &window);
          costs_[i] = cost(window, planes_[i], std::numeric_limits<float>::infinity());
        }
    });
  }

  /**
   * @brief View propagation: every plane of `source` (the other view) is converted to this view and tried at the pixel
   *        it matches. Targets stay in the source pixel's row, so rows are independent.
   */
  void propagateFrom(const ViewSolver& source) {
    const float source_sign = source.sign();
    cv::parallel_for_(cv::Range(0, rows()), [this, &source, source_sign](const cv::Range& range) {
      std::vector<Sample> window;
      for (int y = range.start; y < range.end; ++y)
        for (int x = 0; x < cols(); ++x) {
          const Plane& p = source.planes()[index(x, y)];
          const float d = p.at(static_cast<float>(x), static_cast<float>(y));
          const int target = static_cast<int>(std::lround(x - source_sign * d));
          if (target < 0 || target >= cols()) continue;
          // Source d = a x_s + b y + c with x_s = x_t + s d gives d = (a x_t + b y + c) / (1 - s a).
          const float denominator = 1.0f - source_sign * p.a;
          if (denominator < kMinNormalZ) continue;
          const Plane converted{p.a / denominator, p.b / denominator, p.c / denominator};
          gatherWindow(target, y, &window);
          tryPlane(window, target, y, converted);
        }
    });
  }

  /**
   * @brief One sequential scan (forward: neighbours left and above; backward: right and below) with spatial
   *        propagation and plane refinement, run as anti-diagonal wavefronts (same result as the raster scan).
   */
  void scan(bool forward, int iteration) {
    const int diagonals = rows() + cols() - 1;
    for (int step = 0; step < diagonals; ++step) {
      const int k = forward ? step : diagonals - 1 - step;
      const int x_begin = std::max(0, k - rows() + 1), x_end = std::min(cols() - 1, k);
      const int count = x_end - x_begin + 1;
      cv::parallel_for_(
          cv::Range(0, count),
          [&](const cv::Range& range) {
            thread_local std::vector<Sample> window;
            for (int i = range.start; i < range.end; ++i)
              visit(x_begin + i, k - x_begin - i, forward, iteration, &window);
          },
          std::max(1.0, count / 16.0));
    }
  }

 private:
  size_t index(int x, int y) const { return static_cast<size_t>(y) * cols() + x; }

  void visit(int x, int y, bool forward, int iteration, std::vector<Sample>* window) {
    gatherWindow(x, y, window);
    const int step = forward ? -1 : 1;  // neighbours already visited in this scan
    if (x + step >= 0 && x + step < cols()) tryPlane(*window, x, y, planes_[index(x + step, y)]);
    if (y + step >= 0 && y + step < rows()) tryPlane(*window, x, y, planes_[index(x, y + step)]);
    // Refinement: perturb disparity and normal, halving both ranges until the disparity range is below 0.1 px.
    PixelRng rng(config_.pm_seed, view_index_, iteration, x, y);
    const float fx = static_cast<float>(x), fy = static_cast<float>(y);
    float dz = 0.5f * max_disparity_, dn = 1.0f;
    for (; dz >= 0.1f; dz *= 0.5f, dn *= 0.5f) {
      const Plane& current = planes_[index(x, y)];
      const float z = current.at(fx, fy) + rng.uniform(-dz, dz);
      const float inverse = 1.0f / std::sqrt(current.a * current.a + current.b * current.b + 1.0f);
      float nx = -current.a * inverse + rng.uniform(-dn, dn);
      float ny = -current.b * inverse + rng.uniform(-dn, dn);
      float nz = inverse + rng.uniform(-dn, dn);
      const float norm = std::sqrt(nx * nx + ny * ny + nz * nz);
      if (norm < 1e-6f || nz / norm < kMinNormalZ) continue;
      tryPlane(*window, x, y, planeFromPointNormal(fx, fy, z, nx / norm, ny / norm, nz / norm));
    }
  }

  /// Adopt `plane` at (x, y) if its disparity there is in range and its cost beats the current one.
  void tryPlane(const std::vector<Sample>& window, int x, int y, const Plane& plane) {
    const size_t i = index(x, y);
    const Plane& current = planes_[i];
    if (plane.a == current.a && plane.b == current.b && plane.c == current.c) return;  // common once converged
    const float d = plane.at(static_cast<float>(x), static_cast<float>(y));
    if (!(d >= 0.0f && d <= max_disparity_)) return;
    const float c = cost(window, plane, costs_[i]);
    if (c < costs_[i]) {
      costs_[i] = c;
      planes_[i] = plane;
    }
  }

  /**
   * @brief Window pixels of (x, y) with their support weight (skipping those below pm_min_weight), ordered by
   *        decreasing weight (bucket sort on the colour distance) so that the early exit of cost() comes sooner.
   */
  void gatherWindow(int x, int y, std::vector<Sample>* window) const {
    struct Kept {
      int q;         // pixel index
      int distance;  // L1 colour distance to the centre
    };
    thread_local std::vector<Kept> kept;
    constexpr int kBucketShift = 2;
    constexpr int kBuckets = (3 * 255 >> kBucketShift) + 1;
    kept.clear();
    const int radius = config_.pm_window_radius_px, step = config_.pm_window_step_px;
    const float min_weight = static_cast<float>(config_.pm_min_weight);
    const uint8_t* centre = &self_.color[index(x, y) * 3];
    int start[kBuckets + 1] = {0};
    for (int qy = std::max(0, y - radius); qy <= std::min(rows() - 1, y + radius); qy += step) {
      // Start on the window's grid (x - radius + k step) inside the image, so step > 1 keeps the centre column.
      int qx = x - radius;
      if (qx < 0) qx += ((-qx + step - 1) / step) * step;
      const int qx_end = std::min(cols() - 1, x + radius);
      for (; qx <= qx_end; qx += step) {
        const int q = qy * cols() + qx;
        const uint8_t* color = &self_.color[static_cast<size_t>(q) * 3];
        const int distance =
            std::abs(color[0] - centre[0]) + std::abs(color[1] - centre[1]) + std::abs(color[2] - centre[2]);
        if (weight_table_[distance] < min_weight) continue;
        kept.push_back({q, distance});
        ++start[(distance >> kBucketShift) + 1];
      }
    }
    for (int b = 0; b < kBuckets; ++b) start[b + 1] += start[b];
    window->resize(kept.size());
    for (const Kept& k : kept) {
      Sample& s = (*window)[start[k.distance >> kBucketShift]++];
      const int qy = k.q / cols(), qx = k.q - qy * cols();
      s.x = static_cast<float>(qx);
      s.y = static_cast<float>(qy);
      s.w = weight_table_[k.distance];
      s.row_offset = qy * other_.cols;
      s.f = &self_.features[static_cast<size_t>(k.q) * kFeatures];
    }
  }

  /// Weighted window cost of `plane`; stops early (returning a value >= bound) once the sum reaches `bound`.
  float cost(const std::vector<Sample>& window, const Plane& plane, float bound) const {
    const float last_x = static_cast<float>(other_.cols - 1);
    const float* features = other_.features.data();
    const float one_minus_alpha = 1.0f - alpha_;
    float total = 0.0f;
    for (const Sample& s : window) {
      // A window pixel matched outside the other image compares with its border column (clamped) rather than paying
      // the maximal cost: that penalty would favour any plane keeping the window inside, and pixels near the left
      // border would lose their true plane.
      const float xo = std::min(std::max(s.x - sign_ * plane.at(s.x, s.y), 0.0f), last_x);
      int i0 = static_cast<int>(xo);
      if (i0 >= other_.cols - 1) i0 = other_.cols - 2;
      const float t = xo - static_cast<float>(i0);
      const float* f0 = features + static_cast<size_t>(s.row_offset + i0) * kFeatures;
      const float* f1 = f0 + kFeatures;
      float color = 0.0f;
      for (int k = 0; k < 3; ++k) color += std::fabs(f0[k] + t * (f1[k] - f0[k]) - s.f[k]);
      const float gradient =
          std::fabs(f0[3] + t * (f1[3] - f0[3]) - s.f[3]) + std::fabs(f0[4] + t * (f1[4] - f0[4]) - s.f[4]);
      const float c = one_minus_alpha * std::min(color, tau_color_) + alpha_ * std::min(gradient, tau_gradient_);
      total += s.w * c;
      if (total >= bound) return total;
    }
    return total;
  }

  const DenseStereoConfig& config_;
  const View& self_;
  const View& other_;
  const int view_index_;
  const float sign_;
  std::vector<float> weight_table_;
  float alpha_, tau_color_, tau_gradient_, max_disparity_;
  std::vector<Plane> planes_;
  std::vector<float> costs_;
};

cv::Mat toPlaneMat(const std::vector<Plane>& planes, int rows, int cols) {
  cv::Mat out(rows, cols, CV_32FC3);
  for (int y = 0; y < rows; ++y) {
    cv::Vec3f* row = out.ptr<cv::Vec3f>(y);
    for (int x = 0; x < cols; ++x) {
      const Plane& p = planes[static_cast<size_t>(y) * cols + x];
      row[x] = cv::Vec3f(p.a, p.b, p.c);
    }
  }
  return out;
}

}  // namespace

cv::Mat planeDisparity(const cv::Mat& planes) {
  if (planes.type() != CV_32FC3) throw std::invalid_argument("planeDisparity: planes must be CV_32FC3 (a, b, c)");
  cv::Mat out(planes.size(), CV_32F);
  for (int y = 0; y < planes.rows; ++y) {
    const cv::Vec3f* p = planes.ptr<cv::Vec3f>(y);
    float* d = out.ptr<float>(y);
    for (int x = 0; x < planes.cols; ++x) d[x] = p[x][0] * x + p[x][1] * y + p[x][2];
  }
  return out;
}

cv::Mat fillHolesFromPlanes(const cv::Mat& disparity, const cv::Mat& planes, double max_disparity_px) {
  return fillHolesFromPlanes(disparity, planes, max_disparity_px, cv::Mat(), PlaneCost(), nullptr);
}

cv::Mat fillHolesFromPlanes(const cv::Mat& disparity, const cv::Mat& planes, double max_disparity_px,
                            const cv::Mat& classes, const PlaneCost& cost, cv::Mat* median_holes,
                            const cv::Mat& disparity_right, double foreground_cost_ratio) {
  if (disparity.type() != CV_32F || planes.type() != CV_32FC3 || disparity.size() != planes.size())
    throw std::invalid_argument("fillHolesFromPlanes: need a CV_32F disparity and CV_32FC3 planes of the same size");
  if (!classes.empty() && (classes.type() != CV_8U || classes.size() != disparity.size()))
    throw std::invalid_argument("fillHolesFromPlanes: classes must be empty or a CV_8U map of the disparity's size");
  if (!disparity_right.empty() && (disparity_right.type() != CV_32F || disparity_right.rows != disparity.rows))
    throw std::invalid_argument("fillHolesFromPlanes: disparity_right must be empty or CV_32F with as many rows");
  if (!(foreground_cost_ratio > 0.0 && foreground_cost_ratio <= 1.0))
    throw std::invalid_argument("fillHolesFromPlanes: foreground_cost_ratio must be in (0, 1]");
  // The right view confirms a left disparity d at x when its own disparity at x - d is within this of d.
  constexpr float kConfirmTolerancePx = 1.0f;
  const auto confirmed = [&disparity_right](int x, int y, float d) {
    const int xr = static_cast<int>(std::lround(x - d));
    if (xr < 0 || xr >= disparity_right.cols) return false;
    return std::fabs(disparity_right.ptr<float>(y)[xr] - d) <= kConfirmTolerancePx;  // false for NaN
  };
  const float ratio = static_cast<float>(foreground_cost_ratio);
  cv::Mat out = disparity.clone();
  cv::Mat holes(disparity.size(), CV_8U, cv::Scalar(0));
  const float max_d = static_cast<float>(max_disparity_px);
  std::vector<int> previous_valid(disparity.cols);
  for (int y = 0; y < disparity.rows; ++y) {
    const float* d = disparity.ptr<float>(y);
    const cv::Vec3f* p = planes.ptr<cv::Vec3f>(y);
    const uint8_t* pixel_class = classes.empty() ? nullptr : classes.ptr<uint8_t>(y);
    float* o = out.ptr<float>(y);
    uint8_t* hole = holes.ptr<uint8_t>(y);
    int last = -1;
    for (int x = 0; x < disparity.cols; ++x) {
      if (std::isfinite(d[x])) last = x;
      previous_valid[x] = last;
    }
    int next = -1;
    for (int x = disparity.cols - 1; x >= 0; --x) {
      if (std::isfinite(d[x])) {
        next = x;
        continue;
      }
      hole[x] = 255;
      const int sources[2] = {previous_valid[x], next};
      float values[2] = {std::numeric_limits<float>::infinity(), std::numeric_limits<float>::infinity()};
      for (int k = 0; k < 2; ++k)
        if (sources[k] >= 0) {
          const cv::Vec3f& plane = p[sources[k]];
          values[k] = std::clamp(plane[0] * x + plane[1] * y + plane[2], 0.0f, max_d);
        }
      const float lower = std::min(values[0], values[1]);  // occluded pixels belong to the background
      float value = lower;
      if (pixel_class && pixel_class[x] == kPixelMismatch && cost && sources[0] >= 0 && sources[1] >= 0 &&
          values[0] != values[1]) {
        // Visible in both views: its own surface may be the foreground. The right view decides if it confirms one
        // of the two; else the cost, with near ties to the background (a textureless background beside a textured
        // edge costs about as much under the foreground's plane: Venus' fattened sheet edges).
        const int high = values[1] > values[0] ? 1 : 0, low = 1 - high;
        const bool high_confirmed = !disparity_right.empty() && confirmed(x, y, values[high]);
        const bool low_confirmed = !disparity_right.empty() && confirmed(x, y, values[low]);
        if (high_confirmed != low_confirmed)
          value = high_confirmed ? values[high] : values[low];
        else
          value = cost(x, y, p[sources[high]]) < ratio * cost(x, y, p[sources[low]]) ? values[high] : values[low];
        if (value > lower) hole[x] = 0;  // the foreground was chosen: the weighted median must not undo it
      }
      if (std::isfinite(value)) o[x] = value;
    }
  }
  if (median_holes) *median_holes = holes;
  return fillHoles(out);  // rows without any valid pixel
}

int removeSmallPlaneRegions(cv::Mat* disparity, const cv::Mat& planes, int min_region_px, double tolerance_px) {
  if (!disparity || disparity->type() != CV_32F || planes.type() != CV_32FC3 || disparity->size() != planes.size())
    throw std::invalid_argument("removeSmallPlaneRegions: need a CV_32F disparity and CV_32FC3 planes of one size");
  const int rows = disparity->rows, cols = disparity->cols;
  const float tolerance = static_cast<float>(tolerance_px);
  auto at = [](const cv::Vec3f& plane, int x, int y) { return plane[0] * x + plane[1] * y + plane[2]; };
  std::vector<uint8_t> visited(static_cast<size_t>(rows) * cols, 0);
  std::vector<int> stack, region;
  int removed = 0;
  for (int start = 0; start < rows * cols; ++start) {
    if (visited[start] || !std::isfinite(disparity->ptr<float>(start / cols)[start % cols])) continue;
    visited[start] = 1;
    stack.assign(1, start);
    region.clear();
    while (!stack.empty()) {  // flood fill over plane-continuous 4-neighbours
      const int i = stack.back();
      stack.pop_back();
      region.push_back(i);
      const int y = i / cols, x = i - y * cols;
      const cv::Vec3f& plane = planes.at<cv::Vec3f>(y, x);
      const int neighbours[4][2] = {{x + 1, y}, {x - 1, y}, {x, y + 1}, {x, y - 1}};
      for (const auto& n : neighbours) {
        const int u = n[0], v = n[1], j = v * cols + u;
        if (u < 0 || v < 0 || u >= cols || v >= rows || visited[j] || !std::isfinite(disparity->at<float>(v, u)))
          continue;
        const cv::Vec3f& other = planes.at<cv::Vec3f>(v, u);
        if (std::fabs(at(plane, u, v) - at(other, u, v)) > tolerance ||
            std::fabs(at(other, x, y) - at(plane, x, y)) > tolerance)
          continue;
        visited[j] = 1;
        stack.push_back(j);
      }
    }
    if (static_cast<int>(region.size()) >= min_region_px) continue;
    for (int i : region) disparity->ptr<float>(i / cols)[i % cols] = std::numeric_limits<float>::quiet_NaN();
    removed += static_cast<int>(region.size());
  }
  return removed;
}

PlaneMaps PatchMatchStereo::computePlanes(const cv::Mat& left, const cv::Mat& right) const {
  const std::string error = checkImages(left, right);
  if (!error.empty()) throw std::invalid_argument(name() + ": " + error);
  const View left_view = makeView(left), right_view = makeView(right);
  ViewSolver solver_left(config_, left_view, right_view, 0), solver_right(config_, right_view, left_view, 1);
  solver_left.initialise();
  solver_right.initialise();
  for (int iteration = 0; iteration < config_.pm_iterations; ++iteration) {
    const bool forward = iteration % 2 == 0;  // alternate the scan order (and so the propagation direction)
    if (iteration > 0) solver_left.propagateFrom(solver_right);
    solver_left.scan(forward, iteration);
    solver_right.propagateFrom(solver_left);
    solver_right.scan(forward, iteration);
  }
  return {toPlaneMat(solver_left.planes(), left.rows, left.cols),
          toPlaneMat(solver_right.planes(), right.rows, right.cols)};
}

void PatchMatchStereo::computeRaw(const cv::Mat& left, const cv::Mat& right, cv::Mat* disparity_left,
                                  cv::Mat* disparity_right) const {
  const PlaneMaps planes = computePlanes(left, right);
  *disparity_left = planeDisparity(planes.left);
  if (disparity_right) *disparity_right = planeDisparity(planes.right);
}

cv::Mat PatchMatchStereo::compute(const cv::Mat& left, const cv::Mat& right) const {
  return postProcess(left, right, computePlanes(left, right));
}

cv::Mat PatchMatchStereo::postProcess(const cv::Mat& left, const cv::Mat& right, const PlaneMaps& planes) const {
  const std::string error = checkImages(left, right);
  if (!error.empty()) throw std::invalid_argument(name() + ": " + error);
  if (planes.left.size() != left.size() || planes.right.size() != right.size() || planes.left.type() != CV_32FC3 ||
      planes.right.type() != CV_32FC3)
    throw std::invalid_argument(name() + ": the plane maps must be CV_32FC3 of the images' size");
  const cv::Mat raw_left = planeDisparity(planes.left);
  cv::Mat result = raw_left, classes, raw_right;
  if (config_.left_right_check) {
    raw_right = planeDisparity(planes.right);
    result = leftRightCheck(raw_left, raw_right, config_.left_right_tolerance_px);
    if (config_.fill_holes) {
      removeSmallPlaneRegions(&result, planes.left, kMinPlaneRegionPx, kPlaneRegionTolerancePx);
      classes = classifyInvalidPixels(result, raw_left, raw_right, config_.left_right_tolerance_px);
    }
  }
  if (config_.fill_holes) {
    const View left_view = makeView(left), right_view = makeView(right);
    const ViewSolver left_cost(config_, left_view, right_view, 0);
    const PlaneCost cost = [&left_cost](int x, int y, const cv::Vec3f& plane) {
      return left_cost.planeCost(x, y, Plane{plane[0], plane[1], plane[2]});
    };
    cv::Mat holes;
    result = fillHolesFromPlanes(result, planes.left, config_.max_disparity_px, classes, cost, &holes, raw_right,
                                 kForegroundCostRatio);
    if (config_.fill_median_radius_px > 0)
      result = weightedMedianFill(result, holes, left, config_.fill_median_radius_px, config_.fill_color_sigma);
  }
  if (config_.median_radius_px > 0) result = medianFilterValid(result, config_.median_radius_px);
  if (!config_.subpixel) {
    for (int y = 0; y < result.rows; ++y) {
      float* row = result.ptr<float>(y);
      for (int x = 0; x < result.cols; ++x) row[x] = std::round(row[x]);  // NaN stays NaN
    }
  }
  return result;
}

}  // namespace dense
}  // namespace exocet_stereo
