#include "exocet_mosaic/compose/block_canvas.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include <opencv2/imgproc.hpp>

namespace exocet_mosaic {
namespace compose {
namespace {

int floorDiv(int a, int b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

}  // namespace

BlockCanvas::BlockCanvas(int channels, int block_size_px) : channels_(channels), block_size_(block_size_px) {
  if (channels != 1 && channels != 3) throw std::invalid_argument("BlockCanvas: channels must be 1 or 3");
  if (block_size_px < 16 || block_size_px > 4096)
    throw std::invalid_argument("BlockCanvas: block_size_px must be in [16, 4096], got " +
                                std::to_string(block_size_px));
  block_bytes_ = static_cast<std::size_t>(block_size_) * block_size_ * (channels_ + 1) * sizeof(float);
}

cv::Mat& BlockCanvas::block(int bx, int by) {
  auto it = blocks_.find(key(bx, by));
  if (it != blocks_.end()) return it->second;
  cv::Mat b(block_size_, block_size_, CV_32FC(channels_ + 1), cv::Scalar::all(0));
  return blocks_.emplace(key(bx, by), b).first->second;
}

const cv::Mat* BlockCanvas::findBlock(int bx, int by) const {
  auto it = blocks_.find(key(bx, by));
  return it == blocks_.end() ? nullptr : &it->second;
}

namespace {

// Weight of pixel x: a float plane, or the last channel of an 8-bit image (alpha / 255).
struct FloatWeight {
  const cv::Mat& w;
  float at(int y, int x) const { return w.ptr<float>(y)[x]; }
};
struct AlphaWeight {
  const cv::Mat& im;
  int stride;
  float at(int y, int x) const { return im.ptr<uchar>(y)[x * stride + stride - 1] * (1.f / 255.f); }
};

}  // namespace

template <typename Weight>
void BlockCanvas::accumulateImpl(const cv::Mat& image, int pixel_stride, const Weight& weight,
                                 const cv::Point& top_left, bool replace) {
  if (image.empty()) return;
  const cv::Rect roi(top_left, image.size());
  const int bx0 = floorDiv(roi.x, block_size_), bx1 = floorDiv(roi.x + roi.width - 1, block_size_);
  const int by0 = floorDiv(roi.y, block_size_), by1 = floorDiv(roi.y + roi.height - 1, block_size_);
  const int nc = channels_ + 1;
  int min_x = INT32_MAX, min_y = INT32_MAX, max_x = INT32_MIN, max_y = INT32_MIN;
  for (int by = by0; by <= by1; ++by) {
    for (int bx = bx0; bx <= bx1; ++bx) {
      const cv::Rect brect(bx * block_size_, by * block_size_, block_size_, block_size_);
      const cv::Rect inter = brect & roi;
      if (inter.empty()) continue;
      // Only allocate a block if the image brings data to it (the bounding box of a rotated footprint is larger).
      bool any = false;
      for (int y = inter.y; y < inter.y + inter.height && !any; ++y)
        for (int x = inter.x - roi.x; x < inter.x - roi.x + inter.width; ++x)
          if (weight.at(y - roi.y, x) > 0.f) {
            any = true;
            break;
          }
      if (!any) continue;
      cv::Mat& b = block(bx, by);
      for (int y = inter.y; y < inter.y + inter.height; ++y) {
        const uchar* src = image.ptr<uchar>(y - roi.y) + (inter.x - roi.x) * pixel_stride;
        float* dst = b.ptr<float>(y - brect.y) + (inter.x - brect.x) * nc;
        bool row_any = false;
        int row_min = 0, row_max = 0;
        for (int x = 0; x < inter.width; ++x, src += pixel_stride, dst += nc) {
          const float wx = weight.at(y - roi.y, inter.x - roi.x + x);
          if (wx <= 0.f) continue;
          if (!row_any) row_min = x;
          row_any = true;
          row_max = x;
          if (replace) {
            if (wx <= 0.5f) continue;
            for (int c = 0; c < channels_; ++c) dst[c] = src[c];
            dst[channels_] = 1.f;
          } else {
            for (int c = 0; c < channels_; ++c) dst[c] += wx * src[c];
            dst[channels_] += wx;
          }
        }
        if (row_any) {
          min_x = std::min(min_x, inter.x + row_min);
          max_x = std::max(max_x, inter.x + row_max);
          min_y = std::min(min_y, y);
          max_y = std::max(max_y, y);
        }
      }
    }
  }
  if (min_x <= max_x) {
    const cv::Rect r(min_x, min_y, max_x - min_x + 1, max_y - min_y + 1);
    data_bounds_ = data_bounds_.empty() ? r : (data_bounds_ | r);
  }
}

void BlockCanvas::accumulate(const cv::Mat& image, const cv::Mat& weight, const cv::Point& top_left, bool replace) {
  CV_Assert(image.type() == CV_8UC(channels_) && weight.type() == CV_32F && image.size() == weight.size());
  accumulateImpl(image, channels_, FloatWeight{weight}, top_left, replace);
}

void BlockCanvas::accumulateAlpha(const cv::Mat& image_alpha, const cv::Point& top_left, bool replace) {
  CV_Assert(image_alpha.type() == CV_8UC(channels_ + 1));
  accumulateImpl(image_alpha, channels_ + 1, AlphaWeight{image_alpha, channels_ + 1}, top_left, replace);
}

void BlockCanvas::normalizeBlock(const cv::Mat& acc, cv::Mat* image, cv::Mat* mask) const {
  image->create(acc.size(), CV_8UC(channels_));
  mask->create(acc.size(), CV_8UC1);
  const int nc = channels_ + 1;
  for (int y = 0; y < acc.rows; ++y) {
    const float* a = acc.ptr<float>(y);
    uchar* im = image->ptr<uchar>(y);
    uchar* m = mask->ptr<uchar>(y);
    for (int x = 0; x < acc.cols; ++x, a += nc, im += channels_) {
      const float w = a[channels_];
      if (w > 1e-6f) {
        const float inv = 1.f / w;
        for (int c = 0; c < channels_; ++c) im[c] = cv::saturate_cast<uchar>(a[c] * inv);
        m[x] = 255;
      } else {
        for (int c = 0; c < channels_; ++c) im[c] = 0;
        m[x] = 0;
      }
    }
  }
}

void BlockCanvas::render(const cv::Rect& region, cv::Mat* image, cv::Mat* mask, double scale) const {
  scale = std::min(1.0, std::max(scale, 1e-6));
  const cv::Size out_size(std::max(1, static_cast<int>(std::lround(region.width * scale))),
                          std::max(1, static_cast<int>(std::lround(region.height * scale))));
  image->create(out_size, CV_8UC(channels_));
  image->setTo(cv::Scalar::all(0));
  mask->create(out_size, CV_8UC1);
  mask->setTo(cv::Scalar::all(0));
  if (region.empty()) return;
  const int bx0 = floorDiv(region.x, block_size_), bx1 = floorDiv(region.x + region.width - 1, block_size_);
  const int by0 = floorDiv(region.y, block_size_), by1 = floorDiv(region.y + region.height - 1, block_size_);
  cv::Mat bim, bmask;
  for (int by = by0; by <= by1; ++by) {
    for (int bx = bx0; bx <= bx1; ++bx) {
      const cv::Mat* b = findBlock(bx, by);
      if (!b) continue;
      const cv::Rect brect(bx * block_size_, by * block_size_, block_size_, block_size_);
      const cv::Rect inter = brect & region;
      if (inter.empty()) continue;
      normalizeBlock((*b)(inter - brect.tl()), &bim, &bmask);
      if (scale == 1.0) {
        bim.copyTo((*image)(inter - region.tl()));
        bmask.copyTo((*mask)(inter - region.tl()));
        continue;
      }
      // Preview: each block downscaled into its place (pixel edges rounded).
      const int x0 = static_cast<int>(std::lround((inter.x - region.x) * scale));
      const int y0 = static_cast<int>(std::lround((inter.y - region.y) * scale));
      const int x1 = std::min(out_size.width, static_cast<int>(std::lround((inter.br().x - region.x) * scale)));
      const int y1 = std::min(out_size.height, static_cast<int>(std::lround((inter.br().y - region.y) * scale)));
      if (x1 <= x0 || y1 <= y0) continue;
      const cv::Rect dst(x0, y0, x1 - x0, y1 - y0);
      cv::Mat small_im, small_mask;
      cv::resize(bim, small_im, dst.size(), 0, 0, cv::INTER_AREA);
      cv::resize(bmask, small_mask, dst.size(), 0, 0, cv::INTER_NEAREST);
      small_im.copyTo((*image)(dst));
      small_mask.copyTo((*mask)(dst));
    }
  }
}

cv::Mat BlockCanvas::weights(const cv::Rect& region) const {
  cv::Mat out(region.size(), CV_32F, cv::Scalar(0));
  if (region.empty()) return out;
  const int bx0 = floorDiv(region.x, block_size_), bx1 = floorDiv(region.x + region.width - 1, block_size_);
  const int by0 = floorDiv(region.y, block_size_), by1 = floorDiv(region.y + region.height - 1, block_size_);
  for (int by = by0; by <= by1; ++by)
    for (int bx = bx0; bx <= bx1; ++bx) {
      const cv::Mat* b = findBlock(bx, by);
      if (!b) continue;
      const cv::Rect brect(bx * block_size_, by * block_size_, block_size_, block_size_);
      const cv::Rect inter = brect & region;
      if (inter.empty()) continue;
      cv::Mat w;
      cv::extractChannel((*b)(inter - brect.tl()), w, channels_);
      w.copyTo(out(inter - region.tl()));
    }
  return out;
}

void BlockCanvas::clear() {
  blocks_.clear();
  data_bounds_ = cv::Rect();
}

}  // namespace compose
}  // namespace exocet_mosaic
