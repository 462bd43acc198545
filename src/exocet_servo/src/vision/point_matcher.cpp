#include "exocet_servo/vision/point_matcher.h"

#include <sstream>
#include <stdexcept>

#include <opencv2/calib3d.hpp>

namespace exocet_servo {
namespace vision {

std::string MatcherConfig::validate() const {
  std::ostringstream errors;
  auto check = [&errors](bool ok, const char* field, const std::string& range) {
    if (ok) return;
    if (errors.tellp() > 0) errors << "; ";
    errors << field << " must be in " << range;
  };
  check(max_features >= 8 && max_features <= 100000, "max_features", "[8, 100000]");
  check(ratio > 0.0 && ratio <= 1.0, "ratio", "(0, 1]");
  check(ransac_threshold_px > 0.0 && ransac_threshold_px <= 20.0, "ransac_threshold_px", "(0, 20]");
  check(ransac_confidence > 0.0 && ransac_confidence < 1.0, "ransac_confidence", "(0, 1)");
  check(min_matches >= 8 && min_matches <= 100000, "min_matches", "[8, 100000]");
  check(duplicate_distance_px >= 0.0 && duplicate_distance_px <= 10.0, "duplicate_distance_px", "[0, 10]");
  return errors.str();
}

PointMatcher::PointMatcher(const MatcherConfig& config) : config_(config) {
  const std::string errors = config.validate();
  if (!errors.empty()) throw std::invalid_argument("MatcherConfig: " + errors);
  sift_ = cv::SIFT::create(config.max_features);
}

std::string PointMatcher::setReference(const cv::Mat& image) {
  reference_keypoints_.clear();
  reference_descriptors_.release();
  if (image.empty() || image.type() != CV_8UC1) return "reference image must be a non-empty 8-bit gray image";
  sift_->detectAndCompute(image, cv::noArray(), reference_keypoints_, reference_descriptors_);
  if (static_cast<int>(reference_keypoints_.size()) < config_.min_matches) {
    std::ostringstream msg;
    msg << "reference image has " << reference_keypoints_.size() << " SIFT keypoints, fewer than min_matches "
        << config_.min_matches;
    reference_keypoints_.clear();
    reference_descriptors_.release();
    return msg.str();
  }
  return "";
}

PointMatches PointMatcher::match(const cv::Mat& image) const {
  PointMatches out;
  out.reference_keypoints = static_cast<int>(reference_keypoints_.size());
  if (reference_keypoints_.empty()) {
    out.error = "no reference: call setReference() with a textured image first";
    return out;
  }
  if (image.empty() || image.type() != CV_8UC1) {
    out.error = "current image must be a non-empty 8-bit gray image";
    return out;
  }
  std::vector<cv::KeyPoint> keypoints;
  cv::Mat descriptors;
  sift_->detectAndCompute(image, cv::noArray(), keypoints, descriptors);
  out.current_keypoints = static_cast<int>(keypoints.size());
  if (keypoints.size() < 8) {
    out.error = "current image has " + std::to_string(keypoints.size()) + " SIFT keypoints (needs 8)";
    return out;
  }
  cv::BFMatcher matcher(cv::NORM_L2);
  std::vector<std::vector<cv::DMatch>> forward;
  matcher.knnMatch(reference_descriptors_, descriptors, forward, 2);
  std::vector<int> backward_best(keypoints.size(), -1);
  if (config_.cross_check) {
    std::vector<cv::DMatch> backward;
    matcher.match(descriptors, reference_descriptors_, backward);
    for (const auto& m : backward) backward_best[m.queryIdx] = m.trainIdx;
  }
  std::vector<cv::Point2f> ref, cur;
  for (const auto& knn : forward) {
    if (knn.size() < 2 || knn[0].distance > config_.ratio * knn[1].distance) continue;
    if (config_.cross_check && backward_best[knn[0].trainIdx] != knn[0].queryIdx) continue;
    ref.push_back(reference_keypoints_[knn[0].queryIdx].pt);
    cur.push_back(keypoints[knn[0].trainIdx].pt);
  }
  out.ratio_matches = static_cast<int>(ref.size());
  if (static_cast<int>(ref.size()) < std::max(8, config_.min_matches)) {
    out.error = "only " + std::to_string(ref.size()) + " SIFT matches pass the ratio test (min_matches " +
                std::to_string(config_.min_matches) + ")";
    return out;
  }
  std::vector<uchar> inlier;
  const cv::Mat f =
      cv::findFundamentalMat(ref, cur, cv::FM_RANSAC, config_.ransac_threshold_px, config_.ransac_confidence, inlier);
  if (f.empty()) {
    out.error = "no fundamental matrix found from " + std::to_string(ref.size()) + " matches";
    return out;
  }
  const float dup2 = static_cast<float>(config_.duplicate_distance_px * config_.duplicate_distance_px);
  auto near = [dup2](const cv::Point2f& a, const cv::Point2f& b) {
    const cv::Point2f d = a - b;
    return d.dot(d) <= dup2;
  };
  for (size_t i = 0; i < ref.size(); ++i) {
    if (!inlier[i]) continue;
    bool duplicate = false;  // SIFT gives one keypoint per dominant orientation at the same place
    for (size_t j = 0; j < out.reference_px.size() && !duplicate; ++j)
      duplicate = near(ref[i], out.reference_px[j]) || near(cur[i], out.current_px[j]);
    if (duplicate) continue;
    out.reference_px.push_back(ref[i]);
    out.current_px.push_back(cur[i]);
  }
  if (static_cast<int>(out.reference_px.size()) < config_.min_matches) {
    out.error = "only " + std::to_string(out.reference_px.size()) + " SIFT matches survive RANSAC (min_matches " +
                std::to_string(config_.min_matches) + ")";
  }
  return out;
}

}  // namespace vision
}  // namespace exocet_servo
