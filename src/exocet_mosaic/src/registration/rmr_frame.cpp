#include "rmr_frame.h"

#include <algorithm>
#include <cmath>

#include <opencv2/imgproc.hpp>

namespace exocet_mosaic {
namespace registration {
namespace internal {

namespace {

// Pixels this close to a level's edge are never selected: their central differences need both neighbours.
constexpr int kBorder = 2;
// Pixels sampled (regular grid) to find the gradient threshold that keeps the wanted number of pixels.
constexpr double kSamplePixels = 5000.0;
// Largest number of candidate pixels of a level (beyond, they are taken on a coarser grid).
constexpr double kMaxCandidatePixels = 600000.0;
// The full pass keeps up to this many times the wanted count before trimming to it exactly.
constexpr double kTrimAbove = 1.25;

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
    magnitude_ = std::move(recycled->magnitude_);
    sample_ = std::move(recycled->sample_);
    candidate_magnitude_ = std::move(recycled->candidate_magnitude_);
    candidate_index_ = std::move(recycled->candidate_index_);
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
  std::vector<float>& magnitude = magnitude_;
  magnitude.assign((inner_w + 7) / 8 * 8, 0.0f);  // padded with zeros for the groups of 8 of pass 2
  // |gx| + |gy| (central differences) of the interior pixels of row r, in `magnitude`.
  const auto rowMagnitude = [&](int r) {
    const float* up = image.ptr<float>(r - 1) + kBorder;
    const float* row = image.ptr<float>(r) + kBorder;
    const float* down = image.ptr<float>(r + 1) + kBorder;
    float* m = magnitude.data();
    for (int c = 0; c < inner_w; ++c) m[c] = 0.5f * (std::abs(row[c + 1] - row[c - 1]) + std::abs(down[c] - up[c]));
  };

  // Candidates: every pixel, or on large levels (HD) one pixel in grid x grid, which bounds the cost of the full pass
  // (the strongest gradients of a quarter of the pixels are still many more than the pixels kept).
  const double interior = double(inner_w) * (h - 2 * kBorder);
  const int grid = std::max(1, static_cast<int>(std::ceil(std::sqrt(interior / kMaxCandidatePixels))));
  const double population = interior / (grid * grid);

  // Pass 1, on a regular sample of the candidates: the magnitude threshold that keeps about the wanted number.
  const int sample_step = grid * std::max(1, static_cast<int>(std::sqrt(population / kSamplePixels)));
  std::vector<float>& sample = sample_;
  sample.resize(static_cast<size_t>((h / sample_step + 1) * (w / sample_step + 1)));
  size_t kept = 0;
  long sampled = 0;
  for (int r = kBorder; r < h - kBorder; r += sample_step) {
    const float* up = image.ptr<float>(r - 1);
    const float* row = image.ptr<float>(r);
    const float* down = image.ptr<float>(r + 1);
    for (int c = kBorder; c < w - kBorder; c += sample_step) {
      ++sampled;
      const float m = 0.5f * (std::abs(row[c + 1] - row[c - 1]) + std::abs(down[c] - up[c]));
      sample[kept] = m;
      kept += m >= min_gradient;
    }
  }
  sample.resize(kept);
  const double sample_share = sampled > 0 ? double(sample.size()) / sampled : 0.0;
  // Exact on small levels (sample_step = 1), within a few % on the others: it only decides kTooLittleTexture.
  sel.textured = static_cast<int>(std::lround(sample_share * interior));
  const long max_pixels = std::max<long>(parameters_.min_pixels, std::lround(parameters_.max_pixels *
                                                                             std::ldexp(1.0, 2 * (parameters_.finest_level - level))));
  long target = std::lround(parameters_.pixel_fraction * interior);
  target = std::max<long>(target, parameters_.min_pixels);
  target = std::min<long>({target, max_pixels, std::lround(sample_share * population)});
  float threshold = min_gradient;
  if (target <= 0 || sample.empty()) return sel;
  // The sample's quantile: the full pass then finds the target give or take the sampling error (a few %), trimmed
  // below when it finds many more.
  const size_t keep_in_sample = std::min(sample.size(), static_cast<size_t>(std::ceil(target * sample.size() /
                                                                                        (sample_share * population))));
  if (keep_in_sample < sample.size()) {
    auto nth = sample.end() - static_cast<long>(keep_in_sample);
    std::nth_element(sample.begin(), nth, sample.end());
    threshold = std::max(min_gradient, *nth);
  }

  // Pass 2, every candidate: those at or above the threshold.
  std::vector<int>& candidate_index = candidate_index_;  // (r << 16) + c
  std::vector<float>& candidate_magnitude = candidate_magnitude_;
  size_t candidates = 0;
  // The magnitudes of a row are padded with zeros to a multiple of 8, so that groups of 8 without a candidate are
  // skipped after one vectorised maximum (most are: a few % of the pixels qualify, and they cluster on edges).
  const int padded_w = static_cast<int>(magnitude.size());
  for (int r = kBorder; r < h - kBorder; r += grid) {
    rowMagnitude(r);
    if (candidate_index.size() < candidates + inner_w) {
      candidate_index.resize(2 * (candidates + inner_w));
      candidate_magnitude.resize(2 * (candidates + inner_w));
    }
    const float* m = magnitude.data();
    const int base = (r << 16) + kBorder;
    for (int c0 = 0; c0 < padded_w; c0 += 8) {
      float group_max = m[c0];
      for (int l = 1; l < 8; ++l) group_max = std::max(group_max, m[c0 + l]);
      if (group_max < threshold) continue;
      for (int c = c0; c < c0 + 8; ++c) {
        if (m[c] < threshold || c % grid != 0) continue;
        candidate_index[candidates] = base + c;
        candidate_magnitude[candidates] = m[c];
        ++candidates;
      }
    }
  }

  // Too many (ties at the threshold, sampling error): exactly `target`, all the candidates above the boundary
  // magnitude and an even share (in raster order) of those equal to it.
  float boundary = -1.0f;
  long boundary_keep = 0, boundary_count = 0;
  if (static_cast<double>(candidates) > kTrimAbove * target) {
    std::vector<float>& m = sample_;  // the sample is no longer needed
    m.assign(candidate_magnitude.begin(), candidate_magnitude.begin() + candidates);
    auto nth = m.end() - target;
    std::nth_element(m.begin(), nth, m.end());
    boundary = *nth;
    long above = 0;
    for (size_t i = 0; i < candidates; ++i) {
      above += candidate_magnitude[i] > boundary;
      boundary_count += candidate_magnitude[i] == boundary;
    }
    boundary_keep = target - above;
  }

  const size_t reserve = boundary_count > 0 ? static_cast<size_t>(target) : candidates;
  sel.x.resize(reserve);
  sel.y.resize(reserve);
  sel.value.resize(reserve);
  sel.steepest.resize(reserve * ng);  // one array per parameter, `reserve` apart until compacted below
  sel.next.resize(reserve);
  // Index of the selected pixel at each column of the two latest rows, with the row it belongs to (no clearing).
  std::vector<int>* row_index = row_index_;
  std::vector<int>* row_of = row_of_;
  for (int i = 0; i < 2; ++i) {
    row_index[i].assign(w, -1);
    row_of[i].assign(w, -1);
  }
  const Eigen::Vector2d centre_px = centre(level);
  long boundary_seen = 0;
  for (size_t i = 0; i < candidates; ++i) {
    const float magnitude_i = candidate_magnitude[i];
    if (magnitude_i < boundary) continue;
    if (magnitude_i == boundary) {
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
    std::vector<int>& cur_index = row_index[r & 1];
    std::vector<int>& cur_row = row_of[r & 1];
    const std::vector<int>& prev_index = row_index[(r - 1) & 1];
    const std::vector<int>& prev_row = row_of[(r - 1) & 1];
    if (k > 0 && sel.y[k - 1] == r && sel.x[k - 1] == col - 1) sel.next[k - 1][0] = k;
    if (prev_row[col + 1] == r - 1) sel.next[prev_index[col + 1]][1] = k;
    if (prev_row[col] == r - 1) sel.next[prev_index[col]][2] = k;
    if (prev_row[col - 1] == r - 1) sel.next[prev_index[col - 1]][3] = k;
    cur_index[col] = k;
    cur_row[col] = r;
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
