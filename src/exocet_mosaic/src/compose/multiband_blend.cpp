#include "multiband_blend.h"

#include <opencv2/imgproc.hpp>
#include <opencv2/stitching/detail/blenders.hpp>

namespace exocet_mosaic {
namespace compose {

void blendMultiband(const std::vector<WarpedFrame>& frames, const cv::Rect& region, int bands, int channels,
                    cv::Mat* image, cv::Mat* mask) {
  cv::Mat best(region.size(), CV_32F, cv::Scalar(0));
  cv::Mat label(region.size(), CV_32S, cv::Scalar(-1));
  for (std::size_t k = 0; k < frames.size(); ++k) {
    const cv::Rect inter = frames[k].roi & region;
    for (int y = inter.y; y < inter.y + inter.height; ++y) {
      const float* w = frames[k].weight.ptr<float>(y - frames[k].roi.y) + (inter.x - frames[k].roi.x);
      float* b = best.ptr<float>(y - region.y) + (inter.x - region.x);
      int* l = label.ptr<int>(y - region.y) + (inter.x - region.x);
      for (int x = 0; x < inter.width; ++x)
        if (w[x] > b[x]) {
          b[x] = w[x];
          l[x] = static_cast<int>(k);
        }
    }
  }
  cv::detail::MultiBandBlender blender(false, bands);
  blender.prepare(region);
  int fed = 0;
  for (std::size_t k = 0; k < frames.size(); ++k) {
    const cv::Rect inter = frames[k].roi & region;
    if (inter.empty()) continue;
    // The blender wants every image inside its canvas: feed the part within the region.
    cv::Mat m;
    cv::compare(label(inter - region.tl()), static_cast<int>(k), m, cv::CMP_EQ);
    if (cv::countNonZero(m) == 0) continue;
    const cv::Mat part = frames[k].image(inter - frames[k].roi.tl());
    cv::Mat img3, img16;
    if (part.channels() == 1)
      cv::cvtColor(part, img3, cv::COLOR_GRAY2BGR);
    else
      img3 = part;
    img3.convertTo(img16, CV_16SC3);
    blender.feed(img16, m, inter.tl());
    ++fed;
  }
  if (fed == 0) {
    image->create(region.size(), CV_8UC(channels));
    image->setTo(cv::Scalar::all(0));
    mask->create(region.size(), CV_8U);
    mask->setTo(cv::Scalar::all(0));
    return;
  }
  cv::Mat dst, dst_mask;
  blender.blend(dst, dst_mask);
  // The blender pads its canvas; keep the region.
  dst = dst(cv::Rect(0, 0, region.width, region.height));
  dst_mask = dst_mask(cv::Rect(0, 0, region.width, region.height));
  cv::Mat out8;
  dst.convertTo(out8, CV_8U);
  if (channels == 1) cv::cvtColor(out8, out8, cv::COLOR_BGR2GRAY);
  out8.setTo(cv::Scalar::all(0), dst_mask == 0);
  *image = out8;
  *mask = dst_mask.clone();
}

}  // namespace compose
}  // namespace exocet_mosaic
