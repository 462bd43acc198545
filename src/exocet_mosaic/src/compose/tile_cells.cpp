#include "tile_cells.h"

#include <algorithm>
#include <cmath>
#include <vector>

namespace exocet_mosaic {
namespace compose {

TileCells computeTileCells(const tiles::TileRaster& raster, double cell_size_m) {
  TileCells out;
  const cv::Mat& image = raster.image;
  if (image.empty() || cell_size_m <= 0.0 || raster.gsd_m <= 0.0) return out;
  const int channels = image.channels();
  const double gsd = raster.gsd_m;
  // Pixel centres: E = E0 + (col + 0.5) gsd, N = N0 - (row + 0.5) gsd.
  const auto cell_of = [cell_size_m](double metres) {
    return static_cast<std::int64_t>(std::floor(metres / cell_size_m));
  };
  const std::int64_t west = cell_of(raster.origin_easting_m + 0.5 * gsd);
  const std::int64_t east = cell_of(raster.origin_easting_m + (image.cols - 0.5) * gsd);
  const std::int64_t north = cell_of(raster.origin_northing_m - 0.5 * gsd);
  const std::int64_t south = cell_of(raster.origin_northing_m - (image.rows - 0.5) * gsd);
  const int cols = static_cast<int>(east - west + 1), rows = static_cast<int>(north - south + 1);
  std::vector<int> cell_col(image.cols);
  for (int c = 0; c < image.cols; ++c)
    cell_col[c] = static_cast<int>(cell_of(raster.origin_easting_m + (c + 0.5) * gsd) - west);

  cv::Mat sums(rows, cols, CV_64FC4, cv::Scalar::all(0));  // sum per channel, then pixel count
  for (int r = 0; r < image.rows; ++r) {
    const int row = static_cast<int>(north - cell_of(raster.origin_northing_m - (r + 0.5) * gsd));
    cv::Vec4d* acc = sums.ptr<cv::Vec4d>(row);
    const uchar* px = image.ptr<uchar>(r);
    const uchar* m = raster.mask.empty() ? nullptr : raster.mask.ptr<uchar>(r);
    for (int c = 0; c < image.cols; ++c) {
      if (m && !m[c]) continue;
      cv::Vec4d& a = acc[cell_col[c]];
      for (int k = 0; k < channels; ++k) a[k] += px[c * channels + k];
      a[3] += 1.0;
    }
  }
  // Crop to the cells with data: a tile's mask may leave much of its box empty.
  int r0 = rows, r1 = -1, c0 = cols, c1 = -1;
  for (int r = 0; r < rows; ++r)
    for (int c = 0; c < cols; ++c)
      if (sums.at<cv::Vec4d>(r, c)[3] > 0) {
        r0 = std::min(r0, r), r1 = std::max(r1, r), c0 = std::min(c0, c), c1 = std::max(c1, c);
      }
  if (r1 < 0) return out;
  const double pixels_per_cell = (cell_size_m / gsd) * (cell_size_m / gsd);
  out.west = west + c0;
  out.north = north - r0;
  out.mean.create(r1 - r0 + 1, c1 - c0 + 1, CV_32FC(channels));
  out.coverage.create(out.mean.size(), CV_32F);
  for (int r = 0; r < out.mean.rows; ++r)
    for (int c = 0; c < out.mean.cols; ++c) {
      const cv::Vec4d& a = sums.at<cv::Vec4d>(r + r0, c + c0);
      float* mean = out.mean.ptr<float>(r) + c * channels;
      for (int k = 0; k < channels; ++k) mean[k] = a[3] > 0 ? static_cast<float>(a[k] / a[3]) : 0.0f;
      out.coverage.at<float>(r, c) = static_cast<float>(std::min(1.0, a[3] / pixels_per_cell));
    }
  return out;
}

cv::Mat packTileCells(const TileCells& cells) {
  if (cells.mean.empty()) return cv::Mat();
  const int channels = cells.mean.channels();
  cv::Mat packed(cells.mean.size(), CV_16UC(channels + 1));
  for (int r = 0; r < packed.rows; ++r) {
    const float* mean = cells.mean.ptr<float>(r);
    const float* cov = cells.coverage.ptr<float>(r);
    ushort* p = packed.ptr<ushort>(r);
    for (int c = 0; c < packed.cols; ++c) {
      for (int k = 0; k < channels; ++k)
        p[c * (channels + 1) + k] = cv::saturate_cast<ushort>(mean[c * channels + k] * 256.0f);
      p[c * (channels + 1) + channels] = cv::saturate_cast<ushort>(cov[c] * 65535.0f);
    }
  }
  return packed;
}

void unpackTileCells(const cv::Mat& packed, TileCells* cells) {
  if (packed.empty()) {
    cells->mean.release();
    cells->coverage.release();
    return;
  }
  const int channels = packed.channels() - 1;
  cells->mean.create(packed.size(), CV_32FC(channels));
  cells->coverage.create(packed.size(), CV_32F);
  for (int r = 0; r < packed.rows; ++r) {
    const ushort* p = packed.ptr<ushort>(r);
    float* mean = cells->mean.ptr<float>(r);
    float* cov = cells->coverage.ptr<float>(r);
    for (int c = 0; c < packed.cols; ++c) {
      for (int k = 0; k < channels; ++k) mean[c * channels + k] = p[c * (channels + 1) + k] / 256.0f;
      cov[c] = p[c * (channels + 1) + channels] / 65535.0f;
    }
  }
}

std::string tileFrameKey(const tiles::TileRaster& raster) {
  if (!raster.local_frame.empty()) return "local:" + raster.local_frame;
  return "utm:" + std::to_string(raster.utm_zone) + (raster.northern_hemisphere ? "N" : "S");
}

}  // namespace compose
}  // namespace exocet_mosaic
