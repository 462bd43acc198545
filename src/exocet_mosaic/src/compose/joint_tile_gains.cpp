#include "exocet_mosaic/compose/joint_tile_gains.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <vector>

#include <Eigen/Dense>

#include "tile_cells.h"

namespace exocet_mosaic {
namespace compose {

std::string JointTileGainsConfig::validate() const {
  std::ostringstream e;
  const auto bad = [&e](const std::string& what) { e << (e.tellp() > 0 ? "; " : "") << what; };
  if (cell_size_px < 4 || cell_size_px > 128) bad("cell_size_px must be in [4, 128]");
  if (!(min_cell_coverage >= 0.05 && min_cell_coverage <= 1)) bad("min_cell_coverage must be in [0.05, 1]");
  if (min_common_cells < 1 || min_common_cells > 100000) bad("min_common_cells must be in [1, 100000]");
  if (!(prior_weight >= 1e-3 && prior_weight <= 100)) bad("prior_weight must be in [1e-3, 100]");
  if (!(max_gain >= 1 && max_gain <= 10)) bad("max_gain must be in [1, 10]");
  return e.str();
}

JointTileGains::JointTileGains(const JointTileGainsConfig& config) : config_(config) {
  const std::string error = config.validate();
  if (!error.empty()) throw std::invalid_argument("JointTileGains: " + error);
}

void JointTileGains::add(int tile_index, const tiles::TileRaster& raster) {
  if (raster.image.empty() || raster.gsd_m <= 0) return;
  if (cells_.empty() && cell_size_m_ <= 0) {
    cell_size_m_ = config_.cell_size_px * raster.gsd_m;
    channels_ = raster.image.channels();
    frame_ = tileFrameKey(raster);
  }
  if (raster.image.channels() != channels_ || tileFrameKey(raster) != frame_) return;
  const TileCells c = computeTileCells(raster, cell_size_m_);
  if (c.mean.empty()) return;
  cells_[tile_index] = {c.west, c.north, c.mean, c.coverage};
}

std::map<int, std::array<double, 3>> JointTileGains::solve() const {
  std::map<int, std::array<double, 3>> out;
  std::vector<int> indices;
  for (const auto& [index, c] : cells_) indices.push_back(index);
  const int n = static_cast<int>(indices.size());
  for (int index : indices) out[index] = {1.0, 1.0, 1.0};
  if (n == 0) return out;
  // Pairs: per channel, the median log ratio over the common cells.
  struct Pair {
    int a, b;
    double weight;
    std::array<double, 3> log_ratio;  // log(level_b / level_a)
  };
  std::vector<Pair> pairs;
  for (int i = 0; i < n; ++i)
    for (int j = i + 1; j < n; ++j) {
      const Cells& a = cells_.at(indices[i]);
      const Cells& b = cells_.at(indices[j]);
      // Overlap of their cell boxes (row r is cell row north - r).
      const std::int64_t west = std::max(a.west, b.west);
      const std::int64_t east = std::min(a.west + a.mean.cols, b.west + b.mean.cols);
      const std::int64_t north = std::min(a.north, b.north);
      const std::int64_t south = std::max(a.north - a.mean.rows, b.north - b.mean.rows);
      if (east <= west || north <= south) continue;
      std::array<std::vector<double>, 3> ratios;
      std::array<std::vector<std::pair<double, double>>, 3> levels;  // (a, b) per common cell
      for (std::int64_t row = north; row > south; --row)
        for (std::int64_t col = west; col < east; ++col) {
          const int ra = static_cast<int>(a.north - row), ca = static_cast<int>(col - a.west);
          const int rb = static_cast<int>(b.north - row), cb = static_cast<int>(col - b.west);
          if (a.coverage.at<float>(ra, ca) < config_.min_cell_coverage ||
              b.coverage.at<float>(rb, cb) < config_.min_cell_coverage)
            continue;
          const float* ma = a.mean.ptr<float>(ra) + ca * channels_;
          const float* mb = b.mean.ptr<float>(rb) + cb * channels_;
          bool usable = true;
          for (int k = 0; k < channels_; ++k) usable = usable && ma[k] > 2.0f && mb[k] > 2.0f;  // no information in black
          if (!usable) continue;
          for (int k = 0; k < channels_; ++k) {
            ratios[k].push_back(std::log(mb[k] / ma[k]));
            levels[k].emplace_back(ma[k], mb[k]);
          }
        }
      if (static_cast<int>(ratios[0].size()) < config_.min_common_cells) continue;
      Pair p{i, j, static_cast<double>(ratios[0].size()), {0, 0, 0}};
      for (int k = 0; k < channels_; ++k) {
        // The ratio of the mean levels (what a seam shows), over the cells whose log ratio is within 3 robust sigmas
        // of the median (cells where the tiles show different things are left out).
        std::vector<double> v = ratios[k];
        std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
        const double med = v[v.size() / 2];
        std::vector<double> dev;
        for (double r : ratios[k]) dev.push_back(std::abs(r - med));
        std::nth_element(dev.begin(), dev.begin() + dev.size() / 2, dev.end());
        const double limit = 3.0 * 1.4826 * std::max(1e-3, dev[dev.size() / 2]);
        double sum_a = 0, sum_b = 0;
        for (std::size_t c = 0; c < ratios[k].size(); ++c)
          if (std::abs(ratios[k][c] - med) <= limit) {
            sum_a += levels[k][c].first;
            sum_b += levels[k][c].second;
          }
        p.log_ratio[k] = sum_a > 0 && sum_b > 0 ? std::log(sum_b / sum_a) : med;
      }
      pairs.push_back(p);
    }
  // log g_a - log g_b = log(level_b / level_a): a corrected tile a matches b.
  for (int k = 0; k < channels_; ++k) {
    Eigen::MatrixXd h = Eigen::MatrixXd::Zero(n, n);
    Eigen::VectorXd rhs = Eigen::VectorXd::Zero(n);
    double mean_weight = 0;
    for (const Pair& p : pairs) {
      h(p.a, p.a) += p.weight;
      h(p.b, p.b) += p.weight;
      h(p.a, p.b) -= p.weight;
      h(p.b, p.a) -= p.weight;
      rhs(p.a) += p.weight * p.log_ratio[k];
      rhs(p.b) -= p.weight * p.log_ratio[k];
      mean_weight += p.weight;
    }
    mean_weight = pairs.empty() ? 1.0 : mean_weight / pairs.size();
    for (int i = 0; i < n; ++i) h(i, i) += config_.prior_weight * mean_weight;
    const Eigen::VectorXd log_gain = h.ldlt().solve(rhs);
    for (int i = 0; i < n; ++i)
      out[indices[i]][k] = std::clamp(std::exp(log_gain(i)), 1.0 / config_.max_gain, config_.max_gain);
  }
  if (channels_ == 1)
    for (auto& [index, g] : out) g[1] = g[2] = g[0];
  return out;
}

}  // namespace compose
}  // namespace exocet_mosaic
