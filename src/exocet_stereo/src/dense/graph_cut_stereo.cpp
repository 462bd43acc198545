// Alpha-expansion graph cuts (Boykov-Veksler-Zabih) with Boost.Graph's Boykov-Kolmogorov max-flow.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

// Boost.Graph's edge iterators trip GCC's -Wmaybe-uninitialized (a known false positive in Boost's headers).
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <boost/graph/adjacency_list.hpp>
#include <boost/graph/boykov_kolmogorov_max_flow.hpp>

#include "exocet_stereo/dense/methods.h"
#include "exocet_stereo/dense/post_processing.h"

namespace exocet_stereo {
namespace dense {
namespace {

using Traits = boost::adjacency_list_traits<boost::vecS, boost::vecS, boost::directedS>;
using Graph = boost::adjacency_list<
    boost::vecS, boost::vecS, boost::directedS, boost::no_property,
    boost::property<boost::edge_capacity_t, int64_t,
                    boost::property<boost::edge_residual_capacity_t, int64_t,
                                    boost::property<boost::edge_reverse_t, Traits::edge_descriptor>>>>;
using Edge = Traits::edge_descriptor;

// Integer energies keep max-flow exact; costs are scaled by this before rounding.
constexpr double kEnergyScale = 16.0;

// Grid graph built once per solve; each expansion only rewrites capacities.
class ExpansionGraph {
 public:
  ExpansionGraph(int rows, int cols) : pixels_(rows * cols), graph_(pixels_ + 2) {
    source_ = pixels_;
    sink_ = pixels_ + 1;
    source_edges_.reserve(pixels_);
    sink_edges_.reserve(pixels_);
    for (int p = 0; p < pixels_; ++p) {
      source_edges_.push_back(addEdgePair(source_, p));
      sink_edges_.push_back(addEdgePair(p, sink_));
    }
    for (int y = 0; y < rows; ++y) {
      for (int x = 0; x < cols; ++x) {
        const int p = y * cols + x;
        if (x + 1 < cols) pairs_.push_back({p, p + 1, addEdgePair(p, p + 1)});
        if (y + 1 < rows) pairs_.push_back({p, p + cols, addEdgePair(p, p + cols)});
      }
    }
    colors_.resize(pixels_ + 2);
    predecessors_.resize(pixels_ + 2);
    distances_.resize(pixels_ + 2);
  }

  struct Pair {
    int p, q;
    Edge edge;  // p -> q; its reverse q -> p keeps capacity 0
  };
  const std::vector<Pair>& pairs() const { return pairs_; }

  void setTerminal(int p, int64_t cost_keep, int64_t cost_alpha) {
    const int64_t base = std::min(cost_keep, cost_alpha);
    boost::put(boost::edge_capacity, graph_, source_edges_[p], cost_alpha - base);  // cut when p takes alpha
    boost::put(boost::edge_capacity, graph_, sink_edges_[p], cost_keep - base);     // cut when p keeps its label
  }
  void setPair(size_t index, int64_t capacity) {
    boost::put(boost::edge_capacity, graph_, pairs_[index].edge, capacity);
  }

  /// Runs max-flow; afterwards takesAlpha(p) tells the side of the minimum cut.
  void cut() {
    boost::boykov_kolmogorov_max_flow(graph_, boost::get(boost::edge_capacity, graph_),
                                      boost::get(boost::edge_residual_capacity, graph_),
                                      boost::get(boost::edge_reverse, graph_), predecessors_.data(), colors_.data(),
                                      distances_.data(), boost::get(boost::vertex_index, graph_), source_, sink_);
  }
  bool takesAlpha(int p) const { return colors_[p] != boost::black_color; }  // black = source tree = keep

 private:
  Edge addEdgePair(int from, int to) {
    const Edge forward = boost::add_edge(from, to, graph_).first;
    const Edge backward = boost::add_edge(to, from, graph_).first;
    boost::put(boost::edge_reverse, graph_, forward, backward);
    boost::put(boost::edge_reverse, graph_, backward, forward);
    boost::put(boost::edge_capacity, graph_, forward, 0);
    boost::put(boost::edge_capacity, graph_, backward, 0);
    return forward;
  }

  int pixels_;
  Graph graph_;
  int source_ = 0, sink_ = 0;
  std::vector<Edge> source_edges_, sink_edges_;
  std::vector<Pair> pairs_;
  std::vector<boost::default_color_type> colors_;
  std::vector<Edge> predecessors_;
  std::vector<int64_t> distances_;
};

}  // namespace

cv::Mat GraphCutStereo::solve(const CostVolume& volume, const cv::Mat& gray) const {
  const int rows = volume.rows, cols = volume.cols, labels = volume.labels, pixels = rows * cols;
  const int truncation = config_.smoothness_truncation_px;
  // Smoothness per unit of disparity change; the largest (truncated) jump costs penalty_large.
  const double unit = config_.penalty_large / truncation;

  std::vector<int64_t> data(static_cast<size_t>(pixels) * labels);
  for (size_t i = 0; i < data.size(); ++i) data[i] = std::llround(volume.data[i] * kEnergyScale);
  ExpansionGraph graph(rows, cols);
  const auto& pairs = graph.pairs();
  std::vector<int64_t> weights(pairs.size());
  for (size_t k = 0; k < pairs.size(); ++k) {
    const int gp = gray.data[pairs[k].p], gq = gray.data[pairs[k].q];  // gray is continuous CV_8U
    const double w = std::abs(gp - gq) > config_.contrast_threshold ? unit / config_.contrast_factor : unit;
    weights[k] = std::llround(w * kEnergyScale);
  }
  auto smooth = [truncation](int a, int b) { return static_cast<int64_t>(std::min(std::abs(a - b), truncation)); };

  // Start from winner-take-all.
  std::vector<int> label(pixels);
  for (int p = 0; p < pixels; ++p) {
    const int64_t* c = &data[static_cast<size_t>(p) * labels];
    label[p] = static_cast<int>(std::min_element(c, c + labels) - c);
  }
  auto energy = [&]() {
    int64_t e = 0;
    for (int p = 0; p < pixels; ++p) e += data[static_cast<size_t>(p) * labels + label[p]];
    for (size_t k = 0; k < pairs.size(); ++k) e += weights[k] * smooth(label[pairs[k].p], label[pairs[k].q]);
    return e;
  };

  int64_t current = energy();
  std::vector<int64_t> cost_alpha(pixels), cost_keep(pixels);
  std::vector<int> candidate(pixels);
  for (int cycle = 0; cycle < config_.gc_cycles; ++cycle) {
    bool improved = false;
    for (int alpha = 0; alpha < labels; ++alpha) {
      for (int p = 0; p < pixels; ++p) {
        cost_keep[p] = data[static_cast<size_t>(p) * labels + label[p]];
        cost_alpha[p] = data[static_cast<size_t>(p) * labels + alpha];
      }
      // E(xp, xq) with x = 1 meaning "take alpha": A = V(fp, fq), B = V(fp, alpha), C = V(alpha, fq), D = 0.
      // E = A + (C - A) xp + (D - C) xq + (B + C - A - D)(1 - xp) xq; the last term is the p -> q edge.
      for (size_t k = 0; k < pairs.size(); ++k) {
        const int p = pairs[k].p, q = pairs[k].q;
        const int64_t a = weights[k] * smooth(label[p], label[q]);
        const int64_t b = weights[k] * smooth(label[p], alpha);
        const int64_t c = weights[k] * smooth(alpha, label[q]);
        cost_alpha[p] += c - a;
        cost_alpha[q] -= c;
        graph.setPair(k, b + c - a);
      }
      for (int p = 0; p < pixels; ++p) graph.setTerminal(p, cost_keep[p], cost_alpha[p]);
      graph.cut();
      for (int p = 0; p < pixels; ++p) candidate[p] = graph.takesAlpha(p) ? alpha : label[p];
      std::swap(label, candidate);
      const int64_t proposed = energy();
      if (proposed < current) {
        current = proposed;
        improved = true;
      } else {
        std::swap(label, candidate);  // a cut never raises the energy; keep the old labels on ties
      }
    }
    if (!improved) break;
  }

  cv::Mat disparity(rows, cols, CV_32F);
  for (int p = 0; p < pixels; ++p) disparity.at<float>(p / cols, p % cols) = static_cast<float>(label[p]);
  if (config_.subpixel) {
    // The per-pixel census cost is too noisy for a parabola; fit it on a 5x5 mean of the cost.
    CostVolume smoothed = volume;
    boxAggregate(&smoothed, 2);
    refineSubpixel(smoothed, &disparity);
  }
  return disparity;
}

}  // namespace dense
}  // namespace exocet_stereo

#pragma GCC diagnostic pop
