#include "exocet_mosaic/compose/tile_gain_compensator.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "exocet_common/atomic_file.h"
#include "tile_cells.h"

namespace exocet_mosaic {
namespace compose {

std::string TileGainConfig::validate() const {
  std::vector<std::string> bad;
  auto check = [&bad](bool ok, const std::string& name, const std::string& range, double value) {
    if (ok) return;
    std::ostringstream s;
    s << name << " must be " << range << ", got " << value;
    bad.push_back(s.str());
  };
  check(cell_size_px >= 4 && cell_size_px <= 128, "cell_size_px", "in [4, 128]", cell_size_px);
  check(min_cell_coverage >= 0.05 && min_cell_coverage <= 1.0, "min_cell_coverage", "in [0.05, 1]", min_cell_coverage);
  check(min_common_cells >= 1 && min_common_cells <= 100000, "min_common_cells", "in [1, 100000]", min_common_cells);
  check(prior_weight >= 0.0 && prior_weight <= 10.0, "prior_weight", "in [0, 10]", prior_weight);
  check(max_gain >= 1.0 && max_gain <= 10.0, "max_gain", "in [1, 10]", max_gain);
  check(huber_k >= 0.5 && huber_k <= 100.0, "huber_k", "in [0.5, 100]", huber_k);
  check(seam_ramp_cells >= 0.0 && seam_ramp_cells <= 1000.0, "seam_ramp_cells", "in [0, 1000]", seam_ramp_cells);
  check(cells_in_memory_tiles >= 1 && cells_in_memory_tiles <= 100000, "cells_in_memory_tiles", "in [1, 100000]",
        cells_in_memory_tiles);
  std::string joined;
  for (const auto& b : bad) joined += (joined.empty() ? "" : "; ") + b;
  return joined;
}

namespace {

constexpr double kLumaBgr[3] = {0.114, 0.587, 0.299};
constexpr float kSaturatedGrey = 250.0f;  // cells at the top of the range do not scale with the gain
constexpr float kDarkGrey = 2.0f;         // nor do (near) black ones: no information on a gain

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  const auto mid = v.begin() + v.size() / 2;
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

/// gain minimising sum w rho(gain * m - r): Huber IRLS from the median ratio, cells beyond 3 Huber thresholds
/// dropped; the robust sigma (1.4826 MAD, at least 1 grey level) re-estimated at each iteration. kept: 1 per cell kept.
double robustGain(const std::vector<double>& m, const std::vector<double>& r, const std::vector<double>& w,
                  double huber_k, std::vector<char>* kept) {
  const std::size_t n = m.size();
  std::vector<double> ratios;
  for (std::size_t i = 0; i < n; ++i)
    if (m[i] > kDarkGrey) ratios.push_back(r[i] / m[i]);
  double gain = ratios.empty() ? 1.0 : median(ratios);  // robust start: an outlier patch cannot drag it
  kept->assign(n, 1);
  std::vector<double> abs_residual(n);
  for (int iteration = 0; iteration < 30; ++iteration) {
    for (std::size_t i = 0; i < n; ++i) abs_residual[i] = std::abs(gain * m[i] - r[i]);
    const double threshold = huber_k * std::max(1.0, 1.4826 * median(abs_residual));
    double num = 0.0, den = 0.0;
    for (std::size_t i = 0; i < n; ++i) {
      const double e = abs_residual[i];
      const double u = e <= threshold ? 1.0 : (e > 3.0 * threshold ? 0.0 : threshold / e);
      (*kept)[i] = u > 0.0;
      num += w[i] * u * m[i] * r[i];
      den += w[i] * u * m[i] * m[i];
    }
    if (den <= 0.0) break;
    const double next = num / den;
    const bool converged = std::abs(next - gain) < 1e-7;
    gain = next;
    if (converged) break;
  }
  return gain;
}

}  // namespace

TileGainCompensator::TileGainCompensator(const TileGainConfig& config) : config_(config) {
  const std::string error = config.validate();
  if (!error.empty()) throw std::invalid_argument("TileGainConfig: " + error);
}

TileGains TileGainCompensator::estimate(const tiles::TileRaster& raster, int tile_index) const {
  TileGains out;
  const int channels = raster.image.channels();
  out.channels = channels;
  const double prior = config_.prior_weight;
  const auto clamp_gain = [this](double g) { return std::clamp(g, 1.0 / config_.max_gain, config_.max_gain); };
  const auto pulled = [&](double g) { return clamp_gain((g + prior) / (1.0 + prior)); };

  const auto no_overlap = [&](int common_cells) {
    out.common_cells = common_cells;
    const Record* last = nullptr;
    for (const auto& [index, record] : records_)
      if (index != tile_index && record.gains.channels == channels && (!last || record.sequence > last->sequence))
        last = &record;
    for (int k = 0; k < channels; ++k) out.gain[k] = out.far_gain[k] = last ? pulled(last->gains.far_gain[k]) : 1.0;
    return out;
  };
  if (raster.image.empty() || cell_size_m_ <= 0.0 || tileFrameKey(raster) != frame_) return no_overlap(0);

  const TileCells cells = computeTileCells(raster, cell_size_m_);
  if (cells.mean.empty()) return no_overlap(0);
  // The written tiles' corrected levels on the new tile's cells: coverage-weighted sums over the records.
  cv::Mat ref_sum(cells.mean.size(), CV_32FC(channels), cv::Scalar::all(0));
  cv::Mat ref_cov(cells.mean.size(), CV_32F, cv::Scalar::all(0));
  for (const auto& [index, record] : records_) {
    if (index == tile_index || record.cell_rows == 0 || record.cell_channels != channels + 1) continue;
    // Record cell (row, col) is cell row record.north - row, column record.west + col.
    const std::int64_t row_shift = cells.north - record.cell_north;  // new row = record row + row_shift
    const std::int64_t col_shift = record.cell_west - cells.west;    // new col = record col + col_shift
    const std::int64_t r0 = std::max<std::int64_t>(0, -row_shift);
    const std::int64_t r1 = std::min<std::int64_t>(record.cell_rows, cells.mean.rows - row_shift);
    const std::int64_t c0 = std::max<std::int64_t>(0, -col_shift);
    const std::int64_t c1 = std::min<std::int64_t>(record.cell_cols, cells.mean.cols - col_shift);
    if (r0 >= r1 || c0 >= c1) continue;
    cv::Mat packed = record.cells;
    if (!record.file.empty()) {
      cv::Mat ramp;
      if (!readBack(record, &packed, &ramp)) continue;  // counted: this tile's overlap is left out
    }
    TileCells written;
    unpackTileCells(packed, &written);
    for (std::int64_t r = r0; r < r1; ++r)
      for (std::int64_t c = c0; c < c1; ++c) {
        const float cov = written.coverage.at<float>(r, c);
        if (cov <= 0.0f) continue;
        const int nr = static_cast<int>(r + row_shift), nc = static_cast<int>(c + col_shift);
        const float* mean = written.mean.ptr<float>(r) + c * channels;
        float* sum = ref_sum.ptr<float>(nr) + nc * channels;
        for (int k = 0; k < channels; ++k) sum[k] += cov * mean[k];
        ref_cov.at<float>(nr, nc) += cov;
      }
  }

  // The common cells.
  std::vector<std::vector<double>> raw(channels), written(channels);
  std::vector<double> weight;
  cv::Mat common(cells.mean.size(), CV_8U, cv::Scalar(0));
  const float min_cov = static_cast<float>(config_.min_cell_coverage);
  for (int r = 0; r < cells.mean.rows; ++r)
    for (int c = 0; c < cells.mean.cols; ++c) {
      const float cov_new = cells.coverage.at<float>(r, c), cov_ref = ref_cov.at<float>(r, c);
      if (cov_new < min_cov || cov_ref < min_cov) continue;
      const float* m = cells.mean.ptr<float>(r) + c * channels;
      const float* s = ref_sum.ptr<float>(r) + c * channels;
      bool usable = true;
      for (int k = 0; k < channels; ++k) {
        const float ref = s[k] / cov_ref;
        usable = usable && m[k] > kDarkGrey && m[k] < kSaturatedGrey && ref > kDarkGrey && ref < kSaturatedGrey;
      }
      if (!usable) continue;
      for (int k = 0; k < channels; ++k) {
        raw[k].push_back(m[k]);
        written[k].push_back(s[k] / cov_ref);
      }
      weight.push_back(std::min(1.0f, std::min(cov_new, cov_ref)));
      common.at<uchar>(r, c) = 1;
    }
  const int n = static_cast<int>(weight.size());
  if (n < config_.min_common_cells) return no_overlap(n);

  out.from_overlap = true;
  out.common_cells = n;
  std::vector<char> kept_all(n, 1), kept;
  std::array<double, 3> fitted{1, 1, 1};
  for (int k = 0; k < channels; ++k) {
    fitted[k] = clamp_gain(robustGain(raw[k], written[k], weight, config_.huber_k, &kept));
    for (int i = 0; i < n; ++i) kept_all[i] = kept_all[i] && kept[i];
    out.far_gain[k] = pulled(fitted[k]);
    out.gain[k] = config_.seam_ramp_cells > 0.0 ? fitted[k] : out.far_gain[k];
  }
  out.inlier_cells = static_cast<int>(std::count(kept_all.begin(), kept_all.end(), 1));

  // Diagnostics: the luma step over the kept cells before and after.
  double before = 0.0, after = 0.0, sum_w = 0.0;
  for (int i = 0; i < n; ++i) {
    if (!kept_all[i]) continue;
    for (int k = 0; k < channels; ++k) {
      const double luma = channels == 1 ? 1.0 : kLumaBgr[k];
      before += weight[i] * luma * (raw[k][i] - written[k][i]);
      after += weight[i] * luma * (out.gain[k] * raw[k][i] - written[k][i]);
    }
    sum_w += weight[i];
  }
  if (sum_w > 0.0) out.step_before_grey = before / sum_w, out.step_after_grey = after / sum_w;

  if (config_.seam_ramp_cells > 0.0) {
    // Distance (cells) to the nearest common cell, eased by a raised cosine: 1 on the overlap, 0 from the ramp's end.
    cv::Mat distance;
    cv::distanceTransform(1 - common, distance, cv::DIST_L2, cv::DIST_MASK_PRECISE);
    out.ramp.create(distance.size(), CV_8U);
    const double length = config_.seam_ramp_cells;
    for (int r = 0; r < distance.rows; ++r)
      for (int c = 0; c < distance.cols; ++c) {
        const double d = distance.at<float>(r, c);
        out.ramp.at<uchar>(r, c) =
            d >= length ? 0 : cv::saturate_cast<uchar>(127.5 * (1.0 + std::cos(CV_PI * d / length)));
      }
    out.ramp_cell_west = cells.west;
    out.ramp_cell_north = cells.north;
    out.cell_size_m = cell_size_m_;
  }
  return out;
}

std::array<double, 3> gainAt(const TileGains& gains, double east_m, double north_m) {
  std::array<double, 3> out{1.0, 1.0, 1.0};
  const int channels = std::clamp(gains.channels, 1, 3);
  double ramp = 0.0;  // 0: far_gain, 1: gain
  if (!gains.ramp.empty() && gains.cell_size_m > 0.0 && std::isfinite(east_m) && std::isfinite(north_m)) {
    // Cell coordinates with the cell centres at integers, as apply() maps its pixels.
    const double u = east_m / gains.cell_size_m - static_cast<double>(gains.ramp_cell_west) - 0.5;
    const double v = static_cast<double>(gains.ramp_cell_north) + 0.5 - north_m / gains.cell_size_m;
    const double uc = std::clamp(u, 0.0, static_cast<double>(gains.ramp.cols - 1));
    const double vc = std::clamp(v, 0.0, static_cast<double>(gains.ramp.rows - 1));
    const int u0 = static_cast<int>(std::floor(uc)), v0 = static_cast<int>(std::floor(vc));
    const int u1 = std::min(u0 + 1, gains.ramp.cols - 1), v1 = std::min(v0 + 1, gains.ramp.rows - 1);
    const double fu = uc - u0, fv = vc - v0;
    const auto at = [&](int r, int c) { return static_cast<double>(gains.ramp.at<uchar>(r, c)); };
    ramp = ((1 - fv) * ((1 - fu) * at(v0, u0) + fu * at(v0, u1)) + fv * ((1 - fu) * at(v1, u0) + fu * at(v1, u1))) /
           255.0;
  }
  for (int k = 0; k < channels; ++k) out[k] = gains.far_gain[k] + ramp * (gains.gain[k] - gains.far_gain[k]);
  return out;
}

tiles::TileRaster TileGainCompensator::apply(const tiles::TileRaster& raster, const TileGains& gains) {
  const int channels = raster.image.channels();
  if (raster.image.depth() != CV_8U || channels != gains.channels)
    throw std::invalid_argument("TileGainCompensator::apply: the raster has " + std::to_string(channels) +
                                " channel(s) (CV_8U expected), the gains " + std::to_string(gains.channels));
  tiles::TileRaster out = raster;
  if (raster.image.empty()) return out;
  out.image = cv::Mat();  // the copy shares the caller's pixels: write new ones
  if (gains.ramp.empty() || gains.cell_size_m <= 0.0) {
    cv::multiply(raster.image, cv::Scalar(gains.far_gain[0], gains.far_gain[1], gains.far_gain[2]), out.image);
    return out;
  }
  // The ramp at the pixel centres: cell coordinates (u, v) with the cell centres at integers.
  const double gsd = raster.gsd_m, cell = gains.cell_size_m;
  const cv::Matx23d pixel_to_cell(
      gsd / cell, 0.0, (raster.origin_easting_m + 0.5 * gsd) / cell - static_cast<double>(gains.ramp_cell_west) - 0.5,
      0.0, gsd / cell,
      static_cast<double>(gains.ramp_cell_north) + 0.5 - (raster.origin_northing_m - 0.5 * gsd) / cell);
  cv::Mat ramp;
  cv::warpAffine(gains.ramp, ramp, pixel_to_cell, raster.image.size(), cv::INTER_LINEAR | cv::WARP_INVERSE_MAP,
                 cv::BORDER_REPLICATE);
  std::array<float, 3> far{}, delta{};
  for (int k = 0; k < channels; ++k) {
    far[k] = static_cast<float>(gains.far_gain[k]);
    delta[k] = static_cast<float>((gains.gain[k] - gains.far_gain[k]) / 255.0);
  }
  out.image.create(raster.image.size(), raster.image.type());
  for (int r = 0; r < raster.image.rows; ++r) {
    const uchar* src = raster.image.ptr<uchar>(r);
    const uchar* b = ramp.ptr<uchar>(r);
    uchar* dst = out.image.ptr<uchar>(r);
    for (int c = 0; c < raster.image.cols; ++c)
      for (int k = 0; k < channels; ++k)
        dst[c * channels + k] = cv::saturate_cast<uchar>(src[c * channels + k] * (far[k] + b[c] * delta[k]));
  }
  return out;
}

void TileGainCompensator::record(int tile_index, const tiles::TileRaster& corrected, const TileGains& gains) {
  if (cell_size_m_ <= 0.0 && !corrected.image.empty() && corrected.gsd_m > 0.0) {
    cell_size_m_ = config_.cell_size_px * corrected.gsd_m;
    frame_ = tileFrameKey(corrected);
  }
  Record record;
  record.gains = gains;
  record.sequence = next_sequence_++;
  if (cell_size_m_ > 0.0 && tileFrameKey(corrected) == frame_) {  // another frame: gains only, no cells
    const TileCells cells = computeTileCells(corrected, cell_size_m_);
    record.cell_west = cells.west;
    record.cell_north = cells.north;
    record.cells = packTileCells(cells);
    record.cell_rows = record.cells.rows;
    record.cell_cols = record.cells.cols;
    record.cell_channels = record.cells.channels();
  }
  const auto old = records_.find(tile_index);
  if (old != records_.end()) removeFile(old->second);  // a new version: the old cells go
  records_[tile_index] = std::move(record);
  spillBeyondLimit();
}

std::optional<TileGains> TileGainCompensator::gainsOf(int tile_index) const {
  const auto it = records_.find(tile_index);
  if (it == records_.end()) return std::nullopt;
  TileGains gains = it->second.gains;
  if (!it->second.file.empty()) {
    cv::Mat cells;
    readBack(it->second, &cells, &gains.ramp);  // without its ramp (counted) the tile takes its far gains
  }
  return gains;
}

// Written out: "EXTG" and a version, then the cells and the ramp, each rows, cols, type and bytes.
namespace {
constexpr std::uint32_t kCellsMagic = 0x47545845;  // "EXTG"
constexpr std::uint32_t kCellsVersion = 1;

void putMat(std::string* out, const cv::Mat& m) {
  const std::int32_t header[3] = {m.rows, m.cols, m.type()};
  out->append(reinterpret_cast<const char*>(header), sizeof(header));
  const cv::Mat c = m.isContinuous() ? m : m.clone();
  if (!c.empty()) out->append(reinterpret_cast<const char*>(c.data), c.total() * c.elemSize());
}

bool getMat(std::istream& in, cv::Mat* m) {
  std::int32_t header[3];
  if (!in.read(reinterpret_cast<char*>(header), sizeof(header))) return false;
  if (header[0] < 0 || header[1] < 0 || header[0] > 1000000 || header[1] > 1000000) return false;
  if (header[0] == 0 || header[1] == 0) {
    *m = cv::Mat();
    return true;
  }
  m->create(header[0], header[1], header[2]);
  return bool(in.read(reinterpret_cast<char*>(m->data), static_cast<std::streamsize>(m->total() * m->elemSize())));
}
}  // namespace

void TileGainCompensator::spillBeyondLimit() {
  if (config_.cells_folder.empty()) return;
  std::vector<std::pair<std::uint64_t, int>> in_memory;  // (sequence, index)
  for (const auto& [index, record] : records_)
    if (record.file.empty() && (!record.cells.empty() || !record.gains.ramp.empty()))
      in_memory.emplace_back(record.sequence, index);
  if (in_memory.size() <= static_cast<std::size_t>(config_.cells_in_memory_tiles)) return;
  std::sort(in_memory.begin(), in_memory.end());
  const std::size_t excess = in_memory.size() - static_cast<std::size_t>(config_.cells_in_memory_tiles);
  for (std::size_t i = 0; i < excess; ++i) {
    Record& record = records_.at(in_memory[i].second);
    const std::string path = config_.cells_folder + "/tile_cells_" + std::to_string(in_memory[i].second) + ".bin";
    std::string bytes;
    bytes.append(reinterpret_cast<const char*>(&kCellsMagic), sizeof(kCellsMagic));
    bytes.append(reinterpret_cast<const char*>(&kCellsVersion), sizeof(kCellsVersion));
    putMat(&bytes, record.cells);
    putMat(&bytes, record.gains.ramp);
    try {
      exocet_common::writeFileAtomically(path, bytes);
    } catch (const std::exception&) {
      ++spill_failures_;  // kept in memory: nothing is lost, memory grows (a full disk, a missing folder)
      continue;
    }
    record.file = path;
    record.cells.release();
    record.gains.ramp.release();
  }
}

bool TileGainCompensator::readBack(const Record& record, cv::Mat* cells, cv::Mat* ramp) const {
  std::ifstream in(record.file, std::ios::binary);
  std::uint32_t magic = 0, version = 0;
  cv::Mat c, r;
  const bool ok = in.read(reinterpret_cast<char*>(&magic), sizeof(magic)) &&
                  in.read(reinterpret_cast<char*>(&version), sizeof(version)) && magic == kCellsMagic &&
                  version == kCellsVersion && getMat(in, &c) && getMat(in, &r) && c.rows == record.cell_rows &&
                  c.cols == record.cell_cols && (c.empty() || c.channels() == record.cell_channels);
  if (!ok) {
    ++read_failures_;
    return false;
  }
  *cells = c;
  *ramp = r;
  return true;
}

void TileGainCompensator::removeFile(const Record& record) const {
  if (record.file.empty()) return;
  std::error_code ignored;
  std::filesystem::remove(record.file, ignored);
}

std::size_t TileGainCompensator::spilledCount() const {
  return static_cast<std::size_t>(
      std::count_if(records_.begin(), records_.end(), [](const auto& r) { return !r.second.file.empty(); }));
}

bool TileGainCompensator::forget(int tile_index) {
  const auto it = records_.find(tile_index);
  if (it == records_.end()) return false;
  removeFile(it->second);
  records_.erase(it);
  return true;
}

void TileGainCompensator::clear() {
  for (const auto& [index, record] : records_) removeFile(record);
  records_.clear();
  cell_size_m_ = 0.0;
  frame_.clear();
}

std::size_t TileGainCompensator::memoryBytes() const {
  std::size_t bytes = 0;
  for (const auto& [index, record] : records_)
    bytes += sizeof(Record) + record.cells.total() * record.cells.elemSize() +
             record.gains.ramp.total() * record.gains.ramp.elemSize();
  return bytes;
}

}  // namespace compose
}  // namespace exocet_mosaic
