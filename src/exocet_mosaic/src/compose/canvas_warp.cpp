#include "canvas_warp.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "exocet_mosaic/compose/ground_projection.h"

namespace exocet_mosaic {
namespace compose {

bool warpOntoCanvas(const cv::Mat& image, const cv::Mat& weight, const cv::Matx33d& canvas_from_px, CanvasWarp* warp,
                    std::string* problem) {
  const cv::Size s = image.size();
  const std::array<Eigen::Vector2d, 4> corners = {Eigen::Vector2d(-0.5, -0.5), Eigen::Vector2d(s.width - 0.5, -0.5),
                                                  Eigen::Vector2d(s.width - 0.5, s.height - 0.5),
                                                  Eigen::Vector2d(-0.5, s.height - 0.5)};
  double x0 = 1e300, y0 = 1e300, x1 = -1e300, y1 = -1e300;
  for (int i = 0; i < 4; ++i) {
    const Eigen::Vector2d c = applyHomography(canvas_from_px, corners[i]);
    warp->corners_canvas[i] = c;
    x0 = std::min(x0, c.x());
    y0 = std::min(y0, c.y());
    x1 = std::max(x1, c.x());
    y1 = std::max(y1, c.y());
  }
  const double area = (x1 - x0) * (y1 - y0);
  if (!std::isfinite(area) || area > 64.0 * image.total() + 1e6) {
    if (problem)
      *problem = "image not composed: its placement is degenerate (footprint of " + std::to_string(area) +
                 " canvas px)";
    return false;
  }
  warp->roi = cv::Rect(static_cast<int>(std::floor(x0)) - 1, static_cast<int>(std::floor(y0)) - 1,
                       static_cast<int>(std::ceil(x1) - std::floor(x0)) + 3,
                       static_cast<int>(std::ceil(y1) - std::floor(y0)) + 3);
  const cv::Matx33d roi_from_px = cv::Matx33d(1, 0, -warp->roi.x, 0, 1, -warp->roi.y, 0, 0, 1) * canvas_from_px;
  // One warp of the image with its weight as alpha (8 bits are plenty for blending weights).
  cv::Mat w8, with_alpha;
  weight.convertTo(w8, CV_8U, 255.0);
  cv::max(w8, 1, w8);  // inside the image the weight stays positive
  std::vector<cv::Mat> planes;
  cv::split(image, planes);
  planes.push_back(w8);
  cv::merge(planes, with_alpha);
  // A ring of one pixel: the colour replicated, alpha 0, so that the partly covered pixels at the footprint's edge
  // keep the edge colour (no dark fringe) while their weight fades to 0.
  cv::copyMakeBorder(with_alpha, with_alpha, 1, 1, 1, 1, cv::BORDER_REPLICATE);
  const int last = with_alpha.channels() - 1;
  for (int y = 0; y < with_alpha.rows; ++y) {
    uchar* row = with_alpha.ptr<uchar>(y);
    if (y == 0 || y == with_alpha.rows - 1) {
      for (int x = 0; x < with_alpha.cols; ++x) row[x * (last + 1) + last] = 0;
    } else {
      row[last] = 0;
      row[(with_alpha.cols - 1) * (last + 1) + last] = 0;
    }
  }
  const cv::Matx33d shift_ring(1, 0, 1, 0, 1, 1, 0, 0, 1);  // the ring moved the image by one pixel
  cv::warpPerspective(with_alpha, warp->image_alpha, roi_from_px * shift_ring.inv(), warp->roi.size(),
                      cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar::all(0));
  return true;
}

}  // namespace compose
}  // namespace exocet_mosaic
