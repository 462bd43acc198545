#include "exocet_stereo/geometry/feature_matching.h"

#include <sstream>
#include <stdexcept>

#include <opencv2/imgproc.hpp>

namespace exocet_stereo {
namespace geometry {

std::string SiftMatchingConfig::validate() const {
  std::ostringstream errors;
  auto check = [&errors](bool ok, const char* field, const char* range) {
    if (ok) return;
    if (errors.tellp() > 0) errors << "; ";
    errors << field << " must be in " << range;
  };
  check(max_features >= 16 && max_features <= 100000, "max_features", "[16, 100000]");
  check(contrast_threshold > 0.0 && contrast_threshold < 1.0, "contrast_threshold", "(0, 1)");
  check(edge_threshold >= 1.0 && edge_threshold <= 100.0, "edge_threshold", "[1, 100]");
  check(ratio > 0.0 && ratio <= 1.0, "ratio", "(0, 1]");
  return errors.str();
}

ImageFeatures detectSift(const cv::Mat& image, const SiftMatchingConfig& config) {
  const std::string error = config.validate();
  if (!error.empty()) throw std::invalid_argument("SiftMatchingConfig: " + error);
  if (image.empty()) throw std::invalid_argument("detectSift: the image is empty");
  cv::Mat gray = image;
  if (image.channels() == 3) cv::cvtColor(image, gray, cv::COLOR_BGR2GRAY);
  if (image.channels() == 4) cv::cvtColor(image, gray, cv::COLOR_BGRA2GRAY);
  auto sift = cv::SIFT::create(config.max_features, 3, config.contrast_threshold, config.edge_threshold);
  ImageFeatures features;
  sift->detectAndCompute(gray, cv::noArray(), features.keypoints, features.descriptors);
  return features;
}

std::vector<cv::DMatch> matchSift(const ImageFeatures& a, const ImageFeatures& b, const SiftMatchingConfig& config) {
  const std::string error = config.validate();
  if (!error.empty()) throw std::invalid_argument("SiftMatchingConfig: " + error);
  std::vector<cv::DMatch> kept;
  if (a.keypoints.size() < 2 || b.keypoints.size() < 2) return kept;
  cv::BFMatcher matcher(cv::NORM_L2);
  std::vector<std::vector<cv::DMatch>> forward;
  matcher.knnMatch(a.descriptors, b.descriptors, forward, 2);
  // The mutual check needs only the best match of each b descriptor in a.
  std::vector<cv::DMatch> backward;
  if (config.mutual) matcher.match(b.descriptors, a.descriptors, backward);
  for (const auto& candidates : forward) {
    if (candidates.size() < 2) continue;
    const cv::DMatch& best = candidates[0];
    if (best.distance >= config.ratio * candidates[1].distance) continue;
    if (config.mutual && backward[best.trainIdx].trainIdx != best.queryIdx) continue;
    kept.push_back(best);
  }
  return kept;
}

}  // namespace geometry
}  // namespace exocet_stereo
