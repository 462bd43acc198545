#include "exocet_mosaic/tiles/image_network_adjustment.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <map>
#include <mutex>
#include <numeric>
#include <set>
#include <sstream>
#include <utility>

#include <Eigen/Sparse>
#include <opencv2/core/utility.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>

namespace exocet_mosaic {
namespace tiles {

namespace {

constexpr double kSameImageSigmaPx = 0.05;  ///< ties of two drawings of one image: exact, held tight

Eigen::Vector2d apply(const cv::Matx33d& h, double x, double y) {
  const cv::Vec3d p = h * cv::Vec3d(x, y, 1.0);
  return Eigen::Vector2d(p[0] / p[2], p[1] / p[2]);
}

struct Footprint {
  std::vector<cv::Point2f> quad;  ///< relative to the first image's first corner: float keeps its precision
  cv::Rect2d box;
  double area_m2 = 0;
};

struct Features {
  std::vector<cv::Point2f> points;
  cv::Mat descriptors;  ///< CV_8U rows: OpenCV's SIFT values are whole numbers in [0, 255]
};

/// The grey images the pairs read, at most `capacity` kept (least recently used out); thread-safe.
class GreyCache {
 public:
  GreyCache(std::function<cv::Mat(const std::string&)> load, std::size_t capacity)
      : load_(std::move(load)), capacity_(capacity) {}
  cv::Mat get(const std::string& id) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      const auto found = kept_.find(id);
      if (found != kept_.end()) {
        found->second.second = ++clock_;
        return found->second.first;
      }
    }
    cv::Mat grey = load_(id);  // outside the lock: the reads run in parallel
    if (!grey.empty() && grey.type() != CV_8UC1) grey = cv::Mat();
    std::lock_guard<std::mutex> lock(mutex_);
    if (kept_.size() >= capacity_) {
      auto oldest = kept_.begin();
      for (auto k = kept_.begin(); k != kept_.end(); ++k)
        if (k->second.second < oldest->second.second) oldest = k;
      kept_.erase(oldest);
    }
    kept_[id] = {grey, ++clock_};
    return grey;
  }

 private:
  std::function<cv::Mat(const std::string&)> load_;
  std::size_t capacity_;
  std::mutex mutex_;
  std::map<std::string, std::pair<cv::Mat, std::uint64_t>> kept_;
  std::uint64_t clock_ = 0;
};

const std::string& sourceOf(const AdjustableImage& image) { return image.source.empty() ? image.id : image.source; }

Footprint footprintOf(const AdjustableImage& image, const Eigen::Vector2d& origin) {
  Footprint f;
  const double w = image.size_px.width, h = image.size_px.height;
  const double corners[4][2] = {{0, 0}, {w, 0}, {w, h}, {0, h}};
  double x0 = 1e300, y0 = 1e300, x1 = -1e300, y1 = -1e300;
  for (const auto& c : corners) {
    const Eigen::Vector2d p = apply(image.en_from_px, c[0], c[1]) - origin;
    f.quad.emplace_back(static_cast<float>(p.x()), static_cast<float>(p.y()));
    x0 = std::min(x0, p.x()), y0 = std::min(y0, p.y()), x1 = std::max(x1, p.x()), y1 = std::max(y1, p.y());
  }
  f.box = cv::Rect2d(x0, y0, x1 - x0, y1 - y0);
  f.area_m2 = std::abs(cv::contourArea(f.quad));
  if (!cv::isContourConvex(f.quad)) f.area_m2 = 0;  // a placement that folds the image: not paired
  return f;
}

/// Common ground of two footprints over the smaller one.
double overlapFraction(const Footprint& a, const Footprint& b) {
  if (a.area_m2 <= 0 || b.area_m2 <= 0 || (a.box & b.box).area() <= 0) return 0;
  std::vector<cv::Point2f> common;
  const float area = cv::intersectConvexConvex(a.quad, b.quad, common, true);
  return area > 0 ? area / std::min(a.area_m2, b.area_m2) : 0.0;
}

int descriptorDistance2(const uchar* a, const uchar* b, int n) {
  int sum = 0;
  for (int k = 0; k < n; ++k) {
    const int d = int(a[k]) - int(b[k]);
    sum += d * d;
  }
  return sum;
}

/// Raw ties of a pair by features: each keypoint of a matched among b's keypoints near where the placements predict it
/// (Lowe's ratio among them, mutual best); where a and where b put each on the ground.
void featureTies(const AdjustableImage& ia, const AdjustableImage& ib, const Features& fa, const Features& fb,
                 const ImageAdjustmentConfig& config, std::vector<Eigen::Vector2d>* on_a,
                 std::vector<Eigen::Vector2d>* on_b) {
  if (fa.points.empty() || fb.points.empty()) return;
  const cv::Matx33d b_from_a = ib.en_from_px.inv() * ia.en_from_px;
  const double radius = config.search_radius_px;
  // b's keypoints bucketed in cells of the radius.
  const int columns = std::max(1, static_cast<int>(std::ceil(ib.size_px.width / radius)) + 1);
  const int rows = std::max(1, static_cast<int>(std::ceil(ib.size_px.height / radius)) + 1);
  std::vector<std::vector<int>> cells(static_cast<std::size_t>(columns) * rows);
  const auto cellOf = [&](double x, double y, int* cx, int* cy) {
    *cx = static_cast<int>(std::floor(x / radius));
    *cy = static_cast<int>(std::floor(y / radius));
  };
  for (std::size_t j = 0; j < fb.points.size(); ++j) {
    int cx, cy;
    cellOf(fb.points[j].x, fb.points[j].y, &cx, &cy);
    if (cx >= 0 && cy >= 0 && cx < columns && cy < rows) cells[static_cast<std::size_t>(cy) * columns + cx].push_back(j);
  }
  const double radius2 = radius * radius;
  const double ratio2 = config.ratio * config.ratio;
  std::vector<std::pair<int, int>> best_of_b(fb.points.size(), {-1, 0});  // (a, distance^2)
  std::vector<int> match_of_a(fa.points.size(), -1);
  const int length = fa.descriptors.cols;
  for (std::size_t i = 0; i < fa.points.size(); ++i) {
    const Eigen::Vector2d q = apply(b_from_a, fa.points[i].x, fa.points[i].y);
    if (q.x() < -radius || q.y() < -radius || q.x() > ib.size_px.width + radius ||
        q.y() > ib.size_px.height + radius)
      continue;
    int cx, cy;
    cellOf(q.x(), q.y(), &cx, &cy);
    int best = -1, best_d = 0, second_d = -1;
    for (int y = cy - 1; y <= cy + 1; ++y)
      for (int x = cx - 1; x <= cx + 1; ++x) {
        if (x < 0 || y < 0 || x >= columns || y >= rows) continue;
        for (const int j : cells[static_cast<std::size_t>(y) * columns + x]) {
          const double dx = fb.points[j].x - q.x(), dy = fb.points[j].y - q.y();
          if (dx * dx + dy * dy > radius2) continue;
          const int d = descriptorDistance2(fa.descriptors.ptr<uchar>(static_cast<int>(i)), fb.descriptors.ptr<uchar>(j),
                                            length);
          if (best < 0 || d < best_d) {
            second_d = best < 0 ? -1 : best_d;
            best = j, best_d = d;
          } else if (second_d < 0 || d < second_d) {
            second_d = d;
          }
        }
      }
    if (best < 0 || (second_d >= 0 && best_d >= ratio2 * second_d)) continue;
    match_of_a[i] = best;
    if (best_of_b[best].first < 0 || best_d < best_of_b[best].second) best_of_b[best] = {static_cast<int>(i), best_d};
  }
  for (std::size_t i = 0; i < fa.points.size(); ++i) {
    const int j = match_of_a[i];
    if (j < 0 || best_of_b[j].first != static_cast<int>(i)) continue;
    on_a->push_back(apply(ia.en_from_px, fa.points[i].x, fa.points[i].y));
    on_b->push_back(apply(ib.en_from_px, fb.points[j].x, fb.points[j].y));
  }
}

/// Raw ties of a pair by area: the two images drawn on their common ground at the finer GSD, square patches where both
/// cover all of it, each patch's offset by phase correlation (OpenCV's, Hanning window); where a and where b put the
/// patch's centre. Photometric differences between the passes (the lamp seen from the other side) move a blob
/// detector's keypoints by about a pixel; the correlation of the whole patch is not drawn that way.
void patchTies(const AdjustableImage& ia, const AdjustableImage& ib, const cv::Mat& grey_a, const cv::Mat& grey_b,
               const ImageAdjustmentConfig& config, std::vector<Eigen::Vector2d>* on_a,
               std::vector<Eigen::Vector2d>* on_b) {
  if (grey_a.empty() || grey_b.empty()) return;
  const double gsd_m = std::min(ia.gsd_m, ib.gsd_m);
  // The common bounding box of the footprints, on a grid x = (E - e0) / gsd, y = (n1 - N) / gsd.
  const auto box = [](const AdjustableImage& image) {
    const double w = image.size_px.width, h = image.size_px.height;
    Eigen::Vector2d lo(1e300, 1e300), hi(-1e300, -1e300);
    for (const auto& c : {Eigen::Vector2d(0, 0), Eigen::Vector2d(w, 0), Eigen::Vector2d(w, h), Eigen::Vector2d(0, h)}) {
      const Eigen::Vector2d p = apply(image.en_from_px, c.x(), c.y());
      lo = lo.cwiseMin(p), hi = hi.cwiseMax(p);
    }
    return std::make_pair(lo, hi);
  };
  const auto [lo_a, hi_a] = box(ia);
  const auto [lo_b, hi_b] = box(ib);
  const Eigen::Vector2d lo = lo_a.cwiseMax(lo_b), hi = hi_a.cwiseMin(hi_b);
  const int patch = config.patch_px;
  const cv::Size size(static_cast<int>((hi.x() - lo.x()) / gsd_m), static_cast<int>((hi.y() - lo.y()) / gsd_m));
  if (size.width < patch || size.height < patch || size.width > 20000 || size.height > 20000) return;
  const cv::Matx33d grid_from_en(1 / gsd_m, 0, -lo.x() / gsd_m, 0, -1 / gsd_m, hi.y() / gsd_m, 0, 0, 1);
  const auto draw = [&](const cv::Mat& grey, const cv::Matx33d& en_from_px, cv::Mat* drawn, cv::Mat* valid) {
    const cv::Matx33d grid_from_px = grid_from_en * en_from_px;
    cv::warpPerspective(grey, *drawn, grid_from_px, size, cv::INTER_LINEAR, cv::BORDER_CONSTANT);
    cv::warpPerspective(cv::Mat(grey.size(), CV_8U, cv::Scalar(255)), *valid, grid_from_px, size, cv::INTER_NEAREST,
                        cv::BORDER_CONSTANT);
    cv::erode(*valid, *valid, cv::Mat(), cv::Point(-1, -1), 2);  // no interpolated border pixel
  };
  cv::Mat drawn_a, valid_a, drawn_b, valid_b;
  draw(grey_a, ia.en_from_px, &drawn_a, &valid_a);
  draw(grey_b, ib.en_from_px, &drawn_b, &valid_b);
  cv::Mat both;
  cv::bitwise_and(valid_a, valid_b, both);
  cv::Mat inside;
  cv::integral(both / 255, inside, CV_32S);
  cv::Mat window;
  cv::createHanningWindow(window, cv::Size(patch, patch), CV_32F);
  for (int y = 0; y + patch <= size.height; y += patch)
    for (int x = 0; x + patch <= size.width; x += patch) {
      const int covered = inside.at<int>(y + patch, x + patch) - inside.at<int>(y, x + patch) -
                          inside.at<int>(y + patch, x) + inside.at<int>(y, x);
      if (covered < patch * patch) continue;
      const cv::Rect r(x, y, patch, patch);
      cv::Mat pa, pb;
      drawn_a(r).convertTo(pa, CV_32F);
      drawn_b(r).convertTo(pb, CV_32F);
      double response = 0;
      const cv::Point2d d = cv::phaseCorrelate(pa, pb, window, &response);
      if (response < config.min_response || std::hypot(d.x, d.y) > config.search_radius_px) continue;
      // b shows at (x + d) what a shows at x.
      const Eigen::Vector2d centre(lo.x() + (x + 0.5 * patch) * gsd_m, hi.y() - (y + 0.5 * patch) * gsd_m);
      on_a->push_back(centre);
      on_b->push_back(centre + Eigen::Vector2d(d.x * gsd_m, -d.y * gsd_m));
    }
}

/// The raw ties of a pair that agree with one similarity between the two placements (RANSAC): the images may disagree
/// in rotation as well as in position (the chain's rotation drifts); the ties off it are false matches. At most
/// max_ties_per_pair, spread over the overlap.
ImagePairTies keptTies(const std::vector<Eigen::Vector2d>& on_a, const std::vector<Eigen::Vector2d>& on_b,
                       double gsd_m, const ImageAdjustmentConfig& config) {
  ImagePairTies pair;
  pair.matches = static_cast<int>(on_a.size());
  if (pair.matches < config.min_ties) return pair;
  std::vector<cv::Point2f> ga, gb;  // px of the finer image about the first tie (float precision for RANSAC)
  for (std::size_t k = 0; k < on_a.size(); ++k) {
    const Eigen::Vector2d pa = (on_a[k] - on_a.front()) / gsd_m, pb = (on_b[k] - on_a.front()) / gsd_m;
    ga.emplace_back(static_cast<float>(pa.x()), static_cast<float>(pa.y()));
    gb.emplace_back(static_cast<float>(pb.x()), static_cast<float>(pb.y()));
  }
  std::vector<uchar> inlier;
  const cv::Mat similarity = cv::estimateAffinePartial2D(ga, gb, inlier, cv::RANSAC, config.ransac_threshold_px, 2000,
                                                         0.995, 10);
  if (similarity.empty()) return pair;
  std::vector<int> kept;
  for (std::size_t k = 0; k < inlier.size(); ++k)
    if (inlier[k]) kept.push_back(static_cast<int>(k));
  if (static_cast<int>(kept.size()) < config.min_ties) return pair;
  // At most max_ties_per_pair, spread over the overlap: every k-th in the order of their position along its longer side.
  if (static_cast<int>(kept.size()) > config.max_ties_per_pair) {
    cv::Rect2f box = cv::boundingRect(ga);
    const bool along_x = box.width >= box.height;
    std::sort(kept.begin(), kept.end(), [&](int x, int y) { return along_x ? ga[x].x < ga[y].x : ga[x].y < ga[y].y; });
    std::vector<int> spread;
    for (int k = 0; k < config.max_ties_per_pair; ++k)
      spread.push_back(kept[static_cast<std::size_t>(k) * kept.size() / config.max_ties_per_pair]);
    kept = spread;
  }
  double sum2 = 0;
  for (const int k : kept) {
    pair.on_a_en_m.push_back(on_a[k]);
    pair.on_b_en_m.push_back(on_b[k]);
    sum2 += (on_b[k] - on_a[k]).squaredNorm();
  }
  pair.before_px = std::sqrt(sum2 / kept.size()) / gsd_m;
  return pair;
}

/// The move of a point x of an image about its centre c: x + t + (theta J + s I)(x - c), as a 2x4 Jacobian on
/// (t_e, t_n, theta, s).
Eigen::Matrix<double, 2, 4> moveJacobian(const Eigen::Vector2d& x, const Eigen::Vector2d& c) {
  const Eigen::Vector2d d = x - c;
  Eigen::Matrix<double, 2, 4> j;
  j << 1, 0, -d.y(), d.x(),  //
      0, 1, d.x(), d.y();
  return j;
}

}  // namespace

std::string ImageAdjustmentConfig::validate() const {
  std::ostringstream bad;
  const auto check = [&bad](bool ok, const char* what) {
    if (!ok) bad << (bad.tellp() > 0 ? "; " : "") << what;
  };
  check(max_features >= 50 && max_features <= 20000, "max_features must be in [50, 20000]");
  check(tie_method == "patches" || tie_method == "sift", "tie_method must be patches or sift");
  check(patch_px >= 16 && patch_px <= 512, "patch_px must be in [16, 512]");
  check(min_response >= 0 && min_response <= 1, "min_response must be in [0, 1]");
  check(cached_images >= 2 && cached_images <= 100000, "cached_images must be in [2, 100000]");
  check(contrast_threshold > 0 && contrast_threshold <= 1, "contrast_threshold must be in (0, 1]");
  check(same_pass_s > 0 && same_pass_s <= 1e6, "same_pass_s must be in (0, 1e6]");
  check(sequence_neighbours >= 1 && sequence_neighbours <= 20, "sequence_neighbours must be in [1, 20]");
  check(max_cross_pairs_per_pass >= 0 && max_cross_pairs_per_pass <= 50,
        "max_cross_pairs_per_pass must be in [0, 50]");
  check(min_overlap_fraction > 0 && min_overlap_fraction <= 1, "min_overlap_fraction must be in (0, 1]");
  check(search_radius_px > 0 && search_radius_px <= 200, "search_radius_px must be in (0, 200]");
  check(ratio > 0 && ratio <= 1, "ratio must be in (0, 1]");
  check(min_ties >= 3 && min_ties <= 100000, "min_ties must be in [3, 100000]");
  check(ransac_threshold_px > 0 && ransac_threshold_px <= 100, "ransac_threshold_px must be in (0, 100]");
  check(tie_sigma_px > 0 && tie_sigma_px <= 100, "tie_sigma_px must be in (0, 100]");
  check(max_ties_per_pair >= 3 && max_ties_per_pair <= 1000000, "max_ties_per_pair must be in [3, 1e6]");
  check(rotation_prior_sigma_rad > 0 && rotation_prior_sigma_rad <= 1, "rotation_prior_sigma_rad must be in (0, 1]");
  check(scale_prior_sigma > 0 && scale_prior_sigma <= 1, "scale_prior_sigma must be in (0, 1]");
  check(prior_sigma_m > 0 && prior_sigma_m <= 100, "prior_sigma_m must be in (0, 100]");
  check(passes >= 1 && passes <= 10, "passes must be in [1, 10]");
  check(max_pair_rms_px > 0 && max_pair_rms_px <= 100, "max_pair_rms_px must be in (0, 100]");
  check(huber_sigmas > 0 && huber_sigmas <= 100, "huber_sigmas must be in (0, 100]");
  return bad.str();
}

cv::Matx33d movedPlacement(const cv::Matx33d& frame_from_px, const cv::Matx33d& move_en,
                           const Eigen::Vector2d& frame_origin_en_m) {
  const cv::Matx33d to_en(1, 0, frame_origin_en_m.x(), 0, 1, frame_origin_en_m.y(), 0, 0, 1);
  const cv::Matx33d to_frame(1, 0, -frame_origin_en_m.x(), 0, 1, -frame_origin_en_m.y(), 0, 0, 1);
  return to_frame * move_en * to_en * frame_from_px;
}

ImageAdjustment adjustImages(const std::vector<AdjustableImage>& images,
                             const std::function<cv::Mat(const std::string& id)>& load_gray,
                             const ImageAdjustmentConfig& config) {
  ImageAdjustment out;
  const int n = static_cast<int>(images.size());
  out.shift_en_m.assign(images.size(), Eigen::Vector2d::Zero());
  out.move_en.assign(images.size(), cv::Matx33d::eye());
  out.rotation_rad.assign(images.size(), 0.0);
  out.scale_change.assign(images.size(), 0.0);
  const std::string invalid = config.validate();
  if (!invalid.empty()) {
    out.problem = invalid;
    return out;
  }
  if (n < 2) {
    out.problem = "fewer than two images";
    return out;
  }
  for (const AdjustableImage& image : images)
    if (image.size_px.width <= 0 || image.size_px.height <= 0 || !(image.gsd_m > 0)) {
      out.problem = "image '" + image.id + "' has no size or no ground sample distance";
      return out;
    }

  // Pairs: each image with its next ones in time within a pass, and with the images of other passes it overlaps most.
  std::vector<int> order(images.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return images[a].stamp_s < images[b].stamp_s; });
  const Eigen::Vector2d origin = apply(images[order[0]].en_from_px, 0, 0);
  std::vector<Footprint> footprints;
  for (const AdjustableImage& image : images) footprints.push_back(footprintOf(image, origin));
  std::set<std::pair<int, int>> chosen;
  const auto add = [&chosen](int a, int b) { chosen.insert({std::min(a, b), std::max(a, b)}); };
  for (int s = 0; s < n; ++s)
    for (int k = 1; k <= config.sequence_neighbours && s + k < n; ++k) {
      const int a = order[s], b = order[s + k];
      if (images[b].stamp_s - images[a].stamp_s > config.same_pass_s) break;
      if (overlapFraction(footprints[a], footprints[b]) >= config.min_overlap_fraction) add(a, b);
    }
  for (int a = 0; a < n; ++a) {
    std::vector<std::pair<double, int>> others;
    for (int b = 0; b < n; ++b) {
      if (b == a || std::abs(images[b].stamp_s - images[a].stamp_s) <= config.same_pass_s) continue;
      if ((footprints[a].box & footprints[b].box).area() <= 0) continue;
      const double f = overlapFraction(footprints[a], footprints[b]);
      if (f >= config.min_overlap_fraction) others.emplace_back(f, b);
    }
    // The largest overlaps first, at most max_cross_pairs_per_pass with each other pass (images of another pass
    // within same_pass_s of each other): an image between two lines is tied to both.
    std::sort(others.begin(), others.end(), std::greater<>());
    std::vector<std::pair<double, int>> passes;  // (a stamp of that pass, images taken from it)
    for (const auto& [fraction, b] : others) {
      auto pass = std::find_if(passes.begin(), passes.end(), [&](const std::pair<double, int>& p) {
        return std::abs(p.first - images[b].stamp_s) <= config.same_pass_s;
      });
      if (pass == passes.end()) pass = passes.insert(passes.end(), {images[b].stamp_s, 0});
      if (pass->second >= config.max_cross_pairs_per_pass) continue;
      ++pass->second;
      add(a, b);
    }
  }
  const std::vector<std::pair<int, int>> candidates(chosen.begin(), chosen.end());
  out.pairs_tried = static_cast<int>(candidates.size());
  if (candidates.empty()) {
    out.problem = "no overlapping images";
    return out;
  }

  // Features of the images in a pair (tie_method "sift"), or their pixels as the pairs need them ("patches").
  std::vector<char> needed(images.size(), 0);
  for (const auto& [a, b] : candidates) needed[a] = needed[b] = 1;
  const bool by_features = config.tie_method == "sift";
  std::vector<Features> features(images.size());
  GreyCache greys(load_gray, static_cast<std::size_t>(config.cached_images));
  if (by_features) {
    cv::parallel_for_(cv::Range(0, n), [&](const cv::Range& range) {
      const cv::Ptr<cv::SIFT> sift = cv::SIFT::create(config.max_features, 3, config.contrast_threshold);
      for (int i = range.start; i < range.end; ++i) {
        if (!needed[i]) continue;
        const cv::Mat grey = load_gray(images[i].id);
        if (grey.empty() || grey.type() != CV_8UC1) continue;
        std::vector<cv::KeyPoint> keypoints;
        cv::Mat descriptors;
        sift->detectAndCompute(grey, cv::noArray(), keypoints, descriptors);
        if (keypoints.empty()) continue;
        for (const cv::KeyPoint& k : keypoints) features[i].points.push_back(k.pt);
        descriptors.convertTo(features[i].descriptors, CV_8U);
      }
    });
    for (const Features& f : features) out.images_with_features += f.points.empty() ? 0 : 1;
  }

  // Passes: the pairs measured on the drawings as they are, the moves solved, the drawings moved; the next pass
  // measures what is left (a patch's phase correlation reads a large offset short by a fraction of it).
  std::vector<AdjustableImage> working = images;
  Eigen::VectorXd u_total = Eigen::VectorXd::Zero(4 * n);
  std::map<std::pair<int, int>, double> first_before_px;
  for (int pass = 0; pass < config.passes; ++pass) {
    std::vector<ImagePairTies> measured(candidates.size());
    std::vector<char> readable(images.size(), 0);
    cv::parallel_for_(cv::Range(0, static_cast<int>(candidates.size())), [&](const cv::Range& range) {
      for (int k = range.start; k < range.end; ++k) {
        const auto [a, b] = candidates[k];
        std::vector<Eigen::Vector2d> on_a, on_b;
        if (sourceOf(working[a]) == sourceOf(working[b])) {
          // One image drawn in two tiles: where each drawing puts a grid of its pixels.
          ImagePairTies& same = measured[k];
          for (int y = 0; y <= 4; ++y)
            for (int x = 0; x <= 4; ++x) {
              const double u = 0.25 * x * working[a].size_px.width, v = 0.25 * y * working[a].size_px.height;
              same.on_a_en_m.push_back(apply(working[a].en_from_px, u, v));
              same.on_b_en_m.push_back(apply(working[b].en_from_px, u, v));
            }
          double sum2 = 0;
          for (std::size_t t = 0; t < same.on_a_en_m.size(); ++t)
            sum2 += (same.on_b_en_m[t] - same.on_a_en_m[t]).squaredNorm();
          same.same_image = true;
          same.matches = static_cast<int>(same.on_a_en_m.size());
          same.before_px = std::sqrt(sum2 / same.on_a_en_m.size()) / std::min(working[a].gsd_m, working[b].gsd_m);
          same.a = a, same.b = b;
          continue;
        }
        if (by_features) {
          featureTies(working[a], working[b], features[a], features[b], config, &on_a, &on_b);
        } else {
          const cv::Mat grey_a = greys.get(working[a].id), grey_b = greys.get(working[b].id);
          readable[a] = readable[a] || !grey_a.empty();
          readable[b] = readable[b] || !grey_b.empty();
          patchTies(working[a], working[b], grey_a, grey_b, config, &on_a, &on_b);
        }
        measured[k] = keptTies(on_a, on_b, std::min(working[a].gsd_m, working[b].gsd_m), config);
        measured[k].a = a, measured[k].b = b;
        measured[k].cross_pass = std::abs(working[a].stamp_s - working[b].stamp_s) > config.same_pass_s;
      }
    });
    if (!by_features && pass == 0)
      for (const char r : readable) out.images_with_features += r ? 1 : 0;
    out.pairs.clear();
    out.pairs_rejected = 0;
    out.ties = 0;
    for (ImagePairTies& p : measured)
      if (!p.on_a_en_m.empty()) out.pairs.push_back(std::move(p));
    if (out.pairs.empty()) {
      out.problem = "no pair of overlapping images with " + std::to_string(config.min_ties) + " tie points";
      return out;
    }

    // Linear least squares on (t_e, t_n, theta, s) per image, about its centre, in metres from `origin`: each tie
    // point's disagreement after the moves, (x_a + A_a u_a) - (x_b + A_b u_b), over its 1-sigma, Huber-reweighted; the
    // priors keep each image near the graph's placement.
    std::vector<Eigen::Vector2d> centre(working.size());
    for (int i = 0; i < n; ++i)
      centre[i] = apply(working[i].en_from_px, 0.5 * working[i].size_px.width, 0.5 * working[i].size_px.height) - origin;
    std::vector<double> tie_weight;  // 1 / sigma^2 per pair
    for (const ImagePairTies& p : out.pairs) {
      const double sigma_m = (p.same_image ? kSameImageSigmaPx : config.tie_sigma_px) *
                             std::min(working[p.a].gsd_m, working[p.b].gsd_m);
      tie_weight.push_back(1.0 / (sigma_m * sigma_m));
      out.ties += static_cast<int>(p.on_a_en_m.size());
    }
    std::vector<std::vector<double>> huber(out.pairs.size());
    for (std::size_t k = 0; k < out.pairs.size(); ++k) huber[k].assign(out.pairs[k].on_a_en_m.size(), 1.0);
    const double prior[4] = {1.0 / (config.prior_sigma_m * config.prior_sigma_m),
                             1.0 / (config.prior_sigma_m * config.prior_sigma_m),
                             1.0 / (config.rotation_prior_sigma_rad * config.rotation_prior_sigma_rad),
                             1.0 / (config.scale_prior_sigma * config.scale_prior_sigma)};
    Eigen::VectorXd u = Eigen::VectorXd::Zero(4 * n);
    const auto residual = [&](const ImagePairTies& p, std::size_t t) {
      const Eigen::Vector2d xa = p.on_a_en_m[t] - origin, xb = p.on_b_en_m[t] - origin;
      return Eigen::Vector2d(xa + moveJacobian(xa, centre[p.a]) * u.segment<4>(4 * p.a) - xb -
                             moveJacobian(xb, centre[p.b]) * u.segment<4>(4 * p.b));
    };
    // Rounds: the robust solution, then the pairs whose ties still disagree by more than max_pair_rms_px left out (a
    // pair of wrong ties that agree with one another: low texture, repetitive ground) and the rest solved again.
    const auto pairRmsPx = [&](const ImagePairTies& p) {
      double sum2 = 0;
      for (std::size_t t = 0; t < p.on_a_en_m.size(); ++t) sum2 += residual(p, t).squaredNorm();
      return std::sqrt(sum2 / p.on_a_en_m.size()) / std::min(working[p.a].gsd_m, working[p.b].gsd_m);
    };
    for (int round = 0; round < 4; ++round) {
      for (int iteration = 0; iteration < 8; ++iteration) {
        std::vector<Eigen::Triplet<double>> triplets;
        Eigen::VectorXd rhs = Eigen::VectorXd::Zero(4 * n);
        for (int i = 0; i < n; ++i)
          for (int c = 0; c < 4; ++c) {
            triplets.emplace_back(4 * i + c, 4 * i + c, prior[c]);
            rhs[4 * i + c] -= prior[c] * u_total[4 * i + c];  // the priors hold the sum of the passes' moves
          }
        for (std::size_t k = 0; k < out.pairs.size(); ++k) {
          const ImagePairTies& p = out.pairs[k];
          if (p.rejected) continue;
          Eigen::Matrix4d aa = Eigen::Matrix4d::Zero(), ab = Eigen::Matrix4d::Zero(), bb = Eigen::Matrix4d::Zero();
          Eigen::Vector4d ra = Eigen::Vector4d::Zero(), rb = Eigen::Vector4d::Zero();
          for (std::size_t t = 0; t < p.on_a_en_m.size(); ++t) {
            const Eigen::Vector2d xa = p.on_a_en_m[t] - origin, xb = p.on_b_en_m[t] - origin;
            const Eigen::Matrix<double, 2, 4> ja = moveJacobian(xa, centre[p.a]), jb = -moveJacobian(xb, centre[p.b]);
            const Eigen::Vector2d e0 = xa - xb;
            const double w = tie_weight[k] * huber[k][t];
            aa += w * ja.transpose() * ja;
            ab += w * ja.transpose() * jb;
            bb += w * jb.transpose() * jb;
            ra -= w * ja.transpose() * e0;
            rb -= w * jb.transpose() * e0;
          }
          for (int r = 0; r < 4; ++r)
            for (int c = 0; c < 4; ++c) {
              triplets.emplace_back(4 * p.a + r, 4 * p.a + c, aa(r, c));
              triplets.emplace_back(4 * p.b + r, 4 * p.b + c, bb(r, c));
              triplets.emplace_back(4 * p.a + r, 4 * p.b + c, ab(r, c));
              triplets.emplace_back(4 * p.b + c, 4 * p.a + r, ab(r, c));
            }
          rhs.segment<4>(4 * p.a) += ra;
          rhs.segment<4>(4 * p.b) += rb;
        }
        Eigen::SparseMatrix<double> normal(4 * n, 4 * n);
        normal.setFromTriplets(triplets.begin(), triplets.end());
        Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver(normal);
        if (solver.info() != Eigen::Success) {
          out.problem = "the normal equations could not be factored";
          return out;
        }
        u = solver.solve(rhs);
        bool changed = false;
        for (std::size_t k = 0; k < out.pairs.size(); ++k)
          for (std::size_t t = 0; t < huber[k].size() && !out.pairs[k].rejected && !out.pairs[k].same_image; ++t) {
            const double e = residual(out.pairs[k], t).norm() * std::sqrt(tie_weight[k]);
            const double h = e > config.huber_sigmas ? config.huber_sigmas / e : 1.0;
            changed = changed || std::abs(h - huber[k][t]) > 1e-3;
            huber[k][t] = h;
          }
        if (!changed) break;
      }
      int rejected = 0;
      for (ImagePairTies& p : out.pairs)
        if (!p.rejected && !p.same_image && pairRmsPx(p) > config.max_pair_rms_px) p.rejected = true, ++rejected;
      out.pairs_rejected += rejected;
      if (rejected == 0) break;
    }
    // This pass's moves, composed onto the drawings the next pass measures.
    const cv::Matx33d to_local(1, 0, -origin.x(), 0, 1, -origin.y(), 0, 0, 1);
    const cv::Matx33d to_en(1, 0, origin.x(), 0, 1, origin.y(), 0, 0, 1);
    for (int i = 0; i < n; ++i) {
      const Eigen::Vector4d v = u.segment<4>(4 * i);
      // x' = (1 + s) x + theta J x + t - (theta J + s I) c, in the local frame
      const Eigen::Vector2d c = centre[i];
      const cv::Matx33d local(1 + v[3], -v[2], v[0] + v[2] * c.y() - v[3] * c.x(),  //
                              v[2], 1 + v[3], v[1] - v[2] * c.x() - v[3] * c.y(),  //
                              0, 0, 1);
      const cv::Matx33d move = to_en * local * to_local;
      out.move_en[i] = move * out.move_en[i];
      working[i].en_from_px = move * working[i].en_from_px;
    }
    u_total += u;
    for (ImagePairTies& p : out.pairs) {
      p.after_px = pairRmsPx(p);
      const auto first = first_before_px.find({p.a, p.b});
      if (first == first_before_px.end())
        first_before_px[{p.a, p.b}] = p.before_px;
      else
        p.before_px = first->second;  // as the graph placed them
    }
  }
  for (int i = 0; i < n; ++i) {
    const cv::Matx33d& m = out.move_en[i];
    const Eigen::Vector2d c = apply(images[i].en_from_px, 0.5 * images[i].size_px.width, 0.5 * images[i].size_px.height);
    out.shift_en_m[i] = apply(m, c.x(), c.y()) - c;
    out.rotation_rad[i] = std::atan2(m(1, 0), m(0, 0));
    out.scale_change[i] = std::sqrt(m(0, 0) * m(1, 1) - m(0, 1) * m(1, 0)) - 1.0;
    out.shift_max_m = std::max(out.shift_max_m, out.shift_en_m[i].norm());
    out.rotation_max_rad = std::max(out.rotation_max_rad, std::abs(out.rotation_rad[i]));
  }
  for (const ImagePairTies& p : out.pairs) {
    if (!p.cross_pass || p.rejected) continue;
    out.cross_before_max_px = std::max(out.cross_before_max_px, p.before_px);
    out.cross_after_max_px = std::max(out.cross_after_max_px, p.after_px);
  }
  return out;
}

}  // namespace tiles
}  // namespace exocet_mosaic
