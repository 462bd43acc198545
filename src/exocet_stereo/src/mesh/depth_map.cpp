#include "exocet_stereo/mesh/depth_map.h"

#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

#include <Eigen/LU>

namespace exocet_stereo {
namespace mesh {

std::string RectifiedPairGeometry::validate() const {
  std::ostringstream out;
  const char* sep = "";
  if (!(focal_px > 0.0 && std::isfinite(focal_px))) {
    out << sep << "focal_px = " << focal_px << " must be in (0, inf)";
    sep = "; ";
  }
  if (!(baseline_m > 0.0 && std::isfinite(baseline_m))) {
    out << sep << "baseline_m = " << baseline_m << " must be in (0, inf)";
    sep = "; ";
  }
  if (!std::isfinite(doffs_px)) {
    out << sep << "doffs_px = " << doffs_px << " must be finite";
    sep = "; ";
  }
  if (!(min_disparity_px >= 0.0 && std::isfinite(min_disparity_px))) {
    out << sep << "min_disparity_px = " << min_disparity_px << " must be in [0, inf)";
  }
  return out.str();
}

cv::Mat depthFromDisparity(const cv::Mat& disparity_px, const RectifiedPairGeometry& geometry) {
  if (disparity_px.empty() || disparity_px.type() != CV_32FC1) {
    throw std::invalid_argument("depthFromDisparity: disparity must be a non-empty CV_32FC1 map");
  }
  const std::string bad = geometry.validate();
  if (!bad.empty()) throw std::invalid_argument("depthFromDisparity: " + bad);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const double fb = geometry.focal_px * geometry.baseline_m;
  cv::Mat depth(disparity_px.size(), CV_32FC1);
  for (int y = 0; y < disparity_px.rows; ++y) {
    const float* d = disparity_px.ptr<float>(y);
    float* z = depth.ptr<float>(y);
    for (int x = 0; x < disparity_px.cols; ++x) {
      const double shifted = static_cast<double>(d[x]) + geometry.doffs_px;
      // NaN and +inf fail the comparison below; a disparity at or below the threshold means "at infinity".
      z[x] = (std::isfinite(d[x]) && shifted > geometry.min_disparity_px && shifted > 0.0)
                 ? static_cast<float>(fb / shifted)
                 : nan;
    }
  }
  return depth;
}

PointCloud backProjectDepth(const cv::Mat& depth_m, const geometry::PinholeView& view, const cv::Mat& image,
                            int step_px) {
  if (depth_m.empty() || (depth_m.type() != CV_32FC1 && depth_m.type() != CV_64FC1)) {
    throw std::invalid_argument("backProjectDepth: depth must be a non-empty CV_32FC1 or CV_64FC1 map");
  }
  if (step_px < 1)
    throw std::invalid_argument("backProjectDepth: step_px = " + std::to_string(step_px) + " must be >= 1");
  if (!image.empty() && (image.size() != depth_m.size() || (image.type() != CV_8UC3 && image.type() != CV_8UC1))) {
    throw std::invalid_argument("backProjectDepth: image must be CV_8UC3 or CV_8UC1 of the depth map's size");
  }
  cv::Mat depth;
  depth_m.convertTo(depth, CV_64F);
  const Eigen::Matrix3d K_inv = view.K.inverse();
  const Eigen::Matrix3d Rt = view.R.transpose();
  PointCloud cloud;
  for (int y = 0; y < depth.rows; y += step_px) {
    const double* z = depth.ptr<double>(y);
    for (int x = 0; x < depth.cols; x += step_px) {
      if (!(std::isfinite(z[x]) && z[x] > 0.0)) continue;
      const Eigen::Vector3d X_cam = z[x] * (K_inv * Eigen::Vector3d(x, y, 1.0));
      cloud.points.push_back(Rt * (X_cam - view.t));
      cloud.pixels.emplace_back(x, y);
      if (!image.empty()) {
        if (image.type() == CV_8UC3) {
          const cv::Vec3b bgr = image.at<cv::Vec3b>(y, x);
          cloud.colors.emplace_back(bgr[2], bgr[1], bgr[0]);
        } else {
          const uchar g = image.at<uchar>(y, x);
          cloud.colors.emplace_back(g, g, g);
        }
      }
    }
  }
  return cloud;
}

}  // namespace mesh
}  // namespace exocet_stereo
