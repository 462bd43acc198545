#include "exocet_servo/vision/depth_lookup.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace exocet_servo {
namespace vision {

bool screenedDepthAt(const cv::Mat& depth_m, const Eigen::Vector2d& px, int radius_px, double max_relative_step,
                     double* depth) {
  if (depth_m.empty() || depth_m.type() != CV_32FC1 || !px.allFinite()) return false;
  const int x0 = static_cast<int>(std::floor(px.x())), y0 = static_cast<int>(std::floor(px.y()));
  const int r = std::max(radius_px, 0);
  if (x0 - r < 0 || y0 - r < 0 || x0 + 1 + r >= depth_m.cols || y0 + 1 + r >= depth_m.rows) return false;
  float lo = std::numeric_limits<float>::infinity(), hi = 0.0f;
  for (int y = y0 - r; y <= y0 + 1 + r; ++y) {
    const float* row = depth_m.ptr<float>(y);
    for (int x = x0 - r; x <= x0 + 1 + r; ++x) {
      if (!std::isfinite(row[x])) return false;
      lo = std::min(lo, row[x]);
      hi = std::max(hi, row[x]);
    }
  }
  if (hi > lo * (1.0 + max_relative_step)) return false;
  // Bilinear between the four pixels around px (all inside: checked above).
  const float fx = static_cast<float>(px.x() - x0), fy = static_cast<float>(px.y() - y0);
  const float* r0 = depth_m.ptr<float>(y0);
  const float* r1 = depth_m.ptr<float>(y0 + 1);
  *depth = (1 - fy) * ((1 - fx) * r0[x0] + fx * r0[x0 + 1]) + fy * ((1 - fx) * r1[x0] + fx * r1[x0 + 1]);
  return true;
}

}  // namespace vision
}  // namespace exocet_servo
