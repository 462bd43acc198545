#include "exocet_mosaic/selfcal/feature_track_builder.h"

#include <algorithm>
#include <cmath>
#include <iterator>
#include <set>
#include <sstream>
#include <stdexcept>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

namespace exocet_mosaic {
namespace selfcal {

std::string TrackerConfig::validate() const {
  std::ostringstream err;
  if (step < 1) err << "step = " << step << " must be >= 1; ";
  if (max_corners < 50 || max_corners > 20000) err << "max_corners = " << max_corners << " out of range [50, 20000]; ";
  if (!(quality_level > 0.0 && quality_level < 1.0))
    err << "quality_level = " << quality_level << " out of range (0, 1); ";
  if (!(min_distance_px >= 1.0)) err << "min_distance_px = " << min_distance_px << " must be >= 1; ";
  if (window_px < 5 || window_px > 101 || window_px % 2 == 0)
    err << "window_px = " << window_px << " must be odd in [5, 101]; ";
  if (pyramid_levels < 0 || pyramid_levels > 6)
    err << "pyramid_levels = " << pyramid_levels << " out of range [0, 6]; ";
  if (!(forward_backward_px > 0.0)) err << "forward_backward_px = " << forward_backward_px << " must be > 0; ";
  if (!(border_px >= 0.0)) err << "border_px = " << border_px << " must be >= 0; ";
  if (min_shared_tracks < 8) err << "min_shared_tracks = " << min_shared_tracks << " must be >= 8; ";
  if (!(anchor_max_shift_px > 0.0)) err << "anchor_max_shift_px = " << anchor_max_shift_px << " must be > 0; ";
  std::string s = err.str();
  if (!s.empty()) s.resize(s.size() - 2);
  return s;
}

FeatureTrackBuilder::FeatureTrackBuilder(const TrackerConfig& config) : config_(config) {
  const std::string problem = config_.validate();
  if (!problem.empty()) throw std::invalid_argument("tracker: " + problem);
}

void FeatureTrackBuilder::addFrame(const cv::Mat& gray) {
  if (gray.empty() || gray.type() != CV_8UC1)
    throw std::invalid_argument("frame " + std::to_string(frame_count_) + ": expected a non-empty 8-bit grey image");
  if (frame_count_ == 0) {
    image_size_ = gray.size();
  } else if (gray.size() != image_size_) {
    throw std::invalid_argument("frame " + std::to_string(frame_count_) + " is " + std::to_string(gray.cols) + "x" +
                                std::to_string(gray.rows) + ", the sequence started at " +
                                std::to_string(image_size_.width) + "x" + std::to_string(image_size_.height));
  }
  const cv::Size window(config_.window_px, config_.window_px);
  std::vector<cv::Mat> pyramid;
  cv::buildOpticalFlowPyramid(gray, pyramid, window, config_.pyramid_levels);
  if (frame_count_ > 0) trackInto(pyramid);
  const bool key_frame = frame_count_ % config_.step == 0;
  if (key_frame && config_.anchor_to_birth) anchorToBirth(gray);
  // Corners are topped up at every key frame (so that each key frame starts tracks) and whenever many were lost.
  if (key_frame || static_cast<int>(live_points_.size()) < (3 * config_.max_corners) / 4) addCorners(gray);
  if (key_frame) {
    std::unordered_map<int, cv::Point2f> points;
    points.reserve(live_points_.size());
    for (size_t k = 0; k < live_points_.size(); ++k) points.emplace(live_ids_[k], live_points_[k]);
    key_points_.push_back(std::move(points));
  }
  // Forget the birth images no live track refers to any more.
  if (config_.anchor_to_birth) {
    std::set<int> referenced(live_birth_frames_.begin(), live_birth_frames_.end());
    for (auto it = birth_images_.begin(); it != birth_images_.end();)
      it = referenced.count(it->first) ? std::next(it) : birth_images_.erase(it);
  }
  previous_pyramid_ = std::move(pyramid);
  ++frame_count_;
}

void FeatureTrackBuilder::keepTracks(const std::vector<bool>& keep) {
  size_t kept = 0;
  for (size_t k = 0; k < live_points_.size(); ++k) {
    if (!keep[k]) continue;
    live_points_[kept] = live_points_[k];
    live_ids_[kept] = live_ids_[k];
    live_birth_frames_[kept] = live_birth_frames_[k];
    live_birth_points_[kept] = live_birth_points_[k];
    ++kept;
  }
  live_points_.resize(kept);
  live_ids_.resize(kept);
  live_birth_frames_.resize(kept);
  live_birth_points_.resize(kept);
}

void FeatureTrackBuilder::trackInto(const std::vector<cv::Mat>& pyramid) {
  if (live_points_.empty()) return;
  const cv::Size window(config_.window_px, config_.window_px);
  const cv::TermCriteria criteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 30, 0.01);
  std::vector<cv::Point2f> forward, backward;
  std::vector<uchar> status, back_status;
  std::vector<float> error;
  cv::calcOpticalFlowPyrLK(previous_pyramid_, pyramid, live_points_, forward, status, error, window,
                           config_.pyramid_levels, criteria);
  backward = live_points_;  // initial guess of the way back: where the points started
  cv::calcOpticalFlowPyrLK(pyramid, previous_pyramid_, forward, backward, back_status, error, window,
                           config_.pyramid_levels, criteria, cv::OPTFLOW_USE_INITIAL_FLOW);
  const float fb_sq = static_cast<float>(config_.forward_backward_px * config_.forward_backward_px);
  const float border = static_cast<float>(config_.border_px);
  const float max_x = image_size_.width - 1 - border, max_y = image_size_.height - 1 - border;
  std::vector<bool> keep(live_points_.size(), false);
  for (size_t k = 0; k < live_points_.size(); ++k) {
    const cv::Point2f& p = forward[k];
    const cv::Point2f d = backward[k] - live_points_[k];
    if (!status[k] || !back_status[k] || !(d.dot(d) <= fb_sq)) continue;
    if (!(p.x >= border && p.y >= border && p.x <= max_x && p.y <= max_y)) continue;
    live_points_[k] = p;
    keep[k] = true;
  }
  keepTracks(keep);
}

void FeatureTrackBuilder::anchorToBirth(const cv::Mat& gray) {
  std::map<int, std::vector<size_t>> by_birth;
  for (size_t k = 0; k < live_points_.size(); ++k)
    if (live_birth_frames_[k] != frame_count_) by_birth[live_birth_frames_[k]].push_back(k);
  std::vector<bool> keep(live_points_.size(), true);
  const cv::Size window(config_.window_px, config_.window_px);
  const cv::TermCriteria criteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 30, 0.005);
  const double max_shift_sq = config_.anchor_max_shift_px * config_.anchor_max_shift_px;
  for (const auto& [birth, members] : by_birth) {
    const auto image = birth_images_.find(birth);
    if (image == birth_images_.end() || members.size() < 8) continue;
    std::vector<cv::Point2f> from, to;
    for (size_t k : members) {
      from.push_back(live_birth_points_[k]);
      to.push_back(live_points_[k]);
    }
    // The seabed's dominant plane: warping the birth frame by it undoes the rotation and scale change.
    const cv::Mat h = cv::findHomography(from, to, cv::RANSAC, 3.0);
    if (h.empty()) continue;
    cv::Mat warped;
    cv::warpPerspective(image->second, warped, h, gray.size(), cv::INTER_LINEAR, cv::BORDER_REPLICATE);
    std::vector<cv::Point2f> in_warped, refined = to;
    cv::perspectiveTransform(from, in_warped, h);
    std::vector<uchar> status;
    std::vector<float> error;
    cv::calcOpticalFlowPyrLK(warped, gray, in_warped, refined, status, error, window, 1, criteria,
                             cv::OPTFLOW_USE_INITIAL_FLOW);
    for (size_t m = 0; m < members.size(); ++m) {
      const size_t k = members[m];
      const cv::Point2f d = refined[m] - to[m];
      if (!status[m] || !(d.dot(d) <= max_shift_sq)) {
        keep[k] = false;
        continue;
      }
      live_points_[k] = refined[m];
    }
  }
  keepTracks(keep);
}

void FeatureTrackBuilder::addCorners(const cv::Mat& gray) {
  const int wanted = config_.max_corners - static_cast<int>(live_points_.size());
  if (wanted <= 0) return;
  // Corners near a live track would duplicate it: mask discs around the live tracks.
  cv::Mat mask(gray.size(), CV_8UC1, cv::Scalar(255));
  const int margin = static_cast<int>(std::ceil(config_.border_px + config_.window_px / 2.0));
  mask.rowRange(0, std::min(margin, mask.rows)).setTo(0);
  mask.rowRange(std::max(0, mask.rows - margin), mask.rows).setTo(0);
  mask.colRange(0, std::min(margin, mask.cols)).setTo(0);
  mask.colRange(std::max(0, mask.cols - margin), mask.cols).setTo(0);
  const int radius = static_cast<int>(std::ceil(config_.min_distance_px));
  for (const cv::Point2f& p : live_points_) cv::circle(mask, cv::Point(cvRound(p.x), cvRound(p.y)), radius, 0, -1);
  std::vector<cv::Point2f> corners;
  cv::goodFeaturesToTrack(gray, corners, wanted, config_.quality_level, config_.min_distance_px, mask, 5);
  if (corners.empty()) return;
  cv::cornerSubPix(gray, corners, cv::Size(3, 3), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 20, 0.01));
  for (const cv::Point2f& c : corners) {
    live_points_.push_back(c);
    live_ids_.push_back(next_track_id_++);
    live_birth_frames_.push_back(frame_count_);
    live_birth_points_.push_back(c);
  }
  if (config_.anchor_to_birth) birth_images_[frame_count_] = gray.clone();
}

std::vector<KeyFramePair> FeatureTrackBuilder::keyFramePairs() const {
  std::vector<KeyFramePair> pairs;
  const int n = keyFrameCount();
  for (int a = 0; a < n; ++a) {
    for (int b = a + 1; b < n; ++b) {
      const auto& pa = key_points_[a];
      const auto& pb = key_points_[b];
      // Tracks die and never come back: if b shares too few with a, so do all later key frames.
      KeyFramePair pair;
      pair.key_a = a;
      pair.key_b = b;
      pair.frame_a = a * config_.step;
      pair.frame_b = b * config_.step;
      for (const auto& [id, point_b] : pb) {
        const auto it = pa.find(id);
        if (it == pa.end()) continue;
        pair.track_ids.push_back(id);
        pair.points_a.emplace_back(it->second.x, it->second.y);
        pair.points_b.emplace_back(point_b.x, point_b.y);
      }
      if (static_cast<int>(pair.track_ids.size()) < config_.min_shared_tracks) break;
      // Deterministic order whatever the hash map's.
      std::vector<size_t> order(pair.track_ids.size());
      for (size_t k = 0; k < order.size(); ++k) order[k] = k;
      std::sort(order.begin(), order.end(), [&](size_t x, size_t y) { return pair.track_ids[x] < pair.track_ids[y]; });
      KeyFramePair sorted = pair;
      for (size_t k = 0; k < order.size(); ++k) {
        sorted.track_ids[k] = pair.track_ids[order[k]];
        sorted.points_a[k] = pair.points_a[order[k]];
        sorted.points_b[k] = pair.points_b[order[k]];
      }
      pairs.push_back(std::move(sorted));
    }
  }
  return pairs;
}

}  // namespace selfcal
}  // namespace exocet_mosaic
