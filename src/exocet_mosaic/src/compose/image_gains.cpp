#include "exocet_mosaic/compose/image_gains.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <unordered_map>

#include <Eigen/Sparse>
#include <Eigen/SparseCholesky>
#include <opencv2/imgproc.hpp>

namespace exocet_mosaic {
namespace compose {

std::string ImageGainsConfig::validate() const {
  std::ostringstream e;
  if (grid_columns < 2 || grid_columns > 256) e << "grid_columns = " << grid_columns << " outside [2, 256]; ";
  if (grid_rows < 2 || grid_rows > 256) e << "grid_rows = " << grid_rows << " outside [2, 256]; ";
  if (!(cell_size_m >= 0.0 && cell_size_m <= 100.0)) e << "cell_size_m = " << cell_size_m << " outside [0, 100] m; ";
  if (!(cell_sigma > 0.0 && cell_sigma <= 10.0)) e << "cell_sigma = " << cell_sigma << " outside (0, 10]; ";
  if (!(gain_sigma > 0.0 && gain_sigma <= 10.0)) e << "gain_sigma = " << gain_sigma << " outside (0, 10]; ";
  if (min_common_cells < 1 || min_common_cells > 100000)
    e << "min_common_cells = " << min_common_cells << " outside [1, 100000]; ";
  if (!(max_gain >= 1.0 && max_gain <= 10.0)) e << "max_gain = " << max_gain << " outside [1, 10]; ";
  if (!(min_level >= 0.0 && min_level <= 254.0)) e << "min_level = " << min_level << " outside [0, 254] grey; ";
  std::string s = e.str();
  if (s.size() >= 2) s.resize(s.size() - 2);
  return s;
}

ImageLevels imageLevels(const cv::Mat& image, int grid_columns, int grid_rows) {
  if (image.empty() || image.depth() != CV_8U || (image.channels() != 1 && image.channels() != 3))
    throw std::invalid_argument("imageLevels: the image must be 8-bit with 1 or 3 channels");
  if (grid_columns < 1 || grid_rows < 1 || grid_columns > image.cols || grid_rows > image.rows)
    throw std::invalid_argument("imageLevels: the grid must have at least one block and no more than the pixels");
  ImageLevels out;
  out.image_size = image.size();
  cv::Mat as_float;
  image.convertTo(as_float, CV_32F);
  // INTER_AREA to an exact divisor is the block mean; otherwise the area-weighted mean of the pixels a block covers.
  cv::resize(as_float, out.block_mean, cv::Size(grid_columns, grid_rows), 0, 0, cv::INTER_AREA);
  return out;
}

ImageGains::ImageGains(const ImageGainsConfig& config) : config_(config) {
  const std::string error = config.validate();
  if (!error.empty()) throw std::invalid_argument("ImageGains: " + error);
}

bool ImageGains::add(const std::string& id, ImageLevels levels) {
  if (levels.block_mean.empty() || levels.block_mean.depth() != CV_32F) return false;
  if (levels.block_mean.cols != config_.grid_columns || levels.block_mean.rows != config_.grid_rows) return false;
  if (channels_ == 0) channels_ = levels.channels();
  if (levels.channels() != channels_) return false;
  levels_[id] = std::move(levels);
  return true;
}

std::size_t ImageGains::memoryBytes() const {
  std::size_t bytes = 0;
  for (const auto& [id, l] : levels_) bytes += id.size() + l.block_mean.total() * l.block_mean.elemSize() + 64;
  return bytes;
}

namespace {

struct PairSums {
  int cells = 0;
  std::array<std::vector<float>, 3> log_ratio;  // per common cell, log(level_b / level_a)
  std::array<double, 3> level_a{0, 0, 0}, level_b{0, 0, 0};
};

/// The median of v (reordered).
double median(std::vector<float>& v) {
  const std::size_t h = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + h, v.end());
  if (v.size() % 2 == 1) return v[h];
  return 0.5 * (v[h] + *std::max_element(v.begin(), v.begin() + h));
}

std::uint64_t cellKey(double e, double n, double size) {
  const auto ix = static_cast<std::int64_t>(std::floor(e / size));
  const auto iy = static_cast<std::int64_t>(std::floor(n / size));
  return (static_cast<std::uint64_t>(ix) << 32) ^ (static_cast<std::uint64_t>(iy) & 0xffffffffULL);
}

cv::Point2d apply(const cv::Matx33d& h, double u, double v) {
  const cv::Vec3d p = h * cv::Vec3d(u, v, 1.0);
  return {p[0] / p[2], p[1] / p[2]};
}

}  // namespace

ImageGainSolution ImageGains::solve(const std::map<std::string, ImagePlacement>& placements,
                                    const std::map<std::string, std::array<double, 3>>& fixed_gains) const {
  ImageGainSolution out;
  const int nc = channels_;
  const int cols = config_.grid_columns, rows = config_.grid_rows;
  struct Placed {
    const std::string* id;
    const ImageLevels* levels;
    const ImagePlacement* placement;
  };
  std::vector<Placed> placed;
  std::vector<double> block_sizes_m;
  for (const auto& [id, placement] : placements) {
    const auto levels = levels_.find(id);
    if (levels == levels_.end()) continue;
    const cv::Matx33d& h = placement.en_from_px;
    bool finite = true;
    for (int i = 0; i < 9; ++i) finite = finite && std::isfinite(h.val[i]);
    if (!finite) continue;
    const cv::Size size = levels->second.image_size;
    const double bu = static_cast<double>(size.width) / cols, bv = static_cast<double>(size.height) / rows;
    const cv::Point2d c = apply(h, 0.5 * size.width, 0.5 * size.height);
    const cv::Point2d r = apply(h, 0.5 * size.width + bu, 0.5 * size.height);
    const cv::Point2d d = apply(h, 0.5 * size.width, 0.5 * size.height + bv);
    const double block_m = std::sqrt(std::hypot(r.x - c.x, r.y - c.y) * std::hypot(d.x - c.x, d.y - c.y));
    if (!(block_m > 0.0) || !std::isfinite(block_m)) continue;
    block_sizes_m.push_back(block_m);
    placed.push_back({&id, &levels->second, &placement});
  }
  out.images = static_cast<int>(placed.size());
  // Unknown of each placed image; -1 for a fixed one, whose log gain is known.
  std::vector<int> unknown(placed.size(), -1);
  std::vector<std::array<double, 3>> known_log(placed.size(), std::array<double, 3>{0, 0, 0});
  int n = 0;
  for (std::size_t k = 0; k < placed.size(); ++k) {
    const auto f = fixed_gains.find(*placed[k].id);
    if (f == fixed_gains.end()) {
      unknown[k] = n++;
      continue;
    }
    ++out.fixed_images;
    for (int ch = 0; ch < 3; ++ch) known_log[k][ch] = std::log(std::clamp(f->second[ch], 1e-6, 1e6));
  }
  if (placed.size() < 2) {
    out.problem = "fewer than two images placed";
    return out;
  }
  std::nth_element(block_sizes_m.begin(), block_sizes_m.begin() + block_sizes_m.size() / 2, block_sizes_m.end());
  const double cell_m = config_.cell_size_m > 0.0 ? config_.cell_size_m : block_sizes_m[block_sizes_m.size() / 2];
  out.cell_size_m = cell_m;

  // Every usable block in its ground cell: (image, level per channel), the lighting gain applied.
  struct Sample {
    int image;
    std::array<float, 3> level;
  };
  std::unordered_map<std::uint64_t, std::vector<Sample>> cells;
  cells.reserve(placed.size() * static_cast<std::size_t>(cols * rows) / 2);
  for (int k = 0; k < static_cast<int>(placed.size()); ++k) {
    const ImageLevels& levels = *placed[k].levels;
    const cv::Mat& gain = placed[k].placement->block_gain;
    const bool lit =
        !gain.empty() && gain.size() == levels.block_mean.size() && gain.channels() == nc && gain.depth() == CV_32F;
    const double bu = static_cast<double>(levels.image_size.width) / cols;
    const double bv = static_cast<double>(levels.image_size.height) / rows;
    for (int r = 0; r < rows; ++r) {
      const float* m = levels.block_mean.ptr<float>(r);
      const float* g = lit ? gain.ptr<float>(r) : nullptr;
      for (int c = 0; c < cols; ++c) {
        Sample s{k, {0, 0, 0}};
        bool usable = true;
        for (int ch = 0; ch < nc; ++ch) {
          const float v = m[c * nc + ch] * (g ? g[c * nc + ch] : 1.0f);
          usable = usable && std::isfinite(v) && v >= config_.min_level;
          s.level[ch] = v;
        }
        if (!usable) continue;
        const cv::Point2d p = apply(placed[k].placement->en_from_px, (c + 0.5) * bu, (r + 0.5) * bv);
        if (!std::isfinite(p.x) || !std::isfinite(p.y)) continue;
        cells[cellKey(p.x, p.y, cell_m)].push_back(s);
      }
    }
  }

  // Per cell, each image's mean level there; every pair of images in the cell adds its log ratio.
  const double max_log = std::log(config_.max_gain) * 2.0;  // a ratio beyond what two gains can take is not a level
  std::unordered_map<std::uint64_t, PairSums> pairs;
  std::vector<std::pair<int, std::array<double, 4>>> in_cell;  // image, level sums + count
  for (auto& [key, samples] : cells) {
    if (samples.size() < 2) continue;
    in_cell.clear();
    for (const Sample& s : samples) {
      auto it = std::find_if(in_cell.begin(), in_cell.end(), [&](const auto& e) { return e.first == s.image; });
      if (it == in_cell.end()) {
        in_cell.push_back({s.image, {0, 0, 0, 0}});
        it = in_cell.end() - 1;
      }
      for (int ch = 0; ch < nc; ++ch) it->second[ch] += s.level[ch];
      it->second[3] += 1.0;
    }
    for (std::size_t i = 0; i < in_cell.size(); ++i)
      for (std::size_t j = i + 1; j < in_cell.size(); ++j) {
        const int a = std::min(in_cell[i].first, in_cell[j].first), b = std::max(in_cell[i].first, in_cell[j].first);
        if (unknown[a] < 0 && unknown[b] < 0) continue;  // two known gains: nothing to solve
        const auto& la = in_cell[i].first == a ? in_cell[i].second : in_cell[j].second;
        const auto& lb = in_cell[i].first == a ? in_cell[j].second : in_cell[i].second;
        std::array<double, 3> ratio{0, 0, 0};
        bool usable = true;
        for (int ch = 0; ch < nc; ++ch) {
          ratio[ch] = std::log((lb[ch] / lb[3]) / (la[ch] / la[3]));
          usable = usable && std::abs(ratio[ch]) <= max_log;
        }
        if (!usable) continue;
        PairSums& p = pairs[(static_cast<std::uint64_t>(a) << 32) | static_cast<std::uint64_t>(b)];
        ++p.cells;
        for (int ch = 0; ch < nc; ++ch) {
          p.log_ratio[ch].push_back(static_cast<float>(ratio[ch]));
          p.level_a[ch] += la[ch] / la[3];
          p.level_b[ch] += lb[ch] / lb[3];
        }
      }
  }

  // Normal equations per channel: (x_a - x_b - r_ab) with weight cells / cell_sigma^2, x_a with weight
  // (the image's common cells) / gain_sigma^2; a fixed image's x moves to the right-hand side.
  std::vector<double> image_cells(placed.size(), 0.0);
  std::vector<std::pair<std::pair<int, int>, PairSums*>> used;
  for (auto& [key, p] : pairs) {
    if (p.cells < config_.min_common_cells) continue;
    const int a = static_cast<int>(key >> 32), b = static_cast<int>(key & 0xffffffffULL);
    used.push_back({{a, b}, &p});
    image_cells[a] += p.cells;
    image_cells[b] += p.cells;
  }
  out.pairs = static_cast<int>(used.size());
  if (used.empty()) {
    out.problem = n == 0 ? "every image placed has a fixed gain" : "no two images overlap on enough cells";
    return out;
  }
  const double wc = 1.0 / (config_.cell_sigma * config_.cell_sigma);
  const double wg = 1.0 / (config_.gain_sigma * config_.gain_sigma);
  std::vector<Eigen::Triplet<double>> triplets;
  triplets.reserve(used.size() * 4 + n);
  for (const auto& [ab, p] : used) {
    const double w = wc * p->cells;
    const int ua = unknown[ab.first], ub = unknown[ab.second];
    if (ua >= 0) triplets.emplace_back(ua, ua, w);
    if (ub >= 0) triplets.emplace_back(ub, ub, w);
    if (ua >= 0 && ub >= 0) {
      triplets.emplace_back(ua, ub, -w);
      triplets.emplace_back(ub, ua, -w);
    }
  }
  for (std::size_t k = 0; k < placed.size(); ++k)
    if (unknown[k] >= 0) triplets.emplace_back(unknown[k], unknown[k], wg * std::max(1.0, image_cells[k]));
  Eigen::SparseMatrix<double> a(n, n);
  a.setFromTriplets(triplets.begin(), triplets.end());
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt(a);
  if (ldlt.info() != Eigen::Success) {
    out.problem = "the gains' normal equations could not be factorised";
    return out;
  }
  // Each pair's ratio: the median over its common cells (a cell where the texture under a coarse placement, a
  // shadow or a fish differs is not a level).
  std::vector<std::array<double, 3>> pair_ratio(used.size(), std::array<double, 3>{0, 0, 0});
  for (std::size_t i = 0; i < used.size(); ++i)
    for (int ch = 0; ch < nc; ++ch) pair_ratio[i][ch] = median(used[i].second->log_ratio[ch]);
  std::vector<std::array<double, 3>> gains(placed.size(), std::array<double, 3>{1.0, 1.0, 1.0});
  for (std::size_t k = 0; k < placed.size(); ++k)
    if (unknown[k] < 0)
      for (int ch = 0; ch < 3; ++ch) gains[k][ch] = std::exp(known_log[k][ch]);
  for (int ch = 0; ch < nc; ++ch) {
    Eigen::VectorXd rhs = Eigen::VectorXd::Zero(n);
    for (std::size_t i = 0; i < used.size(); ++i) {
      const auto& [ab, p] = used[i];
      const double w = wc * p->cells, r = pair_ratio[i][ch];
      const int ua = unknown[ab.first], ub = unknown[ab.second];
      // x_a - x_b = r: a known x_b adds (r + x_b) to a's side, a known x_a adds (x_a - r) to b's.
      if (ua >= 0) rhs[ua] += w * (ub >= 0 ? r : r + known_log[ab.second][ch]);
      if (ub >= 0) rhs[ub] += w * (ua >= 0 ? -r : known_log[ab.first][ch] - r);
    }
    const Eigen::VectorXd x = ldlt.solve(rhs);
    for (std::size_t k = 0; k < placed.size(); ++k)
      if (unknown[k] >= 0) gains[k][ch] = std::clamp(std::exp(x[unknown[k]]), 1.0 / config_.max_gain, config_.max_gain);
  }
  for (const auto& [ab, p] : used) {
    double before = 0, after = 0;
    for (int ch = 0; ch < nc; ++ch) {
      const double la = p->level_a[ch] / p->cells, lb = p->level_b[ch] / p->cells;
      before += (la - lb) / nc;
      after += (gains[ab.first][ch] * la - gains[ab.second][ch] * lb) / nc;
    }
    out.step_before_grey = std::max(out.step_before_grey, std::abs(before));
    out.step_after_grey = std::max(out.step_after_grey, std::abs(after));
  }
  for (std::size_t k = 0; k < placed.size(); ++k)
    if (unknown[k] >= 0 && image_cells[k] > 0) out.gain[*placed[k].id] = gains[k];
  return out;
}

}  // namespace compose
}  // namespace exocet_mosaic
