#include "exocet_mosaic/registration/coarse_motion_search.h"

#include <chrono>
#include <sstream>
#include <stdexcept>
#include <vector>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "exocet_mosaic/registration/sift_reference.h"

namespace exocet_mosaic {
namespace registration {

std::string CoarseSearchConfig::validate() const {
  std::ostringstream errors;
  auto check = [&errors](bool ok, const char* name, const char* range) {
    if (!ok) errors << (errors.tellp() > 0 ? "; " : "") << name << " must be in " << range;
  };
  check(width_px >= 64 && width_px <= 100000, "width_px", "[64, 100000]");
  check(max_features >= 20 && max_features <= 100000, "max_features", "[20, 100000]");
  check(contrast_threshold > 0.0 && contrast_threshold < 1.0, "contrast_threshold", "(0, 1)");
  check(ratio > 0.0 && ratio <= 1.0, "ratio", "(0, 1]");
  check(ransac_px > 0.0 && ransac_px <= 50.0, "ransac_px", "(0, 50]");
  check(min_inliers >= 3 && min_inliers <= 100000, "min_inliers", "[3, 100000]");
  check(min_inlier_fraction >= 0.0 && min_inlier_fraction <= 1.0, "min_inlier_fraction", "[0, 1]");
  return errors.str();
}

CoarseMotion coarseMotionSearch(const cv::Mat& a, const cv::Mat& b, const CoarseSearchConfig& config) {
  const std::string invalid = config.validate();
  if (!invalid.empty()) throw std::invalid_argument("coarse motion search: " + invalid);
  const auto start = std::chrono::steady_clock::now();
  CoarseMotion out;
  auto done = [&out, &start](std::string detail) {
    out.detail = std::move(detail);
    out.elapsed_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    return out;
  };
  if (a.empty() || b.empty() || a.type() != CV_8UC1 || b.type() != CV_8UC1 || a.size() != b.size())
    return done("the images must be 8-bit grey and of one size");
  const double scale = std::min(1.0, static_cast<double>(config.width_px) / a.cols);
  cv::Mat small_a = a, small_b = b;
  if (scale < 1.0) {
    cv::resize(a, small_a, cv::Size(), scale, scale, cv::INTER_AREA);
    cv::resize(b, small_b, cv::Size(), scale, scale, cv::INTER_AREA);
  }
  std::vector<cv::Point2f> pa, pb;
  const int features =
      siftRatioMatches(small_a, small_b, config.max_features, config.contrast_threshold, config.ratio, &pa, &pb);
  if (features < 2) return done("too few SIFT features (" + std::to_string(features) + ")");
  out.matches = static_cast<int>(pa.size());
  if (out.matches < config.min_inliers)
    return done(std::to_string(out.matches) + " SIFT matches (min_inliers " + std::to_string(config.min_inliers) + ")");
  std::vector<uchar> mask;
  // A similarity: four parameters that a handful of matches pin down, and what a downward camera mostly does between
  // two images; KLT's own model takes over from it.
  const cv::Mat m = cv::estimateAffinePartial2D(pa, pb, mask, cv::RANSAC, config.ransac_px, 5000, 0.999, 10);
  if (m.empty()) return done("RANSAC found no similarity among " + std::to_string(out.matches) + " matches");
  out.inliers = cv::countNonZero(mask);
  if (out.inliers < config.min_inliers || out.inliers < config.min_inlier_fraction * out.matches)
    return done(std::to_string(out.inliers) + " of " + std::to_string(out.matches) +
                " matches agree on one similarity (min_inliers " + std::to_string(config.min_inliers) + ")");
  Eigen::Matrix3d small = Eigen::Matrix3d::Identity();
  for (int r = 0; r < 2; ++r)
    for (int c = 0; c < 3; ++c) small(r, c) = m.at<double>(r, c);
  // Pixel centres: x_small = s (x + 0.5) - 0.5.
  Eigen::Matrix3d to_small = Eigen::Matrix3d::Identity();
  to_small(0, 0) = to_small(1, 1) = scale;
  to_small(0, 2) = to_small(1, 2) = 0.5 * scale - 0.5;
  out.pixel_matrix = to_small.inverse() * small * to_small;
  out.found = true;
  std::ostringstream what;
  what << out.inliers << " of " << out.matches << " SIFT matches on " << small_a.cols << "x" << small_a.rows
       << " copies agree on a shift of (" << out.pixel_matrix(0, 2) << ", " << out.pixel_matrix(1, 2) << ") px";
  return done(what.str());
}

}  // namespace registration
}  // namespace exocet_mosaic
