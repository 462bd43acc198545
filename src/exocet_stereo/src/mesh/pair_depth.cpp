#include "exocet_stereo/mesh/pair_depth.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include <opencv2/imgproc.hpp>

#include "exocet_stereo/dense/dense_stereo.h"
#include "exocet_stereo/geometry/stereo_rectification.h"
#include "exocet_stereo/geometry/stereo_rig.h"
#include "exocet_stereo/mesh/depth_map.h"

namespace exocet_stereo {
namespace mesh {

namespace {

cv::Mat toCv(const Eigen::Matrix3d& m) {
  cv::Mat out(3, 3, CV_64F);
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) out.at<double>(r, c) = m(r, c);
  return out;
}

Eigen::Matrix3d toEigen(const cv::Mat& m) {
  Eigen::Matrix3d out;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) out(r, c) = m.at<double>(r, c);
  return out;
}

cv::Mat gray(const cv::Mat& image) {
  if (image.channels() == 1) return image;
  cv::Mat g;
  cv::cvtColor(image, g, cv::COLOR_BGR2GRAY);
  return g;
}

}  // namespace

std::string PairDepthConfig::validate() const {
  std::ostringstream err;
  const std::vector<std::string> methods = dense::denseStereoMethods();
  if (std::find(methods.begin(), methods.end(), method) == methods.end()) {
    err << "method '" << method << "' is not one of";
    for (const std::string& m : methods) err << " " << m;
    err << "; ";
  }
  if (!(min_depth_m > 0.0 && min_depth_m < max_depth_m))
    err << "min_depth_m = " << min_depth_m << " must be in (0, max_depth_m); ";
  if (!(max_depth_m > min_depth_m && max_depth_m <= 1e4))
    err << "max_depth_m = " << max_depth_m << " must be in (min_depth_m, 1e4]; ";
  std::string s = err.str();
  if (!s.empty()) s.resize(s.size() - 2);
  return s;
}

DepthView depthFromPair(const CalibratedPair& pair, const PairDepthConfig& config, PairDepthStats* stats) {
  const std::string problems = config.validate();
  if (!problems.empty()) throw std::invalid_argument("PairDepthConfig: " + problems);
  if (pair.left.empty() || pair.left.size() != pair.right.size())
    throw std::invalid_argument("depthFromPair: the left and right images must be non-empty and of one size");
  const Eigen::Isometry3d right_T_left = pair.world_T_right.inverse() * pair.world_T_left;
  if (right_T_left.translation().norm() < 1e-6)
    throw std::invalid_argument("depthFromPair: the two camera centres coincide (no baseline)");

  geometry::StereoRig rig;
  rig.image_size = pair.left.size();
  rig.K_left = toCv(pair.K_left);
  rig.K_right = toCv(pair.K_right);
  rig.dist_left = cv::Mat::zeros(1, 5, CV_64F);
  rig.dist_right = cv::Mat::zeros(1, 5, CV_64F);
  rig.R = toCv(right_T_left.linear());
  rig.T = (cv::Mat_<double>(3, 1) << right_T_left.translation().x(), right_T_left.translation().y(),
           right_T_left.translation().z());
  rig.has_extrinsics = true;
  rig.updateDerived();
  // alpha = -1: OpenCV's default scaling keeps the focal length (alpha = 0 zooms into toed-in views).
  const geometry::Rectification rect = geometry::computeRectification(rig, -1.0);
  cv::Mat left_rect, right_rect;
  geometry::rectifyPair(rect, gray(pair.left), gray(pair.right), left_rect, right_rect);
  const double focal_px = rect.focal_px(), baseline_m = rect.baseline();
  const double doffs_rect_px = rect.P2.at<double>(0, 2) - rect.P1.at<double>(0, 2);

  // Search only the disparities of the depth range: the right image shifted by the smallest (doffs takes it back).
  const double d_min = focal_px * baseline_m / config.max_depth_m - doffs_rect_px;
  const double d_max = focal_px * baseline_m / config.min_depth_m - doffs_rect_px;
  const int offset_px = std::max(0, static_cast<int>(std::floor(d_min)) - 2);
  const int disparities_px = std::max(16, static_cast<int>(std::ceil(d_max)) + 2 - offset_px);
  if (disparities_px > 512) {
    std::ostringstream msg;
    msg << "depthFromPair: the depth range [" << config.min_depth_m << ", " << config.max_depth_m << "] m spans "
        << disparities_px << " disparities at this baseline (" << baseline_m << " m) and focal (" << focal_px
        << " px); at most 512: narrow the range";
    throw std::invalid_argument(msg.str());
  }
  cv::Mat right_shifted = cv::Mat::zeros(right_rect.size(), right_rect.type());
  const int w = right_rect.cols - offset_px;
  if (w > 0)
    right_rect(cv::Rect(0, 0, w, right_rect.rows)).copyTo(right_shifted(cv::Rect(offset_px, 0, w, right_rect.rows)));
  dense::DenseStereoConfig dense_config = dense::defaultConfigFor(config.method, disparities_px);
  dense_config.fill_holes = false;  // a filled disparity is no measurement
  const cv::Mat disparity = dense::createDenseStereo(config.method, dense_config)->compute(left_rect, right_shifted);
  // Winners at the ends of the search range are points outside it: unknown.
  const cv::Mat in_range = (disparity >= 1.0f) & (disparity <= disparities_px - 1.0f);
  cv::Mat kept(disparity.size(), CV_32F, cv::Scalar(NAN));
  disparity.copyTo(kept, in_range);
  RectifiedPairGeometry geometry;
  geometry.focal_px = focal_px;
  geometry.baseline_m = baseline_m;
  geometry.doffs_px = offset_px + doffs_rect_px;

  DepthView view;
  view.K = toEigen(rect.P1.colRange(0, 3));
  Eigen::Isometry3d left_T_rect = Eigen::Isometry3d::Identity();
  left_T_rect.linear() = toEigen(rect.R1).transpose();  // X_rect = R1 X_left
  view.world_T_camera = pair.world_T_left * left_T_rect;
  view.depth_m = depthFromDisparity(kept, geometry);
  view.image = left_rect;
  if (stats) {
    stats->disparities_px = disparities_px;
    stats->offset_px = offset_px;
    stats->depth_pixels = cv::countNonZero(view.depth_m == view.depth_m);
    stats->baseline_m = baseline_m;
  }
  return view;
}

}  // namespace mesh
}  // namespace exocet_stereo
