#include "rmr_frame.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <opencv2/imgproc.hpp>

namespace exocet_mosaic {
namespace registration {
namespace internal {

namespace {

// Pixels this close to a level's edge are never selected: their central differences need both neighbours.
constexpr int kBorder = 2;
// Candidates (one per cell) per pixel wanted: the cell size follows from it.
constexpr double kCandidatesPerPixel = 2.5;
// Histogram of the candidates' magnitudes (|gx| + |gy|, grey levels per pixel), in eighths of a grey level.
constexpr int kHistogramBinsPerGrey = 8;
constexpr int kHistogramBins = 512 * kHistogramBinsPerGrey;

inline int histogramBin(float magnitude) {
  return std::min(kHistogramBins - 1, static_cast<int>(magnitude * kHistogramBinsPerGrey));
}

// Steepest-descent vector grad(I) . dW/dp at the identity, for the parameterisation of motion_model.h, written to
// out[0], out[stride], out[2 * stride]...
inline void steepestDescent(MotionModel model, float gx, float gy, float u, float v, float* out, size_t stride) {
  const auto sd = [out, stride](int j) -> float& { return out[j * stride]; };
  sd(0) = gx;
  sd(1) = gy;
  switch (model) {
    case MotionModel::kTranslation:
      break;
    case MotionModel::kSimilarity:
      sd(2) = gx * u + gy * v;
      sd(3) = -gx * v + gy * u;
      break;
    case MotionModel::kAffine:
    case MotionModel::kHomography:
      sd(2) = gx * u;
      sd(3) = gx * v;
      sd(4) = gy * u;
      sd(5) = gy * v;
      if (model == MotionModel::kHomography) {
        const float radial = gx * u + gy * v;
        sd(6) = -radial * u;
        sd(7) = -radial * v;
      }
      break;
  }
}

}  // namespace

RmrFrame::RmrFrame(const cv::Mat& gray, int levels, const RmrSelectionParameters& selection,
                   std::unique_ptr<RmrFrame> recycled)
    : parameters_(selection) {
  if (recycled) {
    levels_ = std::move(recycled->levels_);
    selections_ = std::move(recycled->selections_);
    candidate_magnitude_ = std::move(recycled->candidate_magnitude_);
    candidate_index_ = std::move(recycled->candidate_index_);
    candidate_cell_ = std::move(recycled->candidate_cell_);
    for (int i = 0; i < 2; ++i) {
      row_index_[i] = std::move(recycled->row_index_[i]);
      row_of_[i] = std::move(recycled->row_of_[i]);
    }
  }
  levels_.resize(std::max(1, levels));
  // cv::Mat::create reuses the recycled buffers when the size is the same.
  if (parameters_.smoothing_sigma_px > 0.0) {
    const int radius = std::max(1, static_cast<int>(std::ceil(2.5 * parameters_.smoothing_sigma_px)));
    const cv::Mat kernel = cv::getGaussianKernel(2 * radius + 1, parameters_.smoothing_sigma_px, CV_32F);
    cv::sepFilter2D(gray, levels_[0], CV_32F, kernel, kernel, cv::Point(-1, -1), 0.0, cv::BORDER_REFLECT_101);
  } else {
    gray.convertTo(levels_[0], CV_32F);
  }
  for (size_t l = 1; l < levels_.size(); ++l) cv::pyrDown(levels_[l - 1], levels_[l]);
  selections_.resize(levels_.size());
  selected_.assign(levels_.size(), false);
  cv::Scalar mean, stddev;
  cv::meanStdDev(levels_[std::min<size_t>(1, levels_.size() - 1)], mean, stddev);
  mean_ = mean[0];
  stddev_ = stddev[0];
}

Eigen::Vector2d RmrFrame::centre(int level) const {
  const cv::Size s = size();
  return Eigen::Vector2d(0.5 * (s.width - 1), 0.5 * (s.height - 1)) / double(1 << level);
}

const RmrLevelSelection& RmrFrame::selection(int level) {
  RmrLevelSelection& sel = selections_[level];
  if (selected_[level]) return sel;
  selected_[level] = true;
  // Reset, keeping the capacity of the recycled buffers.
  sel.count = 0;
  sel.textured = 0;
  sel.x.clear();
  sel.y.clear();
  sel.value.clear();
  sel.steepest.clear();
  sel.next.clear();
  const cv::Mat& image = levels_[level];
  const int w = image.cols, h = image.rows;
  const int ng = parameterCount(parameters_.model);
  sel.geometric_parameters = ng;
  if (w <= 2 * kBorder || h <= 2 * kBorder) return sel;
  const float min_gradient = static_cast<float>(parameters_.min_gradient);
  const int inner_w = w - 2 * kBorder;
  // Candidates: the strongest gradient of each cell of cell x cell pixels, a few per pixel wanted. The pixels kept then
  // spread over the image, and a small bright blob (marine snow, a particle) yields a few candidates rather than its
  // whole rim of strong gradients, so that such outliers stay the minority that the robust estimation needs.
  const int inner_h = h - 2 * kBorder;
  const double interior = double(inner_w) * inner_h;
  const long max_pixels =
      std::max<long>(parameters_.min_pixels,
                     std::lround(parameters_.max_pixels * std::ldexp(1.0, 2 * (parameters_.finest_level - level))));
  long target = std::lround(parameters_.pixel_fraction * interior);
  target = std::min<long>(std::max<long>(target, parameters_.min_pixels), max_pixels);
  const int cell = std::max(1, static_cast<int>(std::lround(std::sqrt(interior / (kCandidatesPerPixel * target)))));
  const int cells_x = (inner_w + cell - 1) / cell;
  std::vector<float>& band_max = band_max_;  // per column, the largest magnitude of the band's rows
  std::vector<int>& band_row = band_row_;    // ... and its row
  band_max.resize(inner_w);
  band_row.resize(inner_w);
  std::vector<int>& candidate_index = candidate_index_;  // (r << 16) + c
  std::vector<int>& candidate_cell = candidate_cell_;    // (cell row << 16) + cell column
  std::vector<float>& candidate_magnitude = candidate_magnitude_;
  size_t candidates = 0;
  long textured = 0;
  int cell_row = 0;
  for (int r0 = kBorder; r0 < h - kBorder; r0 += cell, ++cell_row) {
    // Column maxima over the band's rows (branch-free, vectorised), then the maximum of each cell among them.
    const int r1 = std::min(r0 + cell, h - kBorder);
    float* bm = band_max.data();
    int* br = band_row.data();
    for (int r = r0; r < r1; ++r) {
      const float* up = image.ptr<float>(r - 1) + kBorder;
      const float* row = image.ptr<float>(r) + kBorder;
      const float* down = image.ptr<float>(r + 1) + kBorder;
      if (r == r0) {
        for (int c = 0; c < inner_w; ++c) {
          bm[c] = 0.5f * (std::abs(row[c + 1] - row[c - 1]) + std::abs(down[c] - up[c]));
          br[c] = r;
        }
        // Textured pixels counted on the band's first row (an estimate when cell > 1: it only decides
        // kTooLittleTexture).
        int row_textured = 0;
        for (int c = 0; c < inner_w; ++c) row_textured += bm[c] >= min_gradient;
        textured += static_cast<long>(row_textured) * (r1 - r0);
        continue;
      }
      for (int c = 0; c < inner_w; ++c) {
        const float m = 0.5f * (std::abs(row[c + 1] - row[c - 1]) + std::abs(down[c] - up[c]));
        const int larger = m > bm[c];  // arithmetic rather than selects, which GCC vectorises
        br[c] += (r - br[c]) * larger;
        bm[c] = std::max(bm[c], m);
      }
    }
    if (candidate_index.size() < candidates + cells_x) {
      candidate_index.resize(2 * (candidates + cells_x));
      candidate_cell.resize(2 * (candidates + cells_x));
      candidate_magnitude.resize(2 * (candidates + cells_x));
    }
    // Branch-free (conditional moves; each candidate is written, and kept by advancing the count): the comparisons
    // are unpredictable.
    for (int cx = 0, c0 = 0; cx < cells_x; ++cx, c0 += cell) {
      const int c1 = std::min(c0 + cell, inner_w);
      int best = c0;
      float best_magnitude = bm[c0];
      for (int c = c0 + 1; c < c1; ++c) {
        const bool larger = bm[c] > best_magnitude;
        best = larger ? c : best;
        best_magnitude = larger ? bm[c] : best_magnitude;
      }
      candidate_index[candidates] = (br[best] << 16) + best + kBorder;
      candidate_cell[candidates] = (cell_row << 16) + cx;
      candidate_magnitude[candidates] = best_magnitude;
      candidates += best_magnitude >= min_gradient;
    }
  }
  sel.textured = static_cast<int>(textured);
  if (candidates == 0) return sel;

  // The `target` strongest candidates, from a fine histogram of their magnitudes (cheaper than a selection
  // algorithm): all those of the bins above the boundary bin, and an even share (in raster order) of that bin's.
  int boundary = -1;
  long boundary_keep = 0, boundary_count = 0;
  if (static_cast<long>(candidates) > target) {
    std::vector<int>& histogram = histogram_;
    histogram.assign(kHistogramBins, 0);
    for (size_t i = 0; i < candidates; ++i) ++histogram[histogramBin(candidate_magnitude[i])];
    long above = 0;
    boundary = kHistogramBins - 1;
    while (above + histogram[boundary] < target) above += histogram[boundary--];
    boundary_count = histogram[boundary];
    boundary_keep = target - above;
  }

  const size_t reserve = boundary >= 0 ? static_cast<size_t>(target) : candidates;
  sel.x.resize(reserve);
  sel.y.resize(reserve);
  sel.value.resize(reserve);
  sel.steepest.resize(reserve * ng);  // one array per parameter, `reserve` apart until compacted below
  sel.next.resize(reserve);
  // Index of the selected pixel at each cell column of the two latest cell rows, with the cell row it belongs to (no
  // clearing; one column of margin on each side): neighbours are pixels of neighbouring cells.
  std::vector<int>* row_index = row_index_;
  std::vector<int>* row_of = row_of_;
  for (int i = 0; i < 2; ++i) {
    row_index[i].assign(cells_x + 2, -1);
    row_of[i].assign(cells_x + 2, std::numeric_limits<int>::min());  // no cell row (cy - 1 >= -1)
  }
  const Eigen::Vector2d centre_px = centre(level);
  long boundary_seen = 0;
  for (size_t i = 0; i < candidates; ++i) {
    const int bin = boundary >= 0 ? histogramBin(candidate_magnitude[i]) : 0;
    if (bin < boundary) continue;
    if (bin == boundary) {
      const long before = boundary_seen * boundary_keep / boundary_count;
      ++boundary_seen;
      if (boundary_seen * boundary_keep / boundary_count == before) continue;
    }
    const int col = candidate_index[i] & 0xffff, r = candidate_index[i] >> 16;
    const float* row = image.ptr<float>(r);
    const float gx = 0.5f * (row[col + 1] - row[col - 1]);
    const float gy = 0.5f * (image.ptr<float>(r + 1)[col] - image.ptr<float>(r - 1)[col]);
    const int k = sel.count++;
    sel.x[k] = static_cast<float>(col);
    sel.y[k] = static_cast<float>(r);
    sel.value[k] = row[col];
    steepestDescent(parameters_.model, gx, gy, static_cast<float>(col - centre_px.x()),
                    static_cast<float>(r - centre_px.y()), &sel.steepest[k], reserve);
    sel.next[k] = {-1, -1, -1, -1};
    const int cy = candidate_cell[i] >> 16, cx = (candidate_cell[i] & 0xffff) + 1;
    std::vector<int>& cur_index = row_index[cy & 1];
    std::vector<int>& cur_row = row_of[cy & 1];
    const std::vector<int>& prev_index = row_index[(cy - 1) & 1];
    const std::vector<int>& prev_row = row_of[(cy - 1) & 1];
    if (cur_row[cx - 1] == cy) sel.next[cur_index[cx - 1]][0] = k;
    if (prev_row[cx + 1] == cy - 1) sel.next[prev_index[cx + 1]][1] = k;
    if (prev_row[cx] == cy - 1) sel.next[prev_index[cx]][2] = k;
    if (prev_row[cx - 1] == cy - 1) sel.next[prev_index[cx - 1]][3] = k;
    cur_index[cx] = k;
    cur_row[cx] = cy;
  }
  // One array per parameter, contiguous, so that the normal equations are dot products over contiguous arrays.
  for (int j = 1; j < ng && static_cast<size_t>(sel.count) < reserve; ++j)
    std::copy(sel.steepest.begin() + j * reserve, sel.steepest.begin() + j * reserve + sel.count,
              sel.steepest.begin() + static_cast<size_t>(j) * sel.count);
  sel.steepest.resize(static_cast<size_t>(sel.count) * ng);
  sel.x.resize(sel.count);
  sel.y.resize(sel.count);
  sel.value.resize(sel.count);
  sel.next.resize(sel.count);
  return sel;
}

}  // namespace internal
}  // namespace registration
}  // namespace exocet_mosaic
