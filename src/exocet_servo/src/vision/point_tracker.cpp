#include "exocet_servo/vision/point_tracker.h"

#include <algorithm>
#include <sstream>
#include <stdexcept>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

namespace exocet_servo {
namespace vision {

std::string TrackerConfig::validate() const {
  std::ostringstream errors;
  auto check = [&errors](bool ok, const char* field, const std::string& range) {
    if (ok) return;
    if (errors.tellp() > 0) errors << "; ";
    errors << field << " must be in " << range;
  };
  check(window_px >= 5 && window_px <= 63 && window_px % 2 == 1, "window_px", "odd values of [5, 63]");
  check(pyramid_levels >= 0 && pyramid_levels <= 8, "pyramid_levels", "[0, 8]");
  check(max_iterations >= 1 && max_iterations <= 100, "max_iterations", "[1, 100]");
  check(epsilon_px > 0.0 && epsilon_px <= 1.0, "epsilon_px", "(0, 1]");
  check(max_fb_error_px > 0.0 && max_fb_error_px <= 20.0, "max_fb_error_px", "(0, 20]");
  check(border_px >= 0.0 && border_px <= 1000.0, "border_px", "[0, 1000]");
  check(min_points >= 4 && min_points <= 100000, "min_points", "[4, 100000]");
  return errors.str();
}

PointTracker::PointTracker(const TrackerConfig& config) : config_(config) {
  const std::string errors = config.validate();
  if (!errors.empty()) throw std::invalid_argument("TrackerConfig: " + errors);
}

std::vector<cv::Mat> PointTracker::pyramid(const cv::Mat& image) const {
  std::vector<cv::Mat> pyr;
  cv::buildOpticalFlowPyramid(image, pyr, cv::Size(config_.window_px, config_.window_px), config_.pyramid_levels);
  return pyr;
}

void PointTracker::reset(const cv::Mat& image, const std::vector<cv::Point2f>& points_px, const std::vector<int>& ids) {
  if (points_px.size() != ids.size())
    throw std::invalid_argument("PointTracker::reset: " + std::to_string(points_px.size()) + " points for " +
                                std::to_string(ids.size()) + " ids");
  previous_pyramid_ = pyramid(image);
  image_size_ = image.size();
  points_ = points_px;
  ids_ = ids;
}

int PointTracker::track(const cv::Mat& next_image) {
  std::vector<cv::Mat> next = pyramid(next_image);
  if (points_.empty() || previous_pyramid_.empty() || next_image.size() != image_size_) {
    points_.clear();
    ids_.clear();
    previous_pyramid_ = std::move(next);
    image_size_ = next_image.size();
    return 0;
  }
  const cv::Size window(config_.window_px, config_.window_px);
  const cv::TermCriteria criteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, config_.max_iterations,
                                  config_.epsilon_px);
  std::vector<cv::Point2f> forward, backward;
  std::vector<uchar> status_f, status_b;
  std::vector<float> err;
  cv::calcOpticalFlowPyrLK(previous_pyramid_, next, points_, forward, status_f, err, window, config_.pyramid_levels,
                           criteria);
  // Backward from the forward result, started there (not at the expected answer, which would bias the check).
  cv::calcOpticalFlowPyrLK(next, previous_pyramid_, forward, backward, status_b, err, window, config_.pyramid_levels,
                           criteria);
  keepConsistent(points_, forward, backward, status_f, status_b, nullptr);
  previous_pyramid_ = std::move(next);
  return static_cast<int>(points_.size());
}

int PointTracker::anchorOnReference(const cv::Mat& reference_image, const std::vector<cv::Point2f>& reference_px,
                                    const cv::Mat& current_image, double max_affine_residual_px) {
  if (points_.size() < 6 || reference_image.empty() || current_image.size() != image_size_) return -1;
  // Replaces track() on this image: the next track() starts from it.
  previous_pyramid_ = pyramid(current_image);
  std::vector<cv::Point2f> ref;
  ref.reserve(points_.size());
  for (int id : ids_) {
    if (id < 0 || id >= static_cast<int>(reference_px.size()))
      throw std::invalid_argument("PointTracker::anchorOnReference: id " + std::to_string(id) + " has no reference");
    ref.push_back(reference_px[id]);
  }
  std::vector<uchar> inlier;
  const cv::Mat affine = cv::estimateAffine2D(ref, points_, inlier, cv::RANSAC, max_affine_residual_px);
  if (affine.empty()) return -1;
  cv::Mat warped;
  cv::warpAffine(reference_image, warped, affine, image_size_, cv::INTER_CUBIC, cv::BORDER_REPLICATE);
  std::vector<cv::Point2f> templ;
  cv::transform(ref, templ, affine);
  const cv::Size window(config_.window_px, config_.window_px);
  const cv::TermCriteria criteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, config_.max_iterations,
                                  config_.epsilon_px);
  // Forward from the warped reference, starting at the last positions (the motion since is small near convergence:
  // two levels suffice); backward from there to the template.
  const int levels = std::min(config_.pyramid_levels, 2);
  std::vector<cv::Point2f> forward = points_, backward;
  std::vector<uchar> status_f, status_b;
  std::vector<float> err;
  cv::calcOpticalFlowPyrLK(warped, previous_pyramid_, templ, forward, status_f, err, window, levels, criteria,
                           cv::OPTFLOW_USE_INITIAL_FLOW);
  cv::calcOpticalFlowPyrLK(previous_pyramid_, warped, forward, backward, status_b, err, window, levels, criteria);
  keepConsistent(templ, forward, backward, status_f, status_b, &inlier);
  return static_cast<int>(points_.size());
}

void PointTracker::keepConsistent(const std::vector<cv::Point2f>& origin, const std::vector<cv::Point2f>& forward,
                                  const std::vector<cv::Point2f>& backward, const std::vector<uchar>& status_f,
                                  const std::vector<uchar>& status_b, const std::vector<uchar>* inlier) {
  const float max_fb2 = static_cast<float>(config_.max_fb_error_px * config_.max_fb_error_px);
  const float b = static_cast<float>(config_.border_px);
  std::vector<cv::Point2f> kept;
  std::vector<int> kept_ids;
  for (size_t i = 0; i < points_.size(); ++i) {
    if ((inlier && !(*inlier)[i]) || !status_f[i] || !status_b[i]) continue;
    const cv::Point2f d = backward[i] - origin[i];
    if (d.dot(d) > max_fb2) continue;
    const cv::Point2f& p = forward[i];
    if (p.x < b || p.y < b || p.x > image_size_.width - 1 - b || p.y > image_size_.height - 1 - b) continue;
    kept.push_back(p);
    kept_ids.push_back(ids_[i]);
  }
  points_ = std::move(kept);
  ids_ = std::move(kept_ids);
}

}  // namespace vision
}  // namespace exocet_servo
