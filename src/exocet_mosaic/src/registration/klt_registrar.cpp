#include "exocet_mosaic/registration/klt_registrar.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include <Eigen/Dense>
#include <opencv2/core/hal/intrin.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

#include "exocet_mosaic/registration/rigid_scene_check.h"

namespace exocet_mosaic {
namespace registration {

namespace {

using Clock = std::chrono::steady_clock;

double msSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

cv::Point2f transfer(const Eigen::Matrix3d& h, const cv::Point2f& x) {
  const double w = h(2, 0) * x.x + h(2, 1) * x.y + h(2, 2);
  return {static_cast<float>((h(0, 0) * x.x + h(0, 1) * x.y + h(0, 2)) / w),
          static_cast<float>((h(1, 0) * x.x + h(1, 1) * x.y + h(1, 2)) / w)};
}

std::string sizeString(const cv::Size& size) { return std::to_string(size.width) + "x" + std::to_string(size.height); }

// Scharr derivatives of a pyramid level over [x0, x1) x [y0, y1), exactly as cv::buildOpticalFlowPyramid computes
// them: 3-10-3 smoothing across, central difference along, the image reflected at its border (reflect-101), pairs
// (dI/dx, dI/dy) of int16. Straight from the three rows, 8 columns at a time; the image's first and last columns
// one by one.
void scharrDerivatives(const cv::Mat& image, int x0, int y0, int x1, int y1, cv::Mat* derivatives) {
  const int rows = image.rows, cols = image.cols;
  auto column = [cols](int x) { return x < 0 ? std::min(1, cols - 1) : (x >= cols ? std::max(cols - 2, 0) : x); };
  const int inner0 = std::max(x0, 1), inner1 = std::min(x1, cols - 1);
  for (int y = y0; y < y1; ++y) {
    const uchar* r0 = image.ptr<uchar>(y > 0 ? y - 1 : (rows > 1 ? 1 : 0));
    const uchar* r1 = image.ptr<uchar>(y);
    const uchar* r2 = image.ptr<uchar>(y < rows - 1 ? y + 1 : (rows > 1 ? rows - 2 : 0));
    int16_t* d = derivatives->ptr<int16_t>(y);
    auto one = [&](int x, int left, int right) {
      d[2 * x] = static_cast<int16_t>((r0[right] + r2[right]) * 3 + r1[right] * 10 - (r0[left] + r2[left]) * 3 -
                                      r1[left] * 10);
      d[2 * x + 1] = static_cast<int16_t>(((r2[right] - r0[right]) + (r2[left] - r0[left])) * 3 + (r2[x] - r0[x]) * 10);
    };
    if (x0 == 0) one(0, column(-1), column(1));
    int x = inner0;
#if CV_SIMD128
    // Wrapping (not saturating) arithmetic: every value fits 16 bits.
    const cv::v_int16x8 three = cv::v_setall_s16(3), ten = cv::v_setall_s16(10);
    auto load = [](const uchar* p) { return cv::v_reinterpret_as_s16(cv::v_load_expand(p)); };
    for (; x < inner1; x += 8) {
      // The last 8 columns of a span that is not a multiple of 8 overlap the previous ones (same values again).
      if (x + 8 > inner1) {
        if (inner1 - inner0 < 8) break;
        x = inner1 - 8;
      }
      const cv::v_int16x8 left =
          cv::v_mul_wrap(load(r0 + x - 1) + load(r2 + x - 1), three) + cv::v_mul_wrap(load(r1 + x - 1), ten);
      const cv::v_int16x8 right =
          cv::v_mul_wrap(load(r0 + x + 1) + load(r2 + x + 1), three) + cv::v_mul_wrap(load(r1 + x + 1), ten);
      const cv::v_int16x8 outer =
          cv::v_sub_wrap(load(r2 + x - 1), load(r0 + x - 1)) + cv::v_sub_wrap(load(r2 + x + 1), load(r0 + x + 1));
      const cv::v_int16x8 dy =
          cv::v_mul_wrap(outer, three) + cv::v_mul_wrap(cv::v_sub_wrap(load(r2 + x), load(r0 + x)), ten);
      cv::v_store_interleave(d + 2 * x, cv::v_sub_wrap(right, left), dy);
    }
#endif
    for (; x < inner1; ++x) one(x, x - 1, x + 1);
    if (x1 == cols && cols > 1) one(cols - 1, column(cols - 2), column(cols));
  }
}

// One pyramid level from the one below, whose image lies in `below` at (border_x, border_y) with a reflected border
// of at least 2 pixels: the separable 4-tap binomial filter [1 3 3 1] / 8 at every other pixel, so that pixel x of
// the result covers pixels 2x - 1 ... 2x + 2 below. Half the cost of pyrDown's 5-tap filter (which the library's
// baseline build does not vectorise as well), smoother than a 2 x 2 mean: the coarse levels must still find large
// motions between views that rotate. The half-pixel offset (centre 2x + 0.5 rather than 2x) is the same in both
// images of a pair, so it does not bias the tracks.
void downsample(const cv::Mat& below, int border_x, int border_y, cv::Mat* out) {
  const int width = out->cols, height = out->rows;
  // Rows of the level below filtered horizontally (h[x] covers columns 2x - 1 ... 2x + 2); the four that an output
  // row needs, two of them kept for the next.
  std::vector<uint16_t> rows(4 * size_t(width));
  uint16_t* h[4] = {rows.data(), rows.data() + width, rows.data() + 2 * width, rows.data() + 3 * width};
  auto filterRow = [&](int row, uint16_t* dst) {
    const uchar* r = below.ptr<uchar>(border_y + row) + border_x;
    int x = 0;
#if CV_SIMD128
    // Two neighbouring bytes per 16-bit lane: the low byte is column 2x - 1 (or 2x + 1), the high one 2x (2x + 2).
    const cv::v_uint16x8 low_byte = cv::v_setall_u16(0xff), three = cv::v_setall_u16(3);
    for (; x + 8 <= width; x += 8) {
      const cv::v_uint16x8 p = cv::v_reinterpret_as_u16(cv::v_load(r + 2 * x - 1));
      const cv::v_uint16x8 q = cv::v_reinterpret_as_u16(cv::v_load(r + 2 * x + 1));
      cv::v_store(dst + x, (p & low_byte) + cv::v_shr<8>(q) + cv::v_mul_wrap(cv::v_shr<8>(p) + (q & low_byte), three));
    }
#endif
    for (; x < width; ++x) dst[x] = static_cast<uint16_t>(r[2 * x - 1] + r[2 * x + 2] + 3 * (r[2 * x] + r[2 * x + 1]));
  };
  filterRow(-1, h[2]);
  filterRow(0, h[3]);
  for (int y = 0; y < height; ++y) {
    std::swap(h[0], h[2]);  // rows 2y - 1 and 2y were computed as the previous output row's last two
    std::swap(h[1], h[3]);
    filterRow(2 * y + 1, h[2]);
    filterRow(2 * y + 2, h[3]);
    uchar* o = out->ptr<uchar>(y);
    int x = 0;
#if CV_SIMD128
    const cv::v_uint16x8 three = cv::v_setall_u16(3), half = cv::v_setall_u16(32);
    for (; x + 8 <= width; x += 8) {
      const cv::v_uint16x8 sum = cv::v_load(h[0] + x) + cv::v_load(h[3] + x) +
                                 cv::v_mul_wrap(cv::v_load(h[1] + x) + cv::v_load(h[2] + x), three) + half;
      cv::v_pack_store(o + x, cv::v_shr<6>(sum));
    }
#endif
    for (; x < width; ++x) o[x] = static_cast<uchar>((h[0][x] + h[3][x] + 3 * (h[1][x] + h[2][x]) + 32) >> 6);
  }
}

const KltConfig& validated(const KltConfig& config) {
  const std::string error = config.validate();
  if (!error.empty()) throw std::invalid_argument("KltConfig: " + error);
  return config;
}

}  // namespace

std::string KltConfig::validate() const {
  std::ostringstream errors;
  auto check = [&errors](bool ok, const char* field, const std::string& range) {
    if (ok) return;
    if (errors.tellp() > 0) errors << "; ";
    errors << field << " must be in " << range;
  };
  const int minimal = minimalPointCount(model);
  const std::string minimal_range =
      "[" + std::to_string(minimal) + " (minimal points of the " + toString(model) + " model), 5000]";
  check(max_features >= 8 && max_features <= 5000, "max_features", "[8, 5000]");
  check(grid_cols >= 1 && grid_cols <= 64, "grid_cols", "[1, 64]");
  check(grid_rows >= 1 && grid_rows <= 64, "grid_rows", "[1, 64]");
  check(min_distance_px >= 1.0 && min_distance_px <= 200.0, "min_distance_px", "[1, 200]");
  check(quality_level >= 0.0 && quality_level < 1.0, "quality_level", "[0, 1)");
  check(min_eigenvalue >= 0.0 && min_eigenvalue <= 1.0, "min_eigenvalue", "[0, 1]");
  check(block_size >= 3 && block_size <= 15 && block_size % 2 == 1, "block_size", "odd values of [3, 15]");
  check(detection_max_width_px >= 64 && detection_max_width_px <= 100000, "detection_max_width_px", "[64, 100000]");
  check(min_features >= 1 && min_features <= max_features, "min_features", "[1, max_features]");
  check(redetect_fraction >= 0.0 && redetect_fraction <= 1.0, "redetect_fraction", "[0, 1]");
  check(window_px >= 5 && window_px <= 63 && window_px % 2 == 1, "window_px", "odd values of [5, 63]");
  check(pyramid_levels >= 1 && pyramid_levels <= 8, "pyramid_levels", "[1, 8]");
  check(lk_max_iterations >= 1 && lk_max_iterations <= 100, "lk_max_iterations", "[1, 100]");
  check(lk_epsilon_px > 0.0 && lk_epsilon_px <= 1.0, "lk_epsilon_px", "(0, 1]");
  check(fb_threshold_px > 0.0 && fb_threshold_px <= 20.0, "fb_threshold_px", "(0, 20]");
  check(fb_fine_start_px >= 0.0 && fb_fine_start_px <= 100.0, "fb_fine_start_px", "[0, 100]");
  check(predicted_pyramid_levels >= 1 && predicted_pyramid_levels <= 8, "predicted_pyramid_levels", "[1, 8]");
  check(retrack_fraction >= 0.0 && retrack_fraction <= 1.0, "retrack_fraction", "[0, 1]");
  check(prediction_probes >= 0 && prediction_probes <= 1000, "prediction_probes", "[0, 1000]");
  check(prediction_tolerance_px > 0.0 && prediction_tolerance_px <= 100.0, "prediction_tolerance_px", "(0, 100]");
  check(min_tracks >= minimal && min_tracks <= 5000, "min_tracks", minimal_range);
  check(min_inliers >= minimal && min_inliers <= 5000, "min_inliers", minimal_range);
  check(min_inlier_fraction >= 0.0 && min_inlier_fraction <= 1.0, "min_inlier_fraction", "[0, 1]");
  check(consensus_threshold_px > 0.0 && consensus_threshold_px <= 100.0, "consensus_threshold_px", "(0, 100]");
  check(rejection_k >= 2.0 && rejection_k <= 20.0, "rejection_k", "[2, 20]");
  check(min_residual_scale_px > 0.0 && min_residual_scale_px <= 10.0, "min_residual_scale_px", "(0, 10]");
  check(max_residual_px > 0.0 && max_residual_px <= 100.0, "max_residual_px", "(0, 100]");
  check(max_local_residual_px > 0.0 && max_local_residual_px <= 100.0, "max_local_residual_px", "(0, 100]");
  check(rigid_k_sigma >= 1.0 && rigid_k_sigma <= 20.0, "rigid_k_sigma", "[1, 20]");
  const std::string coarse_error = coarse.validate();
  if (!coarse_error.empty()) errors << (errors.tellp() > 0 ? "; " : "") << "coarse: " << coarse_error;
  check(covariance_inflation >= 1.0 && covariance_inflation <= 100.0, "covariance_inflation", "[1, 100]");
  check(max_motion_fraction > 0.0 && max_motion_fraction <= 10.0, "max_motion_fraction", "(0, 10]");
  check(min_mean_grey >= 0.0 && min_mean_grey <= 255.0, "min_mean_grey", "[0, 255]");
  check(min_contrast_grey >= 0.0 && min_contrast_grey <= 128.0, "min_contrast_grey", "[0, 128]");
  return errors.str();
}

RobustFitConfig KltConfig::fitConfig() const {
  RobustFitConfig fit;
  fit.model = model;
  fit.rejection_k = rejection_k;
  fit.min_scale_px = min_residual_scale_px;
  fit.min_inliers = min_inliers;
  fit.min_inlier_fraction = min_inlier_fraction;
  fit.sample_threshold_px = consensus_threshold_px;
  return fit;
}

KltRegistrar::KltRegistrar(const KltConfig& config)
    : config_(validated(config)), fitter_(config_.fitConfig()), window_(config_.window_px, config_.window_px) {}

void KltRegistrar::reset() {
  has_previous_ = false;
  previous_.features.clear();
  current_.features.clear();
}

MotionEstimate KltRegistrar::emptyEstimate(const cv::Size& size) const {
  MotionEstimate estimate;
  estimate.failed = true;
  estimate.failure = FailureReason::kNoPreviousFrame;
  estimate.method = RegistrationMethod::kKlt;
  estimate.model = config_.model;
  estimate.centre_px = {0.5 * (size.width - 1), 0.5 * (size.height - 1)};
  const int p = parameterCount(config_.model);
  estimate.parameters = Eigen::VectorXd::Zero(p);
  estimate.covariance = Eigen::MatrixXd::Zero(p, p);
  estimate.pixel_matrix = Eigen::Matrix3d::Identity();
  return estimate;
}

void KltRegistrar::prepare(const cv::Mat& gray, Frame* frame) {
  const Clock::time_point start = Clock::now();
  frame->size = gray.size();
  buildImagePyramid(gray, frame);
  // The derivatives, which cost more than the images on every level, are filled in where Lucas-Kanade will read
  // them (derivatives_on_demand), or here on whole levels. Their buffers keep a zero border, like
  // cv::buildOpticalFlowPyramid's.
  frame->derivative_buffers.resize(frame->max_level + 1);
  frame->pyramid.resize(2 * (frame->max_level + 1));
  for (int level = 0; level <= frame->max_level; ++level) {
    const cv::Mat& image = frame->images[level];
    cv::Mat& buffer = frame->derivative_buffers[level];
    const cv::Size padded(image.cols + 2 * window_.width, image.rows + 2 * window_.height);
    if (buffer.size() != padded || buffer.type() != CV_16SC2) {
      buffer.create(padded, CV_16SC2);
      buffer.setTo(cv::Scalar::all(0));
    }
    frame->pyramid[2 * level] = image;
    frame->pyramid[2 * level + 1] = buffer(cv::Rect(window_.width, window_.height, image.cols, image.rows));
    if (!config_.derivatives_on_demand) {
      // OpenCV's Scharr filter, independent of ours (test DerivativesOnDemandMatchWholeLevels compares the two).
      cv::Mat dx, dy;
      cv::Scharr(image, dx, CV_16S, 1, 0, 1.0, 0.0, cv::BORDER_REFLECT_101 | cv::BORDER_ISOLATED);
      cv::Scharr(image, dy, CV_16S, 0, 1, 1.0, 0.0, cv::BORDER_REFLECT_101 | cv::BORDER_ISOLATED);
      cv::Mat derivatives = frame->pyramid[2 * level + 1];
      cv::merge(std::vector<cv::Mat>{dx, dy}, derivatives);
    }
  }
  frame->complete_levels = config_.derivatives_on_demand ? 0u : ~0u;
  frame->features.clear();
  frame->detected_cells = frame->detected_features = 0;
  frame->strongest_corner = 0.0f;
  // Mean and contrast on the coarsest level: cheap, and the sensor noise does not pass for contrast there.
  cv::Scalar mean, stddev;
  cv::meanStdDev(frame->pyramid[2 * frame->max_level], mean, stddev);
  frame->usable = mean[0] >= config_.min_mean_grey && stddev[0] >= config_.min_contrast_grey;
  frame->unusable_detail.clear();
  if (!frame->usable) {
    std::ostringstream detail;
    detail.precision(3);
    detail << "mean grey " << mean[0] << " (min_mean_grey " << config_.min_mean_grey << "), contrast " << stddev[0]
           << " (min_contrast_grey " << config_.min_contrast_grey << ")";
    frame->unusable_detail = detail.str();
  }
  diagnostics_.pyramid_ms += msSince(start);
}

void KltRegistrar::buildImagePyramid(const cv::Mat& gray, Frame* frame) {
  // cv::buildOpticalFlowPyramid's layout (each level inside a buffer with a reflected border of the window's size,
  // as many levels as are larger than the window), each level filtered down from the one below by downsample().
  const int border_x = window_.width, border_y = window_.height;
  frame->image_buffers.resize(config_.pyramid_levels);
  frame->images.resize(config_.pyramid_levels);
  cv::Size size = gray.size();
  int level = 0;
  for (;; ++level) {
    cv::Mat& buffer = frame->image_buffers[level];
    const cv::Size padded(size.width + 2 * border_x, size.height + 2 * border_y);
    if (buffer.size() != padded || buffer.type() != CV_8UC1) buffer.create(padded, CV_8UC1);
    cv::Mat& image = frame->images[level];
    image = buffer(cv::Rect(border_x, border_y, size.width, size.height));
    if (level == 0) {
      if (gray.data == image.data && gray.step == image.step) {  // written in place (nextImageBuffer)
        cv::copyMakeBorder(image, buffer, border_y, border_y, border_x, border_x,
                           cv::BORDER_REFLECT_101 | cv::BORDER_ISOLATED);
      } else {  // a copy: the caller may overwrite its image before the next call
        cv::copyMakeBorder(gray, buffer, border_y, border_y, border_x, border_x, cv::BORDER_REFLECT_101);
      }
    } else {
      downsample(frame->image_buffers[level - 1], border_x, border_y, &image);
      cv::copyMakeBorder(image, buffer, border_y, border_y, border_x, border_x,
                         cv::BORDER_REFLECT_101 | cv::BORDER_ISOLATED);
    }
    const cv::Size next((size.width + 1) / 2, (size.height + 1) / 2);
    if (level + 1 >= config_.pyramid_levels || next.width <= window_.width || next.height <= window_.height) break;
    size = next;
  }
  frame->max_level = level;
  frame->images.resize(level + 1);
}

void KltRegistrar::computeDerivatives(Frame* frame, const std::vector<cv::Point2f>& points, size_t first, int min_level,
                                      int max_level) {
  if (!config_.derivatives_on_demand || first >= points.size()) return;
  // Lucas-Kanade reads the derivatives over the window (+1 for the bilinear interpolation) around each point.
  const int half = config_.window_px / 2 + 2;
  const double patch_area = (2.0 * half + 1.0) * (2.0 * half + 1.0);
  for (int level = min_level; level <= std::min(max_level, frame->max_level); ++level) {
    if (frame->complete_levels & (1u << level)) continue;
    const cv::Mat& image = frame->pyramid[2 * level];
    cv::Mat& derivatives = frame->pyramid[2 * level + 1];
    if ((points.size() - first) * patch_area >= 0.5 * image.total()) {
      // Coarse levels: the patches would cover most of the level anyway.
      scharrDerivatives(image, 0, 0, image.cols, image.rows, &derivatives);
      frame->complete_levels |= 1u << level;
      continue;
    }
    const float scale = 1.0f / static_cast<float>(1 << level);
    for (size_t i = first; i < points.size(); ++i) {
      const int cx = cvFloor(points[i].x * scale), cy = cvFloor(points[i].y * scale);
      const int x0 = std::max(0, cx - half), x1 = std::min(image.cols, cx + half + 1);
      const int y0 = std::max(0, cy - half), y1 = std::min(image.rows, cy + half + 1);
      if (x0 < x1 && y0 < y1) scharrDerivatives(image, x0, y0, x1, y1, &derivatives);
    }
  }
}

bool KltRegistrar::needsDetection(const Frame& frame) const {
  const int n = static_cast<int>(frame.features.size());
  if (n < config_.min_features || frame.detected_features == 0) return true;
  if (n < config_.redetect_fraction * frame.detected_features) return true;
  // Cells holding a feature: the features leaving the image empty whole cells before the count drops much.
  const double cell_w = double(frame.size.width) / config_.grid_cols,
               cell_h = double(frame.size.height) / config_.grid_rows;
  uint64_t filled[64] = {};  // one bit per column, one word per row
  int cells = 0;
  for (const cv::Point2f& f : frame.features) {
    const int cx = std::min(config_.grid_cols - 1, std::max(0, static_cast<int>(f.x / cell_w)));
    const int cy = std::min(config_.grid_rows - 1, std::max(0, static_cast<int>(f.y / cell_h)));
    const uint64_t bit = uint64_t(1) << cx;
    if (!(filled[cy] & bit)) {
      filled[cy] |= bit;
      ++cells;
    }
  }
  return cells < config_.redetect_fraction * frame.detected_cells;
}

void KltRegistrar::topUpFeatures(Frame* frame) {
  const Clock::time_point start = Clock::now();
  const int width = frame->size.width, height = frame->size.height;
  const int cols = config_.grid_cols, rows = config_.grid_rows, cells = cols * rows;
  const int quota = std::max(1, config_.max_features / cells);
  const double cell_w = double(width) / cols, cell_h = double(height) / rows;
  auto cell_of = [&](float x, float y) {
    const int cx = std::min(cols - 1, std::max(0, static_cast<int>(x / cell_w)));
    const int cy = std::min(rows - 1, std::max(0, static_cast<int>(y / cell_h)));
    return cy * cols + cx;
  };
  // Bins of min_distance: a feature closer than min_distance to another lies in one of the 3x3 bins around it.
  const float min_distance = static_cast<float>(config_.min_distance_px);
  const int bin_cols = static_cast<int>(std::ceil(width / min_distance)) + 1;
  const int bin_rows = static_cast<int>(std::ceil(height / min_distance)) + 1;
  occupancy_head_.assign(bin_cols * bin_rows, -1);
  occupancy_next_.clear();
  std::vector<cv::Point2f>& features = frame->features;
  auto near = [&](const cv::Point2f& p, float distance) {
    const int bx = static_cast<int>(p.x / min_distance), by = static_cast<int>(p.y / min_distance);
    for (int y = std::max(0, by - 1); y <= std::min(bin_rows - 1, by + 1); ++y)
      for (int x = std::max(0, bx - 1); x <= std::min(bin_cols - 1, bx + 1); ++x)
        for (int i = occupancy_head_[y * bin_cols + x]; i >= 0; i = occupancy_next_[i]) {
          const cv::Point2f d = features[i] - p;
          if (d.x * d.x + d.y * d.y < distance * distance) return true;
        }
    return false;
  };
  auto occupy = [&](int index) {
    const cv::Point2f& p = features[index];
    const int bin = static_cast<int>(p.y / min_distance) * bin_cols + static_cast<int>(p.x / min_distance);
    occupancy_next_.push_back(occupancy_head_[bin]);
    occupancy_head_[bin] = index;
  };

  // Keep the surviving features that stay clear of the border, dropping those that have converged onto another
  // (zooming out brings tracks together).
  const float margin = static_cast<float>(config_.window_px / 2 + 1);
  cell_count_.assign(cells, 0);
  size_t kept = 0;
  for (size_t i = 0; i < features.size(); ++i) {
    const cv::Point2f p = features[i];
    if (p.x < margin || p.y < margin || p.x > width - 1 - margin || p.y > height - 1 - margin) continue;
    if (near(p, 0.5f * min_distance)) continue;
    features[kept] = p;
    occupy(static_cast<int>(kept++));
    ++cell_count_[cell_of(p.x, p.y)];
  }
  features.resize(kept);

  // The detector runs only where features are lacking: on each such cell, or on their bounding box when they are
  // many (the first image, after a failure).
  rois_.clear();
  int needy = 0;
  cv::Rect box;
  for (int c = 0; c < cells; ++c) {
    if (cell_count_[c] >= quota) continue;
    const int cx = c % cols, cy = c / cols;
    const cv::Rect cell(static_cast<int>(cx * cell_w), static_cast<int>(cy * cell_h),
                        static_cast<int>(std::ceil((cx + 1) * cell_w)) - static_cast<int>(cx * cell_w),
                        static_cast<int>(std::ceil((cy + 1) * cell_h)) - static_cast<int>(cy * cell_h));
    box = needy++ == 0 ? cell : (box | cell);
    rois_.push_back(cell);
  }
  if (2 * needy > cells) rois_.assign(1, box);

  // Detect on the finest level no wider than detection_max_width_px: a corner there is textured at full resolution
  // too, and Lucas-Kanade needs texture, not a precisely located corner.
  int level = 0;
  while (level < frame->max_level && frame->pyramid[2 * level].cols > config_.detection_max_width_px) ++level;
  const cv::Mat& image = frame->pyramid[2 * level];
  const int s = 1 << level;
  const int pad = config_.block_size / 2 + 2;
  candidates_.clear();
  for (const cv::Rect& area : rois_) {
    const cv::Rect roi =
        cv::Rect(area.x / s - pad, area.y / s - pad, area.width / s + 2 * pad + 1, area.height / s + 2 * pad + 1) &
        cv::Rect(0, 0, image.cols, image.rows);
    cv::cornerMinEigenVal(image(roi), eigen_, config_.block_size, 3);
    // Local maxima (3x3) above the absolute floor, in the cells that lack features.
    const float floor = static_cast<float>(config_.min_eigenvalue);
    for (int y = 1; y < eigen_.rows - 1; ++y) {
      const float* above = eigen_.ptr<float>(y - 1);
      const float* row = eigen_.ptr<float>(y);
      const float* below = eigen_.ptr<float>(y + 1);
      const float fy = static_cast<float>((roi.y + y) * s);
      if (fy < margin || fy > height - 1 - margin) continue;
      for (int x = 1; x < eigen_.cols - 1; ++x) {
        const float v = row[x];
        if (v < floor || v <= 0.0f || v < row[x - 1] || v < row[x + 1] || v < above[x - 1] || v < above[x] ||
            v < above[x + 1] || v < below[x - 1] || v < below[x] || v < below[x + 1])
          continue;
        const float fx = static_cast<float>((roi.x + x) * s);
        if (fx < margin || fx > width - 1 - margin) continue;
        const int cell = cell_of(fx, fy);
        if (cell_count_[cell] < quota) candidates_.push_back({v, fx, fy, cell});
      }
    }
  }
  // quality_level is relative to the strongest corner of this search or, when it covered a few cells only, of the
  // detections that found the features of the other cells.
  float strongest = 2 * needy > cells ? 0.0f : frame->strongest_corner;
  for (const Candidate& c : candidates_) strongest = std::max(strongest, c.strength);
  frame->strongest_corner = strongest;
  const float threshold = static_cast<float>(config_.quality_level) * strongest;
  std::sort(candidates_.begin(), candidates_.end(),
            [](const Candidate& a, const Candidate& b) { return a.strength > b.strength; });
  int detected = 0;
  for (const Candidate& c : candidates_) {
    if (static_cast<int>(features.size()) >= config_.max_features || c.strength < threshold) break;
    if (cell_count_[c.cell] >= quota) continue;
    const cv::Point2f p(c.x, c.y);
    if (near(p, min_distance)) continue;
    features.push_back(p);
    occupy(static_cast<int>(features.size()) - 1);
    ++cell_count_[c.cell];
    ++detected;
  }
  computeDerivatives(frame, features, features.size() - detected, 0, 0);  // the coarser levels when tracked there
  frame->detected_features = static_cast<int>(features.size());
  frame->detected_cells =
      static_cast<int>(std::count_if(cell_count_.begin(), cell_count_.end(), [](int n) { return n > 0; }));
  diagnostics_.detected += detected;
  diagnostics_.detect_ms += msSince(start);
}

int KltRegistrar::trackForward(Frame* previous, const Frame& current, const Eigen::Matrix3d& prediction_px,
                               int all_levels, bool whole_pyramid, const cv::TermCriteria& criteria) {
  // The finest level's derivatives are there around every feature (computed when it was tracked into, or detected
  // in, that image); the coarser levels' are computed here for the features tracked on them.
  const std::vector<cv::Point2f>& features = previous->features;
  const int n = static_cast<int>(features.size());
  forward_.resize(n);
  for (int i = 0; i < n; ++i) forward_[i] = transfer(prediction_px, features[i]);
  const int fine_levels = std::min(all_levels, config_.predicted_pyramid_levels - 1);
  const int probes = std::min(n, config_.prediction_probes);
  if (whole_pyramid || fine_levels == all_levels || prediction_px.isIdentity(1e-12) || probes == 0) {
    computeDerivatives(previous, features, 0, 1, all_levels);
    cv::calcOpticalFlowPyrLK(previous->pyramid, current.pyramid, features, forward_, status_, error_, window_,
                             all_levels, criteria, cv::OPTFLOW_USE_INITIAL_FLOW);
    return all_levels;
  }
  // The coarse levels serve to find motions that the prediction has not taken out. A few features spread over the
  // list (and so over the image) are tracked on the whole pyramid first: if most of them end up near where the
  // prediction sent them, the others need only the fine levels. Checked, because a track that starts too far away
  // for the levels it runs on may stay where it started, and so may its backward track: the forward-backward check
  // would not see it.
  group_.clear();
  for (int p = 0; p < probes; ++p) group_.push_back(static_cast<int>((static_cast<int64_t>(p) * n) / probes));
  group_to_.resize(probes);
  group_start_.resize(probes);
  for (int p = 0; p < probes; ++p) {
    group_to_[p] = features[group_[p]];
    group_start_[p] = forward_[group_[p]];
  }
  computeDerivatives(previous, group_to_, 0, 1, all_levels);
  cv::calcOpticalFlowPyrLK(previous->pyramid, current.pyramid, group_to_, group_start_, group_status_, error_, window_,
                           all_levels, criteria, cv::OPTFLOW_USE_INITIAL_FLOW);
  probe_misses_.clear();
  for (int p = 0; p < probes; ++p) {
    if (!group_status_[p]) continue;
    const cv::Point2f d = group_start_[p] - forward_[group_[p]];
    probe_misses_.push_back(d.x * d.x + d.y * d.y);
  }
  // Three quarters of the probes within tolerance (the others may be on particles, or lost).
  const size_t quartile = (3 * static_cast<size_t>(probes) + 3) / 4;
  bool trusted = probe_misses_.size() >= quartile;
  if (trusted) {
    std::nth_element(probe_misses_.begin(), probe_misses_.begin() + (quartile - 1), probe_misses_.end());
    trusted = probe_misses_[quartile - 1] <= config_.prediction_tolerance_px * config_.prediction_tolerance_px;
  }
  diagnostics_.prediction_trusted = trusted;
  if (!trusted) {
    computeDerivatives(previous, features, 0, 1, all_levels);
    cv::calcOpticalFlowPyrLK(previous->pyramid, current.pyramid, features, forward_, status_, error_, window_,
                             all_levels, criteria, cv::OPTFLOW_USE_INITIAL_FLOW);
    return all_levels;
  }
  // The probes keep their tracks; the others run on the fine levels.
  status_.assign(n, 0);
  is_probe_.assign(n, 0);
  for (int p = 0; p < probes; ++p) {
    forward_[group_[p]] = group_start_[p];
    status_[group_[p]] = group_status_[p];
    is_probe_[group_[p]] = 1;
  }
  group_.clear();
  for (int i = 0; i < n; ++i)
    if (!is_probe_[i]) group_.push_back(i);
  group_to_.resize(group_.size());
  group_start_.resize(group_.size());
  for (size_t g = 0; g < group_.size(); ++g) {
    group_to_[g] = features[group_[g]];
    group_start_[g] = forward_[group_[g]];
  }
  if (!group_.empty()) {
    computeDerivatives(previous, group_to_, 0, 1, fine_levels);
    cv::calcOpticalFlowPyrLK(previous->pyramid, current.pyramid, group_to_, group_start_, group_status_, error_,
                             window_, fine_levels, criteria, cv::OPTFLOW_USE_INITIAL_FLOW);
  }
  for (size_t g = 0; g < group_.size(); ++g) {
    forward_[group_[g]] = group_start_[g];
    status_[group_[g]] = group_status_[g];
  }
  return fine_levels;
}

void KltRegistrar::trackBackward(Frame* from, const Frame& to, int levels, const cv::TermCriteria& criteria) {
  back_status_.assign(to_.size(), 0);
  if (to_.empty()) return;
  // A backward track that starts within fb_fine_start_px * 2^L of its feature needs no level coarser than L to
  // get there (a good prediction puts nearly all of them on the finest level); each level costs as much as the
  // finest one, so the tracks are grouped by the coarsest level they need.
  for (int level = 0; level <= levels; ++level) {
    const double reach_px = config_.fb_fine_start_px * double(1 << level);
    group_.clear();
    for (size_t k = 0; k < to_.size(); ++k) {
      if (back_status_[k] != 0) continue;  // tracked, or lost, on a finer level
      const cv::Point2f d = backward_[k] - from_[k];
      if (level == levels || (reach_px > 0.0 && d.x * d.x + d.y * d.y <= reach_px * reach_px))
        group_.push_back(static_cast<int>(k));
    }
    if (group_.empty()) continue;
    group_to_.resize(group_.size());
    group_start_.resize(group_.size());
    for (size_t g = 0; g < group_.size(); ++g) {
      group_to_[g] = to_[group_[g]];
      group_start_[g] = backward_[group_[g]];
    }
    computeDerivatives(from, group_to_, 0, 1, level);  // the finest level's are there around every track
    cv::calcOpticalFlowPyrLK(from->pyramid, to.pyramid, group_to_, group_start_, group_status_, error_, window_, level,
                             criteria, cv::OPTFLOW_USE_INITIAL_FLOW);
    for (size_t g = 0; g < group_.size(); ++g) {
      backward_[group_[g]] = group_start_[g];
      back_status_[group_[g]] = group_status_[g] ? 2 : 3;  // 2: tracked, 3: lost (a coarser level would not help)
    }
  }
  for (uchar& s : back_status_) s = s == 2;
}

void KltRegistrar::estimate(Frame* previous, Frame* current, const Eigen::Matrix3d& prediction_px,
                            MotionEstimate* result) {
  estimateFrom(previous, current, prediction_px, result);
  const FailureReason f = result->failure;
  if (!config_.coarse_search || !result->failed ||
      !(f == FailureReason::kTooFewTracks || f == FailureReason::kTooFewInliers || f == FailureReason::kInconsistent))
    return;
  diagnostics_.coarse_searched = true;
  const CoarseMotion coarse = coarseMotionSearch(previous->images[0], current->images[0], config_.coarse);
  diagnostics_.coarse_ms = coarse.elapsed_ms;
  if (!coarse.found) {
    result->failure_detail += "; no coarse search result either: " + coarse.detail;
    return;
  }
  // From (nearly) the same start the tracks would fail the same way.
  const int width = current->size.width, height = current->size.height;
  double moved_px = 0.0;
  for (const Eigen::Vector2d& corner : {Eigen::Vector2d(0.0, 0.0), Eigen::Vector2d(width - 1.0, 0.0),
                                        Eigen::Vector2d(0.0, height - 1.0), Eigen::Vector2d(width - 1.0, height - 1.0)})
    moved_px =
        std::max(moved_px, (transferPoint(coarse.pixel_matrix, corner) - transferPoint(prediction_px, corner)).norm());
  if (moved_px < config_.window_px / 2.0) {
    result->failure_detail += "; the coarse search agrees with the prediction (" + coarse.detail + ")";
    return;
  }
  diagnostics_.coarse_found = true;
  MotionEstimate retry = emptyEstimate(current->size);
  estimateFrom(previous, current, coarse.pixel_matrix, &retry);
  if (!retry.failed) {
    *result = retry;
    return;
  }
  result->failure_detail += "; tracked again from a coarse search (" + coarse.detail + "): " + toString(retry.failure) +
                            ": " + retry.failure_detail;
}

void KltRegistrar::estimateFrom(Frame* previous_frame, Frame* current, const Eigen::Matrix3d& prediction_px,
                                MotionEstimate* result) {
  const Frame& previous = *previous_frame;
  auto fail = [result](FailureReason reason, const std::string& detail) {
    result->failed = true;
    result->failure = reason;
    result->failure_detail = detail;
  };
  current->features.clear();
  if (!current->usable) return fail(FailureReason::kTooDark, "current image: " + current->unusable_detail);
  if (!previous.usable) return fail(FailureReason::kTooDark, "previous image: " + previous.unusable_detail);
  diagnostics_.features = static_cast<int>(previous.features.size());
  if (diagnostics_.features < config_.min_features)
    return fail(FailureReason::kTooLittleTexture, "previous image: " + std::to_string(diagnostics_.features) +
                                                      " features found (min_features " +
                                                      std::to_string(config_.min_features) + ")");

  // --- Forward tracking from where the prediction sends each feature, then backward from where the inverse
  // prediction sends each track: the two start from different places, so that a track that converged to a wrong
  // local minimum does not come back to its feature. A checked prediction lets most tracks skip the coarse levels
  // (trackForward); if too few tracks come back all the same, they are tracked again on the whole pyramid. ---
  Clock::time_point start = Clock::now();
  const int width = current->size.width, height = current->size.height;
  const std::vector<cv::Point2f>& features = previous.features;
  const int n = static_cast<int>(features.size());
  const int all_levels = std::min(previous.max_level, current->max_level);
  const cv::TermCriteria criteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, config_.lk_max_iterations,
                                  config_.lk_epsilon_px);
  const Eigen::Matrix3d inverse_prediction = prediction_px.inverse();
  const float fb_sq = static_cast<float>(config_.fb_threshold_px * config_.fb_threshold_px);
  size_t kept = 0;
  bool whole_pyramid = false;
  for (;;) {
    const int levels = trackForward(previous_frame, *current, prediction_px, all_levels, whole_pyramid, criteria);
    from_.clear();
    to_.clear();
    for (int i = 0; i < n; ++i) {
      const cv::Point2f& b = forward_[i];
      if (!status_[i] || !(b.x >= 0.0f && b.y >= 0.0f && b.x <= width - 1 && b.y <= height - 1)) continue;
      from_.push_back(features[i]);
      to_.push_back(b);
    }
    // The finest level's derivatives around to_: the backward pass reads them, the next pair around the inliers.
    computeDerivatives(current, to_, 0, 0, 0);
    backward_.resize(to_.size());
    for (size_t k = 0; k < to_.size(); ++k) backward_[k] = transfer(inverse_prediction, to_[k]);
    trackBackward(current, previous, levels, criteria);
    kept = 0;
    fb_.clear();
    for (size_t k = 0; k < to_.size(); ++k) {
      const cv::Point2f d = backward_[k] - from_[k];
      const float d_sq = d.x * d.x + d.y * d.y;
      if (!back_status_[k] || !(d_sq <= fb_sq)) continue;
      from_[kept] = from_[k];
      to_[kept++] = to_[k];
      fb_.push_back(std::sqrt(d_sq));
    }
    from_.resize(kept);
    to_.resize(kept);
    if (levels == all_levels || (static_cast<int>(kept) >= config_.min_tracks && kept >= config_.retrack_fraction * n))
      break;
    whole_pyramid = true;  // the prediction missed after all
    diagnostics_.retracked = true;
  }
  diagnostics_.tracked = static_cast<int>(kept);
  result->observations = static_cast<int>(kept);
  diagnostics_.track_ms += msSince(start);
  if (diagnostics_.tracked < config_.min_tracks)
    return fail(FailureReason::kTooFewTracks, std::to_string(diagnostics_.tracked) + " of " + std::to_string(n) +
                                                  " features tracked with a forward-backward error below " +
                                                  std::to_string(config_.fb_threshold_px) + " px (min_tracks " +
                                                  std::to_string(config_.min_tracks) + ")");

  // --- Robust least squares, the prediction as one of the initial hypotheses ---
  start = Clock::now();
  const Eigen::Vector2d& centre = result->centre_px;
  Eigen::VectorXd initial;
  if (!prediction_px.isIdentity(1e-12))
    initial = parametersFromPixelMatrix(config_.model, prediction_px, centre, width, height);
  RobustFit fit = fitter_.fit(from_, to_, centre, initial);
  diagnostics_.fit_ms += msSince(start);
  const bool one_plane =
      fit.local_scale_px <= config_.max_local_residual_px && fit.residual_scale_px <= config_.max_residual_px;
  // Per attempt (estimate() may retry from a coarse search): whether the rigid scene, not one plane, accepted it.
  bool rigid_scene = false;
  if (fit.ok && !one_plane && config_.model == MotionModel::kHomography) {
    rigid_scene = true;
    // Not one plane: relief (parallax along the epipolar lines) or tracks that move on their own. One rigid scene
    // tells them apart. (With a lower model a plane's perspective would pass as relief: its misfit is refused below.)
    start = Clock::now();
    const double sigma = trackingNoiseFromForwardBackward_px(fb_, config_.min_residual_scale_px);
    RigidSceneConfig rigid_config;
    rigid_config.k_sigma = config_.rigid_k_sigma;
    const RigidSceneCheck rigid = checkRigidScene(from_, to_, sigma, rigid_config);
    diagnostics_.rigid_checked = true;
    diagnostics_.rigid_consistent = rigid.consistent_count;
    diagnostics_.tracking_noise_px = sigma;
    std::ostringstream not_plane;
    not_plane << "neighbouring inliers disagree by " << fit.local_scale_px << " px (max_local_residual_px "
              << config_.max_local_residual_px << "), residual scale " << fit.residual_scale_px
              << " px (max_residual_px " << config_.max_residual_px << ")";
    if (!rigid.estimated || rigid.consistent_count < config_.min_inliers ||
        rigid.consistent_count < config_.min_inlier_fraction * static_cast<double>(kept)) {
      diagnostics_.fit_ms += msSince(start);
      return fail(FailureReason::kInconsistent, not_plane.str() + ", and " + rigid.detail +
                                                    ": the tracks do not move with one rigid scene (particles, fish?)");
    }
    // The dominant plane from the scene's tracks only.
    size_t n_scene = 0;
    for (size_t k = 0; k < kept; ++k) {
      if (!rigid.consistent[k]) continue;
      from_[n_scene] = from_[k];
      to_[n_scene++] = to_[k];
    }
    from_.resize(n_scene);
    to_.resize(n_scene);
    fit = fitter_.fit(from_, to_, centre, fit.parameters);
    diagnostics_.fit_ms += msSince(start);
  }
  diagnostics_.local_residual_px = fit.local_scale_px;
  result->parameters = fit.parameters;
  result->covariance = config_.covariance_inflation * fit.covariance;
  result->pixel_matrix = pixelMatrix(config_.model, fit.parameters, centre);
  result->inliers = fit.inliers;
  result->inlier_fraction = fit.inlier_fraction;
  result->residual_scale = fit.residual_scale_px;
  result->iterations = fit.iterations;
  if (!fit.ok) return fail(fit.failure, fit.failure_detail);

  // --- Acceptance: bounded motion, residuals consistent with tracking noise ---
  double largest_px = 0.0;
  for (const Eigen::Vector2d& corner : {Eigen::Vector2d(0.0, 0.0), Eigen::Vector2d(width - 1.0, 0.0),
                                        Eigen::Vector2d(0.0, height - 1.0), Eigen::Vector2d(width - 1.0, height - 1.0)})
    largest_px = std::max(largest_px, (transferPoint(result->pixel_matrix, corner) - corner).norm());
  const double bound_px = config_.max_motion_fraction * std::min(width, height);
  if (!(largest_px <= bound_px))
    return fail(FailureReason::kMotionTooLarge,
                "an image corner moves " + std::to_string(largest_px) + " px (max_motion_fraction " +
                    std::to_string(config_.max_motion_fraction) + " allows " + std::to_string(bound_px) + " px)");
  if (!rigid_scene && !(fit.residual_scale_px <= config_.max_residual_px))
    return fail(FailureReason::kInconsistent, "inlier residual scale " + std::to_string(fit.residual_scale_px) +
                                                  " px (max_residual_px " + std::to_string(config_.max_residual_px) +
                                                  "): the " + toString(config_.model) + " model does not fit");
  if (!rigid_scene && !(fit.local_scale_px <= config_.max_local_residual_px))
    return fail(FailureReason::kInconsistent, "neighbouring inliers disagree by " + std::to_string(fit.local_scale_px) +
                                                  " px (max_local_residual_px " +
                                                  std::to_string(config_.max_local_residual_px) +
                                                  "): the tracks do not move with one surface (particles?)");
  result->failed = false;
  result->failure = FailureReason::kNone;
  result->failure_detail.clear();
  // The inlier tracks are the next pair's features (the struck-off ones are on moving things or badly tracked),
  // measured against what the last detection left.
  for (size_t k = 0; k < to_.size(); ++k)
    if (fit.inlier_mask[k]) current->features.push_back(to_[k]);
  current->detected_features = previous.detected_features;
  current->detected_cells = previous.detected_cells;
  current->strongest_corner = previous.strongest_corner;
}

cv::Mat KltRegistrar::nextImageBuffer(const cv::Size& size) {
  if (current_.image_buffers.empty()) current_.image_buffers.resize(1);
  cv::Mat& buffer = current_.image_buffers[0];
  const cv::Size padded(size.width + 2 * window_.width, size.height + 2 * window_.height);
  if (buffer.size() != padded || buffer.type() != CV_8UC1) buffer.create(padded, CV_8UC1);
  return buffer(cv::Rect(window_.width, window_.height, size.width, size.height));
}

MotionEstimate KltRegistrar::registerNext(const cv::Mat& gray, const Eigen::Matrix3d& prediction_px) {
  const Clock::time_point start = Clock::now();
  diagnostics_ = KltDiagnostics();
  MotionEstimate result = emptyEstimate(gray.size());
  if (gray.empty() || gray.type() != CV_8UC1) {
    result.failure = FailureReason::kInvalidInput;
    result.failure_detail = gray.empty()
                                ? "empty image"
                                : "image type " + cv::typeToString(gray.type()) + ", expected CV_8UC1 (8-bit grey)";
    result.elapsed_ms = msSince(start);
    return result;
  }
  prepare(gray, &current_);
  if (!has_previous_) {
    result.failure = FailureReason::kNoPreviousFrame;
    result.failure_detail = "first image after a reset";
  } else if (current_.size != previous_.size) {
    result.failure = FailureReason::kInvalidInput;
    result.failure_detail =
        "image size " + sizeString(current_.size) + " differs from the previous image's " + sizeString(previous_.size);
  } else {
    estimate(&previous_, &current_, prediction_px, &result);
  }
  // A failed pair leaves no features: detect afresh. Otherwise only top up when the tracks have thinned out.
  if (current_.usable && (result.failed || needsDetection(current_))) topUpFeatures(&current_);
  std::swap(previous_, current_);
  has_previous_ = true;
  result.elapsed_ms = msSince(start);
  return result;
}

MotionEstimate KltRegistrar::registerPair(const cv::Mat& previous, const cv::Mat& current,
                                          const Eigen::Matrix3d& prediction_px) {
  const Clock::time_point start = Clock::now();
  diagnostics_ = KltDiagnostics();
  MotionEstimate result = emptyEstimate(current.size());
  std::string invalid;
  for (const cv::Mat* image : {&previous, &current}) {
    if (image->empty())
      invalid = "empty image";
    else if (image->type() != CV_8UC1)
      invalid = "image type " + cv::typeToString(image->type()) + ", expected CV_8UC1 (8-bit grey)";
  }
  if (invalid.empty() && previous.size() != current.size())
    invalid = "image sizes differ: " + sizeString(previous.size()) + " and " + sizeString(current.size());
  if (!invalid.empty()) {
    result.failure = FailureReason::kInvalidInput;
    result.failure_detail = invalid;
    result.elapsed_ms = msSince(start);
    return result;
  }
  Frame a, b;
  prepare(previous, &a);
  if (a.usable) topUpFeatures(&a);
  prepare(current, &b);
  estimate(&a, &b, prediction_px, &result);
  result.elapsed_ms = msSince(start);
  return result;
}

}  // namespace registration
}  // namespace exocet_mosaic
