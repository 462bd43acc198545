#include "exocet_mosaic/compose/image_reduction.h"

#include <cmath>

#include <opencv2/imgproc.hpp>

namespace exocet_mosaic {
namespace compose {

bool isImageReduction(int reduction) { return reduction == 1 || reduction == 2 || reduction == 4 || reduction == 8; }

cv::Size reducedImageSize(const cv::Size& full_size, int reduction) {
  if (reduction < 1) return cv::Size();
  return cv::Size(full_size.width / reduction, full_size.height / reduction);
}

cv::Matx33d fullFromReducedPx(int reduction) {
  const double r = reduction, c = 0.5 * (reduction - 1);
  return cv::Matx33d(r, 0, c, 0, r, c, 0, 0, 1);
}

cv::Mat reduceImage(const cv::Mat& image, const cv::Size& full_size, int reduction) {
  if (image.empty() || !isImageReduction(reduction)) return cv::Mat();
  if (reduction == 1) return image.size() == full_size ? image : cv::Mat();
  const cv::Size reduced = reducedImageSize(full_size, reduction);
  if (reduced.empty()) return cv::Mat();
  if (image.size() == full_size) {
    // Only whole blocks: INTER_AREA by an integer factor is their exact mean, and pixel x of the result stays
    // centred on full px r x + (r - 1) / 2.
    const cv::Mat blocks = image(cv::Rect(0, 0, reduced.width * reduction, reduced.height * reduction));
    cv::Mat out;
    cv::resize(blocks, out, reduced, 0, 0, cv::INTER_AREA);
    return out;
  }
  const cv::Size ceil_size((full_size.width + reduction - 1) / reduction,
                           (full_size.height + reduction - 1) / reduction);
  if (image.cols < reduced.width || image.rows < reduced.height || image.cols > ceil_size.width ||
      image.rows > ceil_size.height)
    return cv::Mat();
  return image.size() == reduced ? image : image(cv::Rect(cv::Point(0, 0), reduced));
}

int chooseImageReduction(double native_gsd_m, double tile_gsd_m, int max_reduction, int current) {
  if (!(native_gsd_m > 0.0) || !(tile_gsd_m > 0.0) || !std::isfinite(native_gsd_m) || !std::isfinite(tile_gsd_m))
    return 1;
  int ideal = 1;
  while (ideal * 2 <= max_reduction && native_gsd_m * ideal * 2 <= tile_gsd_m) ideal *= 2;
  if (!isImageReduction(current) || current > max_reduction) return ideal;
  const bool too_coarse = native_gsd_m * current > 1.1 * tile_gsd_m;
  const bool could_double = current * 2 <= max_reduction && native_gsd_m * current * 2 <= 0.9 * tile_gsd_m;
  return too_coarse || could_double ? ideal : current;
}

}  // namespace compose
}  // namespace exocet_mosaic
