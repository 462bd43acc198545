#include "exocet_mosaic/registration/illumination_normalizer.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include <opencv2/core/hal/intrin.hpp>
#if defined(__GNUC__) && defined(__x86_64__)
#include <immintrin.h>
#endif
#include <opencv2/imgproc.hpp>

namespace exocet_mosaic {
namespace registration {
namespace {

/// out = in * gain + offset, rounded and saturated, the fields blended between two rows: (1 - wy) * row0 + wy * row1.
/// Rounding to nearest even everywhere (cvRound, the vector conversions), so that every path gives the same bytes.
void normalizeRow(const uint8_t* in, const float* gain0, const float* gain1, const float* offset0, const float* offset1,
                  float wy, int width, uint8_t* out, int x = 0) {
#if CV_SIMD128
  // Explicit 128-bit vectors: the library is compiled for the baseline instruction set, where the compiler does not
  // vectorise the conversions of this loop by itself.
  const cv::v_float32x4 w = cv::v_setall_f32(wy);
  for (; x + 16 <= width; x += 16) {
    cv::v_uint16x8 p0, p1;
    cv::v_expand(cv::v_load(in + x), p0, p1);
    cv::v_uint32x4 q[4];
    cv::v_expand(p0, q[0], q[1]);
    cv::v_expand(p1, q[2], q[3]);
    cv::v_int32x4 r[4];
    for (int k = 0; k < 4; ++k) {
      const int i = x + 4 * k;
      const cv::v_float32x4 g0 = cv::v_load(gain0 + i), f0 = cv::v_load(offset0 + i);
      const cv::v_float32x4 g = cv::v_muladd(cv::v_load(gain1 + i) - g0, w, g0);
      const cv::v_float32x4 f = cv::v_muladd(cv::v_load(offset1 + i) - f0, w, f0);
      r[k] = cv::v_round(cv::v_muladd(cv::v_cvt_f32(cv::v_reinterpret_as_s32(q[k])), g, f));
    }
    cv::v_store(out + x, cv::v_pack_u(cv::v_pack(r[0], r[1]), cv::v_pack(r[2], r[3])));
  }
#endif
  for (; x < width; ++x) {
    const float g = gain0[x] + wy * (gain1[x] - gain0[x]);
    const float f = offset0[x] + wy * (offset1[x] - offset0[x]);
    out[x] = cv::saturate_cast<uint8_t>(g * float(in[x]) + f);
  }
}

#if defined(__GNUC__) && defined(__x86_64__)
#define EXOCET_NORMALIZE_AVX2 1
/// normalizeRow with 256-bit vectors, for the processors that have them (run-time check): this pass writes every
/// pixel, and the baseline build gets half the throughput. No fused multiply-adds: the same bytes as normalizeRow.
__attribute__((target("avx2"))) void normalizeRowAvx2(const uint8_t* in, const float* gain0, const float* gain1,
                                                      const float* offset0, const float* offset1, float wy, int width,
                                                      uint8_t* out) {
  const __m256 w = _mm256_set1_ps(wy);
  int x = 0;
  for (; x + 16 <= width; x += 16) {
    const __m128i pixels = _mm_loadu_si128(reinterpret_cast<const __m128i*>(in + x));
    __m256i r[2];
    for (int k = 0; k < 2; ++k) {
      const int i = x + 8 * k;
      const __m256 p = _mm256_cvtepi32_ps(_mm256_cvtepu8_epi32(k == 0 ? pixels : _mm_srli_si128(pixels, 8)));
      const __m256 g0 = _mm256_loadu_ps(gain0 + i), f0 = _mm256_loadu_ps(offset0 + i);
      const __m256 g = _mm256_add_ps(_mm256_mul_ps(_mm256_sub_ps(_mm256_loadu_ps(gain1 + i), g0), w), g0);
      const __m256 f = _mm256_add_ps(_mm256_mul_ps(_mm256_sub_ps(_mm256_loadu_ps(offset1 + i), f0), w), f0);
      r[k] = _mm256_cvtps_epi32(_mm256_add_ps(_mm256_mul_ps(p, g), f));
    }
    // packs works within 128-bit lanes: 0-3 8-11 4-7 12-15, put back in order before the last pack.
    const __m256i words = _mm256_permute4x64_epi64(_mm256_packs_epi32(r[0], r[1]), 0xd8);
    const __m128i bytes = _mm_packus_epi16(_mm256_castsi256_si128(words), _mm256_extracti128_si256(words, 1));
    _mm_storeu_si128(reinterpret_cast<__m128i*>(out + x), bytes);
  }
  normalizeRow(in, gain0, gain1, offset0, offset1, wy, width, out, x);
}

bool hasAvx2() {
  static const bool has = __builtin_cpu_supports("avx2");
  return has;
}
#endif

}  // namespace

std::string IlluminationNormalizerConfig::validate() const {
  std::string errors;
  const auto check = [&errors](bool ok, const std::string& what) {
    if (!ok) errors += (errors.empty() ? "" : "; ") + what;
  };
  check(level >= 1 && level <= 6, "level must be in [1, 6]");
  check(sigma_level_px >= 0.5 && sigma_level_px <= 20.0, "sigma_level_px must be in [0.5, 20]");
  check(min_contrast_grey >= 0.5 && min_contrast_grey <= 100.0, "min_contrast_grey must be in [0.5, 100]");
  check(min_mean_grey >= 0.0 && min_mean_grey <= 255.0, "min_mean_grey must be in [0, 255]");
  check(min_stddev_grey >= 0.0 && min_stddev_grey <= 128.0, "min_stddev_grey must be in [0, 128]");
  check(output_gain >= 1.0 && output_gain <= 100.0, "output_gain must be in [1, 100]");
  return errors;
}

IlluminationNormalizer::IlluminationNormalizer(const IlluminationNormalizerConfig& config) : config_(config) {
  const std::string error = config_.validate();
  if (!error.empty()) throw std::invalid_argument("illumination normaliser: " + error);
}

cv::Mat IlluminationNormalizer::apply(const cv::Mat& gray) {
  cv::Mat out;
  apply(gray, &out);
  return out;
}

void IlluminationNormalizer::apply(const cv::Mat& gray, cv::Mat* out, InputStatistics* statistics) {
  InputStatistics unused;
  if (!statistics) statistics = &unused;
  *statistics = InputStatistics();
  if (gray.empty() || gray.type() != CV_8UC1) {
    *out = gray;
    return;
  }
  if (gray.cols < 2 || gray.rows < 2) {  // no half-resolution image to measure: too small to normalise
    cv::Scalar mean, stddev;
    cv::meanStdDev(gray, mean, stddev);
    statistics->mean_grey = mean[0];
    statistics->stddev_grey = stddev[0];
    *out = gray;
    return;
  }
  measure(gray, statistics);
  if (!config_.enabled) {
    *out = gray;
    return;
  }
  computeFields();

  // out = gain * I + offset, the two fields interpolated bilinearly from the block centres: each block row is
  // interpolated to every column once, then each image row blends two such rows.
  const int width = gray.cols, height = gray.rows, blocks_down = gain_.rows;
  const float block_px = float(1 << config_.level), centre_px = 0.5f * (block_px - 1.0f);
  out->create(gray.size(), CV_8UC1);
  rows_.resize(4 * size_t(width));
  float *gain0 = rows_.data(), *offset0 = gain0 + width, *gain1 = offset0 + width, *offset1 = gain1 + width;
  int loaded0 = -1, loaded1 = -1;
  for (int y = 0; y < height; ++y) {
    const float cy = std::min(std::max((float(y) - centre_px) / block_px, 0.0f), float(blocks_down - 1));
    const int y0 = std::min(int(cy), std::max(blocks_down - 2, 0)), y1 = std::min(y0 + 1, blocks_down - 1);
    const float wy = cy - float(y0);
    if (y0 != loaded0) {
      if (y0 == loaded1) {
        std::swap(gain0, gain1);
        std::swap(offset0, offset1);
        std::swap(loaded0, loaded1);
      } else {
        expandRow(y0, gain0, offset0);
        loaded0 = y0;
      }
    }
    if (y1 != loaded1) {
      expandRow(y1, gain1, offset1);
      loaded1 = y1;
    }
#ifdef EXOCET_NORMALIZE_AVX2
    if (hasAvx2()) {
      normalizeRowAvx2(gray.ptr<uint8_t>(y), gain0, gain1, offset0, offset1, wy, width, out->ptr<uint8_t>(y));
      continue;
    }
#endif
    normalizeRow(gray.ptr<uint8_t>(y), gain0, gain1, offset0, offset1, wy, width, out->ptr<uint8_t>(y));
  }
}

void IlluminationNormalizer::measure(const cv::Mat& gray, InputStatistics* statistics) {
  // The half-resolution image h (sums of 2 x 2 pixels) is formed row by row; its sums and sums of squares
  // accumulate per column over a block's rows, then per block. Pairs of h rows give the sums of 4 x 4 pixels of
  // the statistics.
  const int half_w = gray.cols / 2, half_h = gray.rows / 2;  // an odd last column or row is left out
  const int cells = 1 << (config_.level - 1);                // half-resolution pixels per block side
  const int blocks_across = (half_w + cells - 1) / cells, blocks_down = (half_h + cells - 1) / cells;
  block_mean_.create(blocks_down, blocks_across, CV_32F);
  block_mean_sq_.create(blocks_down, blocks_across, CV_32F);
  half_.resize(half_w);
  previous_half_.resize(half_w);
  column_sum_.resize(half_w);     // at most 32 rows of h <= 1020: fits 16 bits
  column_sum_sq_.resize(half_w);  // at most 32 rows of h^2 <= 1040400: fits 32 bits
  double quarter_sum = 0.0, quarter_sum_sq = 0.0;
  long quarter_count = 0;
  for (int by = 0; by < blocks_down; ++by) {
    std::fill(column_sum_.begin(), column_sum_.end(), uint16_t(0));
    std::fill(column_sum_sq_.begin(), column_sum_sq_.end(), 0u);
    const int j0 = by * cells, j1 = std::min(j0 + cells, half_h);
    for (int j = j0; j < j1; ++j) {
      const uint8_t* r0 = gray.ptr<uint8_t>(2 * j);
      const uint8_t* r1 = gray.ptr<uint8_t>(2 * j + 1);
      uint16_t* h = half_.data();
      uint16_t* sum = column_sum_.data();
      uint32_t* sum_sq = column_sum_sq_.data();
      int i = 0;
#if CV_SIMD128
      const cv::v_uint16x8 low_byte = cv::v_setall_u16(0xff);
      for (; i + 8 <= half_w; i += 8) {
        // Each 16-bit lane holds two neighbouring pixels.
        const cv::v_uint16x8 a = cv::v_reinterpret_as_u16(cv::v_load(r0 + 2 * i));
        const cv::v_uint16x8 b = cv::v_reinterpret_as_u16(cv::v_load(r1 + 2 * i));
        const cv::v_uint16x8 v = (a & low_byte) + cv::v_shr<8>(a) + (b & low_byte) + cv::v_shr<8>(b);
        cv::v_store(h + i, v);
        cv::v_store(sum + i, cv::v_load(sum + i) + v);
        cv::v_uint32x4 sq_low, sq_high;
        cv::v_mul_expand(v, v, sq_low, sq_high);
        cv::v_store(sum_sq + i, cv::v_load(sum_sq + i) + sq_low);
        cv::v_store(sum_sq + i + 4, cv::v_load(sum_sq + i + 4) + sq_high);
      }
#endif
      for (; i < half_w; ++i) {
        const uint16_t v = uint16_t(r0[2 * i] + r0[2 * i + 1] + r1[2 * i] + r1[2 * i + 1]);
        h[i] = v;
        sum[i] = uint16_t(sum[i] + v);
        sum_sq[i] += uint32_t(v) * v;
      }
      if (j % 2 == 1) {
        // q: sums of 4 x 4 pixels, from two rows of h.
        const uint16_t* above = previous_half_.data();
        const int quarter_w = half_w / 2;
        double row_sum = 0.0, row_sum_sq = 0.0;
        int k = 0;
#if CV_SIMD128
        cv::v_int32x4 lane_sum = cv::v_setzero_s32();
        cv::v_float32x4 lane_sum_sq = cv::v_setzero_f32();  // a check statistic: float sums are precise enough
        const cv::v_int16x8 ones = cv::v_setall_s16(1);
        for (; k + 4 <= quarter_w; k += 4) {
          const cv::v_int16x8 pairs = cv::v_reinterpret_as_s16(cv::v_load(above + 2 * k) + cv::v_load(h + 2 * k));
          const cv::v_int32x4 q = cv::v_dotprod(pairs, ones);  // at most 4080
          lane_sum += q;
          const cv::v_float32x4 qf = cv::v_cvt_f32(q);
          lane_sum_sq = cv::v_muladd(qf, qf, lane_sum_sq);
        }
        row_sum = cv::v_reduce_sum(lane_sum);
        row_sum_sq = cv::v_reduce_sum(lane_sum_sq);
#endif
        for (; k < quarter_w; ++k) {
          const double q = double(above[2 * k]) + above[2 * k + 1] + h[2 * k] + h[2 * k + 1];
          row_sum += q;
          row_sum_sq += q * q;
        }
        quarter_sum += row_sum;
        quarter_sum_sq += row_sum_sq;
        quarter_count += quarter_w;
      }
      half_.swap(previous_half_);
    }
    float* mean = block_mean_.ptr<float>(by);
    float* mean_sq = block_mean_sq_.ptr<float>(by);
    for (int bx = 0; bx < blocks_across; ++bx) {
      const int i0 = bx * cells, i1 = std::min(i0 + cells, half_w);
      double s = 0.0, s2 = 0.0;
      for (int i = i0; i < i1; ++i) {
        s += column_sum_[i];
        s2 += column_sum_sq_[i];
      }
      const double n = double(i1 - i0) * double(j1 - j0);  // half-resolution pixels in the block
      mean[bx] = float(s / (4.0 * n));                     // h is a sum of 4 pixels
      mean_sq[bx] = float(s2 / (16.0 * n));
    }
  }
  if (quarter_count > 0) {
    const double mean = quarter_sum / (16.0 * quarter_count);
    statistics->mean_grey = mean;
    statistics->stddev_grey = std::sqrt(std::max(quarter_sum_sq / (256.0 * quarter_count) - mean * mean, 0.0));
  } else {  // smaller than 4 x 4 pixels
    cv::Scalar mean, stddev;
    cv::meanStdDev(gray, mean, stddev);
    statistics->mean_grey = mean[0];
    statistics->stddev_grey = stddev[0];
  }

  // Columns of the interpolation from block centres to pixels, kept while the size stays.
  const int width = gray.cols;
  if (expand_width_ != width || expand_blocks_ != blocks_across) {
    expand_width_ = width;
    expand_blocks_ = blocks_across;
    expand_wx_.resize(width);
    expand_run_.assign(std::max(blocks_across, 2), width);
    expand_run_[0] = 0;
    const float block_px = float(1 << config_.level), centre_px = 0.5f * (block_px - 1.0f);
    for (int x = width - 1; x >= 0; --x) {
      const float cx = std::min(std::max((float(x) - centre_px) / block_px, 0.0f), float(blocks_across - 1));
      const int x0 = std::min(int(cx), std::max(blocks_across - 2, 0));
      expand_wx_[x] = blocks_across > 1 ? cx - float(x0) : 0.0f;
      expand_run_[x0] = x;  // columns [expand_run_[i], expand_run_[i + 1]) lie between the centres of i and i + 1
    }
  }
}

void IlluminationNormalizer::computeFields() {
  cv::GaussianBlur(block_mean_, block_mean_, cv::Size(), config_.sigma_level_px, 0.0, cv::BORDER_REFLECT);
  cv::GaussianBlur(block_mean_sq_, block_mean_sq_, cv::Size(), config_.sigma_level_px, 0.0, cv::BORDER_REFLECT);
  gain_.create(block_mean_.size(), CV_32F);
  offset_.create(block_mean_.size(), CV_32F);
  const float floor_sq = float(config_.min_contrast_grey * config_.min_contrast_grey);
  const float output_gain = float(config_.output_gain);
  for (int r = 0; r < gain_.rows; ++r) {
    const float* m = block_mean_.ptr<float>(r);
    const float* q = block_mean_sq_.ptr<float>(r);
    float* g = gain_.ptr<float>(r);
    float* f = offset_.ptr<float>(r);
    for (int c = 0; c < gain_.cols; ++c) {
      g[c] = output_gain / std::sqrt(std::max(q[c] - m[c] * m[c], floor_sq));
      f[c] = 128.0f - g[c] * m[c];
    }
  }
}

void IlluminationNormalizer::expandRow(int coarse_row, float* gain, float* offset) const {
  const float* g = gain_.ptr<float>(coarse_row);
  const float* f = offset_.ptr<float>(coarse_row);
  if (gain_.cols == 1) {
    std::fill(gain, gain + expand_width_, g[0]);
    std::fill(offset, offset + expand_width_, f[0]);
    return;
  }
  // Between two block centres the weights grow linearly: one run of columns per pair of blocks, no gathers.
  for (int i = 0; i + 1 < gain_.cols; ++i) {
    const float g0 = g[i], dg = g[i + 1] - g[i], f0 = f[i], df = f[i + 1] - f[i];
    const float* w = expand_wx_.data();
    for (int x = expand_run_[i]; x < expand_run_[i + 1]; ++x) {
      gain[x] = g0 + w[x] * dg;
      offset[x] = f0 + w[x] * df;
    }
  }
}

}  // namespace registration
}  // namespace exocet_mosaic
