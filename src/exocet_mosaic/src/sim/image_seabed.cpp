#include "exocet_mosaic/sim/image_seabed.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <stdexcept>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

namespace exocet_mosaic {
namespace sim {
namespace {

constexpr size_t kMaxPatchTexels = size_t(1) << 26;

template <typename P>
void accumulateMean(const cv::Mat& img, const std::vector<float>& lut, double sum[3]) {
  for (int r = 0; r < img.rows; ++r) {
    const P* row = img.ptr<P>(r);
    for (int c = 0; c < img.cols; ++c)
      for (int k = 0; k < 3; ++k) sum[k] += lut[row[c][k]];
  }
}

}  // namespace

ImageSeabed::ImageSeabed(const std::string& path, double pixel_size_m, double center_x_m, double center_y_m,
                         double decode_gamma)
    : pixel_size_m_(pixel_size_m) {
  if (!std::isfinite(pixel_size_m) || pixel_size_m <= 0.0)
    throw std::invalid_argument("ImageSeabed: pixel_size_m must be finite and > 0 (got " +
                                std::to_string(pixel_size_m) + ")");
  if (!std::isfinite(decode_gamma) || decode_gamma <= 0.0)
    throw std::invalid_argument("ImageSeabed: decode_gamma must be finite and > 0 (got " +
                                std::to_string(decode_gamma) + ")");
  if (!std::isfinite(center_x_m) || !std::isfinite(center_y_m))
    throw std::invalid_argument("ImageSeabed: center_x_m and center_y_m must be finite");

  {
    // imread() says nothing about why it failed: tell a missing file from an undecodable one.
    std::ifstream probe(path, std::ios::binary);
    if (!probe) throw std::runtime_error("ImageSeabed: cannot open '" + path + "': " + std::strerror(errno));
  }
  cv::Mat img;
  try {
    img = cv::imread(path, cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception& e) {
    throw std::runtime_error("ImageSeabed: cannot decode '" + path + "': " + e.what());
  }
  if (img.empty())
    throw std::runtime_error("ImageSeabed: cannot decode '" + path + "': not an image format OpenCV reads, or corrupt");
  if (img.depth() != CV_8U && img.depth() != CV_16U)
    throw std::runtime_error("ImageSeabed: '" + path + "' has pixel depth " + std::to_string(img.depth()) +
                             "; only 8 and 16-bit images are supported");
  switch (img.channels()) {
    case 1:
      cv::cvtColor(img, base_, cv::COLOR_GRAY2RGB);
      break;
    case 3:
      cv::cvtColor(img, base_, cv::COLOR_BGR2RGB);
      break;
    case 4:
      cv::cvtColor(img, base_, cv::COLOR_BGRA2RGB);
      break;
    default:
      throw std::runtime_error("ImageSeabed: '" + path + "' has " + std::to_string(img.channels()) +
                               " channels; expected 1, 3 or 4");
  }
  img.release();
  cv::flip(base_, base_, 0);  // row 0 = southern edge, as TexturePatch rows go north

  const int max_value = base_.depth() == CV_8U ? 255 : 65535;
  lut_.resize(max_value + 1);
  for (int v = 0; v <= max_value; ++v)
    lut_[v] = static_cast<float>(std::pow(static_cast<double>(v) / max_value, decode_gamma));

  x_min_m_ = center_x_m - 0.5 * base_.cols * pixel_size_m;
  y_min_m_ = center_y_m - 0.5 * base_.rows * pixel_size_m;

  double sum[3] = {0.0, 0.0, 0.0};
  if (base_.depth() == CV_8U)
    accumulateMean<cv::Vec3b>(base_, lut_, sum);
  else
    accumulateMean<cv::Vec3w>(base_, lut_, sum);
  const double n = static_cast<double>(base_.total());
  mean_ = cv::Vec3f(static_cast<float>(sum[0] / n), static_cast<float>(sum[1] / n), static_cast<float>(sum[2] / n));

  // Pyramid: exact 2x2 means, the missing texels of odd sizes taken as the mean colour.
  int w = base_.cols, h = base_.rows;
  while (w > 1 || h > 1) {
    const int nw = (w + 1) / 2, nh = (h + 1) / 2;
    cv::Mat_<cv::Vec3f> next(nh, nw);
    const cv::Mat_<cv::Vec3f>* prev = levels_.empty() ? nullptr : &levels_.back();
    for (int r = 0; r < nh; ++r) {
      for (int c = 0; c < nw; ++c) {
        cv::Vec3f acc(0.f, 0.f, 0.f);
        for (int dr = 0; dr < 2; ++dr) {
          for (int dc = 0; dc < 2; ++dc) {
            const int pr = 2 * r + dr, pc = 2 * c + dc;
            if (pr >= h || pc >= w)
              acc += mean_;
            else
              acc += prev ? (*prev)(pr, pc) : basePixel(pc, pr);
          }
        }
        next(r, c) = acc * 0.25f;
      }
    }
    levels_.push_back(next);
    w = nw;
    h = nh;
  }
}

cv::Vec3f ImageSeabed::basePixel(int c, int r) const {
  if (base_.depth() == CV_8U) {
    const cv::Vec3b& p = base_.at<cv::Vec3b>(r, c);
    return cv::Vec3f(lut_[p[0]], lut_[p[1]], lut_[p[2]]);
  }
  const cv::Vec3w& p = base_.at<cv::Vec3w>(r, c);
  return cv::Vec3f(lut_[p[0]], lut_[p[1]], lut_[p[2]]);
}

TexturePatch<cv::Vec3f> ImageSeabed::albedoPatch(int level, const WorldRect& area) {
  if (level < 0 || level > maxLevel())
    throw std::out_of_range("ImageSeabed: level " + std::to_string(level) + " outside [0, " +
                            std::to_string(maxLevel()) + "]");
  if (!std::isfinite(area.x_min_m) || !std::isfinite(area.x_max_m) || !std::isfinite(area.y_min_m) ||
      !std::isfinite(area.y_max_m) || area.x_max_m < area.x_min_m || area.y_max_m < area.y_min_m)
    throw std::invalid_argument("ImageSeabed::albedoPatch: area must be finite with x_min <= x_max, y_min <= y_max");
  const double w = std::ldexp(pixel_size_m_, level);
  // Texel (i, j) of the level is centred on (x_min + (i + 0.5) w, y_min + (j + 0.5) w); one texel of margin.
  const int64_t i0 = static_cast<int64_t>(std::floor((area.x_min_m - x_min_m_) / w - 0.5)) - 1;
  const int64_t i1 = static_cast<int64_t>(std::ceil((area.x_max_m - x_min_m_) / w - 0.5)) + 1;
  const int64_t j0 = static_cast<int64_t>(std::floor((area.y_min_m - y_min_m_) / w - 0.5)) - 1;
  const int64_t j1 = static_cast<int64_t>(std::ceil((area.y_max_m - y_min_m_) / w - 0.5)) + 1;
  const size_t cols = static_cast<size_t>(i1 - i0 + 1), rows = static_cast<size_t>(j1 - j0 + 1);
  if (cols * rows > kMaxPatchTexels)
    throw std::invalid_argument("ImageSeabed::albedoPatch: " + std::to_string(cols) + " x " + std::to_string(rows) +
                                " texels at level " + std::to_string(level) + " exceeds 64 Mtexels");
  TexturePatch<cv::Vec3f> patch;
  patch.level = level;
  patch.texel_m = w;
  patch.x0_m = x_min_m_ + (static_cast<double>(i0) + 0.5) * w;
  patch.y0_m = y_min_m_ + (static_cast<double>(j0) + 0.5) * w;
  patch.texels.create(static_cast<int>(rows), static_cast<int>(cols));
  patch.texels.setTo(mean_);

  const int lw = level == 0 ? base_.cols : levels_[level - 1].cols;
  const int lh = level == 0 ? base_.rows : levels_[level - 1].rows;
  const int64_t a0 = std::max<int64_t>(i0, 0), a1 = std::min<int64_t>(i1, lw - 1);
  const int64_t b0 = std::max<int64_t>(j0, 0), b1 = std::min<int64_t>(j1, lh - 1);
  for (int64_t j = b0; j <= b1; ++j) {
    cv::Vec3f* out = patch.texels[j - j0] + (a0 - i0);
    if (level > 0) {
      std::copy(levels_[level - 1][j] + a0, levels_[level - 1][j] + a1 + 1, out);
    } else if (base_.depth() == CV_8U) {
      const cv::Vec3b* in = base_.ptr<cv::Vec3b>(static_cast<int>(j)) + a0;
      for (int64_t i = a0; i <= a1; ++i, ++in, ++out) *out = cv::Vec3f(lut_[(*in)[0]], lut_[(*in)[1]], lut_[(*in)[2]]);
    } else {
      const cv::Vec3w* in = base_.ptr<cv::Vec3w>(static_cast<int>(j)) + a0;
      for (int64_t i = a0; i <= a1; ++i, ++in, ++out) *out = cv::Vec3f(lut_[(*in)[0]], lut_[(*in)[1]], lut_[(*in)[2]]);
    }
  }
  return patch;
}

WorldRect ImageSeabed::bounds() const {
  WorldRect r;
  r.x_min_m = x_min_m_;
  r.y_min_m = y_min_m_;
  r.x_max_m = x_min_m_ + base_.cols * pixel_size_m_;
  r.y_max_m = y_min_m_ + base_.rows * pixel_size_m_;
  return r;
}

bool ImageSeabed::covers(const WorldRect& area) const {
  const WorldRect b = bounds();
  return area.x_min_m >= b.x_min_m && area.x_max_m <= b.x_max_m && area.y_min_m >= b.y_min_m &&
         area.y_max_m <= b.y_max_m;
}

}  // namespace sim
}  // namespace exocet_mosaic
