#include "exocet_mosaic/registration/sift_reference.h"

#include <algorithm>
#include <vector>

#include <opencv2/calib3d.hpp>
#include <opencv2/features2d.hpp>

namespace exocet_mosaic {
namespace registration {

int siftRatioMatches(const cv::Mat& a, const cv::Mat& b, int max_features, double contrast_threshold, double ratio,
                     std::vector<cv::Point2f>* pa, std::vector<cv::Point2f>* pb) {
  pa->clear();
  pb->clear();
  cv::Ptr<cv::SIFT> sift = cv::SIFT::create(max_features, 3, contrast_threshold, 10.0, 1.6);
  std::vector<cv::KeyPoint> ka, kb;
  cv::Mat da, db;
  sift->detectAndCompute(a, cv::noArray(), ka, da);
  sift->detectAndCompute(b, cv::noArray(), kb, db);
  if (da.rows < 2 || db.rows < 2) return std::min(da.rows, db.rows);
  std::vector<std::vector<cv::DMatch>> knn;
  cv::BFMatcher(cv::NORM_L2).knnMatch(da, db, knn, 2);
  for (const auto& m : knn)
    if (m.size() == 2 && m[0].distance < ratio * m[1].distance) {
      pa->push_back(ka[m[0].queryIdx].pt);
      pb->push_back(kb[m[0].trainIdx].pt);
    }
  return std::min(da.rows, db.rows);
}

SiftReference siftReferenceHomography(const cv::Mat& a, const cv::Mat& b) {
  SiftReference ref;
  // A low contrast threshold: seabed texture is faint, and the default (0.04) keeps only a few dozen points of a
  // 384x288 Sparus frame, too few for a sub-pixel reference; 0.005 keeps about two thousand.
  std::vector<cv::Point2f> pa, pb;
  siftRatioMatches(a, b, 0, 0.005, 0.8, &pa, &pb);
  ref.matches = int(pa.size());
  if (pa.size() < 20) return ref;
  cv::Mat mask;
  // MAGSAC++ (OpenCV's USAC), the RANSAC whose model does not hinge on one inlier threshold: on the Sparus frames
  // the classic RANSAC's homography moves a corner by up to 1.2 px from one run or threshold to another, MAGSAC++'s
  // by 0.15 px (median), which makes it a reference that can judge sub-pixel estimates.
  const cv::Mat h = cv::findHomography(pa, pb, cv::USAC_MAGSAC, 1.0, mask, 10000, 0.9999);
  if (h.empty()) return ref;
  ref.inliers = cv::countNonZero(mask);
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) ref.pixel_matrix(r, c) = h.at<double>(r, c);
  ref.found = ref.inliers >= 20;
  return ref;
}

}  // namespace registration
}  // namespace exocet_mosaic
