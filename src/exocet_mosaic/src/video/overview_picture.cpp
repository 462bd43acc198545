#include "exocet_mosaic/video/overview_picture.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <opencv2/imgproc.hpp>

namespace exocet_mosaic {
namespace video {

cv::Mat drawOverview(const std::vector<MosaicThumbnail>& mosaics, const std::vector<FramePlacement>& track,
                     int max_side_px) {
  double min_e = std::numeric_limits<double>::infinity(), max_e = -min_e, min_n = min_e, max_n = -min_e;
  for (const MosaicThumbnail& m : mosaics) {
    min_e = std::min(min_e, m.origin_easting_m);
    max_e = std::max(max_e, m.origin_easting_m + m.image.cols * m.gsd_m);
    max_n = std::max(max_n, m.origin_northing_m);
    min_n = std::min(min_n, m.origin_northing_m - m.image.rows * m.gsd_m);
  }
  for (const FramePlacement& f : track) {
    if (!f.camera_en_m) continue;
    min_e = std::min(min_e, f.camera_en_m->x());
    max_e = std::max(max_e, f.camera_en_m->x());
    min_n = std::min(min_n, f.camera_en_m->y());
    max_n = std::max(max_n, f.camera_en_m->y());
  }
  if (!std::isfinite(min_e)) return cv::Mat();
  const double margin_m = 0.5;
  min_e -= margin_m;
  max_e += margin_m;
  min_n -= margin_m;
  max_n += margin_m;
  const double extent_m = std::max(max_e - min_e, max_n - min_n);
  const double px_per_m = max_side_px / extent_m;
  const cv::Size size(std::max(1, int(std::ceil((max_e - min_e) * px_per_m))),
                      std::max(1, int(std::ceil((max_n - min_n) * px_per_m))));
  cv::Mat canvas(size, CV_8UC3, cv::Scalar(40, 40, 40));
  const auto toPixel = [&](double e, double n) { return cv::Point2d((e - min_e) * px_per_m, (max_n - n) * px_per_m); };

  for (const MosaicThumbnail& m : mosaics) {
    if (m.image.empty()) continue;
    cv::Mat colour = m.image;
    if (colour.channels() == 1) cv::cvtColor(colour, colour, cv::COLOR_GRAY2BGR);
    // Mosaic pixel -> canvas pixel: a scale and a shift (both north-up).
    const double s = m.gsd_m * px_per_m;
    const cv::Point2d o = toPixel(m.origin_easting_m, m.origin_northing_m);
    const cv::Matx23d warp(s, 0, o.x, 0, s, o.y);
    cv::Mat warped, warped_mask;
    cv::warpAffine(colour, warped, warp, size, cv::INTER_AREA, cv::BORDER_CONSTANT);
    cv::warpAffine(m.mask, warped_mask, warp, size, cv::INTER_NEAREST, cv::BORDER_CONSTANT);
    warped.copyTo(canvas, warped_mask);
  }

  std::vector<cv::Point> line;
  for (const FramePlacement& f : track)
    if (f.camera_en_m) line.push_back(toPixel(f.camera_en_m->x(), f.camera_en_m->y()));
  const int thickness = std::max(1, max_side_px / 600);
  if (line.size() >= 2) cv::polylines(canvas, line, false, cv::Scalar(0, 220, 255), thickness, cv::LINE_AA);
  if (!line.empty()) {
    cv::circle(canvas, line.front(), 3 * thickness + 2, cv::Scalar(0, 200, 0), cv::FILLED, cv::LINE_AA);
    cv::circle(canvas, line.back(), 3 * thickness + 2, cv::Scalar(0, 0, 230), cv::FILLED, cv::LINE_AA);
  }
  // Scale bar: 1 m (or 0.1 / 10 m when 1 m would be too short or too long), bottom left; north arrow top right.
  double bar_m = 1.0;
  if (bar_m * px_per_m < 30) bar_m = 10.0;
  if (bar_m * px_per_m > size.width / 2.0) bar_m = 0.1;
  const cv::Point bar0(10, size.height - 12), bar1(10 + int(bar_m * px_per_m), size.height - 12);
  cv::line(canvas, bar0, bar1, cv::Scalar(255, 255, 255), thickness + 1);
  cv::putText(canvas, (bar_m < 1 ? std::string("0.1 m") : std::to_string(int(bar_m)) + " m"), bar0 + cv::Point(0, -6),
              cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
  const cv::Point north(size.width - 20, 30);
  cv::arrowedLine(canvas, north + cv::Point(0, 20), north - cv::Point(0, 5), cv::Scalar(255, 255, 255), thickness + 1);
  cv::putText(canvas, "N", north + cv::Point(-5, 38), cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(255, 255, 255), 1,
              cv::LINE_AA);
  return canvas;
}

}  // namespace video
}  // namespace exocet_mosaic
