#include "exocet_mosaic/tiles/tile_revisions.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include <Eigen/Dense>
#include <opencv2/imgcodecs.hpp>

#include "exocet_common/atomic_file.h"
#include "exocet_mosaic/compose/ground_projection.h"

namespace exocet_mosaic {
namespace tiles {

int PositionCorrectionTrack::set(const std::vector<double>& stamps_s, const std::vector<Eigen::Vector2d>& corrections_m) {
  stamps_s_.clear();
  corrections_m_.clear();
  int left_out = 0;
  const std::size_t n = std::min(stamps_s.size(), corrections_m.size());
  left_out += static_cast<int>(std::max(stamps_s.size(), corrections_m.size()) - n);
  for (std::size_t i = 0; i < n; ++i) {
    if (!std::isfinite(stamps_s[i]) || !corrections_m[i].allFinite() ||
        (!stamps_s_.empty() && stamps_s[i] <= stamps_s_.back())) {
      ++left_out;
      continue;
    }
    stamps_s_.push_back(stamps_s[i]);
    corrections_m_.push_back(corrections_m[i]);
  }
  return left_out;
}

Eigen::Vector2d PositionCorrectionTrack::at(double stamp_s) const {
  if (stamps_s_.empty()) return Eigen::Vector2d::Zero();
  if (!(stamp_s > stamps_s_.front())) return corrections_m_.front();
  if (stamp_s >= stamps_s_.back()) return corrections_m_.back();
  const std::size_t j = std::upper_bound(stamps_s_.begin(), stamps_s_.end(), stamp_s) - stamps_s_.begin();
  const double t = (stamp_s - stamps_s_[j - 1]) / (stamps_s_[j] - stamps_s_[j - 1]);
  return (1 - t) * corrections_m_[j - 1] + t * corrections_m_[j];
}

namespace {

nlohmann::json matrixJson(const cv::Matx33d& m) {
  nlohmann::json a = nlohmann::json::array();
  for (int i = 0; i < 9; ++i) a.push_back(m.val[i]);
  return a;
}

template <typename T>
T field(const nlohmann::json& json, const char* name) {
  if (!json.contains(name)) throw std::invalid_argument(std::string("tile record: no '") + name + "'");
  try {
    return json.at(name).get<T>();
  } catch (const nlohmann::json::exception& e) {
    throw std::invalid_argument(std::string("tile record: bad '") + name + "': " + e.what());
  }
}

}  // namespace

nlohmann::json tileRecordToJson(const TileRecord& r) {
  nlohmann::json j;
  j["type"] = "exocet_tile_record";
  j["index"] = r.index;
  j["version"] = r.version;
  j["ground_origin_en_m"] = {r.ground_origin_en_m.x(), r.ground_origin_en_m.y()};
  j["gsd_m"] = r.gsd_m;
  j["utm_zone"] = r.utm_zone;
  j["northern_hemisphere"] = r.northern_hemisphere;
  j["local_frame"] = r.local_frame;
  const TileMetadata& m = r.metadata;
  j["metadata"] = {{"dive_name", m.dive_name},       {"first_frame", m.first_frame},
                   {"last_frame", m.last_frame},     {"start_time_s", m.start_time_s},
                   {"end_time_s", m.end_time_s},     {"close_reason", m.close_reason},
                   {"extra", m.extra}};
  if (std::isfinite(m.mean_altitude_m)) j["metadata"]["mean_altitude_m"] = m.mean_altitude_m;
  nlohmann::json images = nlohmann::json::array();
  for (const auto& i : r.images) {
    nlohmann::json image = {{"frame", i.frame},
                            {"stamp_s", i.stamp_s},
                            {"file", i.file},
                            {"width_px", i.width_px},
                            {"height_px", i.height_px},
                            {"closed_ground_from_px", matrixJson(i.closed_ground_from_px)},
                            {"closed_correction_m", {i.closed_correction_m.x(), i.closed_correction_m.y()}},
                            {"ground_from_px", matrixJson(i.ground_from_px)}};
    if (i.closed_navigation_m)
      image["closed_navigation_m"] = {i.closed_navigation_m->x(), i.closed_navigation_m->y()};
    if (i.closed_navigation_heading_rad) image["closed_navigation_heading_rad"] = *i.closed_navigation_heading_rad;
    if (i.gain != std::array<double, 3>{1.0, 1.0, 1.0}) image["gain"] = i.gain;
    images.push_back(image);
  }
  j["images"] = images;
  j["adjustment"] = matrixJson(r.adjustment);
  return j;
}

namespace {

cv::Matx33d matrixField(const nlohmann::json& json, const char* name) {
  const auto h = field<std::vector<double>>(json, name);
  if (h.size() != 9) throw std::invalid_argument(std::string("tile record: ") + name + " must hold 9 numbers");
  cv::Matx33d m;
  for (int k = 0; k < 9; ++k) m.val[k] = h[k];
  if (!std::isfinite(cv::determinant(m)) || std::abs(cv::determinant(m)) < 1e-300)
    throw std::invalid_argument(std::string("tile record: ") + name + " is singular or not finite");
  return m;
}

Eigen::Vector2d pointField(const nlohmann::json& json, const char* name) {
  const auto v = field<std::vector<double>>(json, name);
  if (v.size() != 2 || !std::isfinite(v[0]) || !std::isfinite(v[1]))
    throw std::invalid_argument(std::string("tile record: ") + name + " must hold 2 finite numbers");
  return Eigen::Vector2d(v[0], v[1]);
}

}  // namespace

TileRecord tileRecordFromJson(const nlohmann::json& j) {
  if (!j.is_object()) throw std::invalid_argument("tile record: not a JSON object");
  TileRecord r;
  r.index = field<int>(j, "index");
  r.version = field<int>(j, "version");
  r.ground_origin_en_m = pointField(j, "ground_origin_en_m");
  r.gsd_m = field<double>(j, "gsd_m");
  if (!(r.gsd_m > 0)) throw std::invalid_argument("tile record: gsd_m must be > 0");
  r.utm_zone = field<int>(j, "utm_zone");
  r.northern_hemisphere = field<bool>(j, "northern_hemisphere");
  r.local_frame = field<std::string>(j, "local_frame");
  const nlohmann::json m = field<nlohmann::json>(j, "metadata");
  r.metadata.dive_name = field<std::string>(m, "dive_name");
  r.metadata.first_frame = field<int>(m, "first_frame");
  r.metadata.last_frame = field<int>(m, "last_frame");
  r.metadata.start_time_s = field<double>(m, "start_time_s");
  r.metadata.end_time_s = field<double>(m, "end_time_s");
  r.metadata.close_reason = field<std::string>(m, "close_reason");
  r.metadata.extra = field<std::map<std::string, std::string>>(m, "extra");
  if (m.contains("mean_altitude_m")) r.metadata.mean_altitude_m = field<double>(m, "mean_altitude_m");
  for (const auto& i : field<nlohmann::json>(j, "images")) {
    RecordedImage image;
    image.frame = field<int>(i, "frame");
    image.stamp_s = field<double>(i, "stamp_s");
    image.file = field<std::string>(i, "file");
    if (image.file.empty() || image.file.find('/') != std::string::npos)
      throw std::invalid_argument("tile record: an image file must be a plain name (got '" + image.file + "')");
    image.width_px = field<int>(i, "width_px");
    image.height_px = field<int>(i, "height_px");
    if (image.width_px <= 0 || image.height_px <= 0)
      throw std::invalid_argument("tile record: an image's width_px and height_px must be > 0");
    image.closed_ground_from_px = matrixField(i, "closed_ground_from_px");
    image.closed_correction_m = pointField(i, "closed_correction_m");
    if (i.contains("closed_navigation_m")) image.closed_navigation_m = pointField(i, "closed_navigation_m");
    if (i.contains("closed_navigation_heading_rad")) {
      const double heading = field<double>(i, "closed_navigation_heading_rad");
      if (!std::isfinite(heading))
        throw std::invalid_argument("tile record: an image's closed_navigation_heading_rad must be finite");
      image.closed_navigation_heading_rad = heading;
    }
    image.ground_from_px = matrixField(i, "ground_from_px");
    if (i.contains("gain")) {
      image.gain = field<std::array<double, 3>>(i, "gain");
      for (double g : image.gain)
        if (!(g > 0.0 && std::isfinite(g)))
          throw std::invalid_argument("tile record: an image's gain must hold 3 finite numbers > 0");
    }
    r.images.push_back(image);
  }
  if (j.contains("adjustment")) r.adjustment = matrixField(j, "adjustment");
  return r;
}

std::string recordedImageName(const std::string& prefix, double stamp_s) {
  return prefix + "_" + std::to_string(std::llround(stamp_s * 1e9)) + ".jpg";
}

std::string writeRecordedImage(const std::string& folder, const std::string& name, const cv::Mat& image,
                               int jpeg_quality) {
  if (image.empty() || image.depth() != CV_8U || (image.channels() != 1 && image.channels() != 3))
    return "image " + name + " not kept: it must be 8-bit grey or BGR";
  std::vector<uchar> bytes;
  try {
    if (!cv::imencode(".jpg", image, bytes, {cv::IMWRITE_JPEG_QUALITY, std::clamp(jpeg_quality, 50, 100)}))
      return "image " + name + " not kept: JPEG encoding failed";
    exocet_common::writeFileAtomically(folder + "/" + name, std::string(bytes.begin(), bytes.end()));
  } catch (const std::exception& e) {
    return "image " + name + " not kept: " + e.what();
  }
  return "";
}

std::string RevisionConfig::validate() const {
  std::string e;
  const auto bad = [&](const std::string& what) { e += (e.empty() ? "" : "; ") + what; };
  if (!(target_sigma_m > 0 && target_sigma_m <= 10)) bad("target_sigma_m must be in (0, 10]");
  if (!(scale_prior_sigma > 0 && scale_prior_sigma <= 1)) bad("scale_prior_sigma must be in (0, 1]");
  if (!(rotation_prior_sigma > 0 && rotation_prior_sigma <= 1)) bad("rotation_prior_sigma must be in (0, 1]");
  if (residual_window_images < 0 || residual_window_images > 101 ||
      (residual_window_images > 0 && residual_window_images % 2 == 0))
    bad("residual_window_images must be 0 or odd in [1, 101] (got " + std::to_string(residual_window_images) + ")");
  return e;
}

namespace {

Eigen::Vector2d centreOf(const RecordedImage& image) {
  return Eigen::Vector2d(0.5 * (image.width_px - 1), 0.5 * (image.height_px - 1));
}

cv::Matx33d translation(const Eigen::Vector2d& t) { return cv::Matx33d(1, 0, t.x(), 0, 1, t.y(), 0, 0, 1); }

/// Least squares of p = (da, b, tx, ty) in  target = q + [da -b; b da] (q - c) + t  with priors on da and b.
Eigen::Vector4d fitSimilarity(const std::vector<Eigen::Vector2d>& q, const std::vector<Eigen::Vector2d>& target,
                              const std::vector<bool>& use, const Eigen::Vector2d& c, const RevisionConfig& config) {
  Eigen::Matrix4d a = Eigen::Matrix4d::Zero();
  Eigen::Vector4d rhs = Eigen::Vector4d::Zero();
  const double w = 1.0 / (config.target_sigma_m * config.target_sigma_m);
  for (std::size_t i = 0; i < q.size(); ++i) {
    if (!use[i]) continue;
    const Eigen::Vector2d d = q[i] - c;
    Eigen::Matrix<double, 2, 4> j;
    j << d.x(), -d.y(), 1, 0, d.y(), d.x(), 0, 1;
    a += w * j.transpose() * j;
    rhs += w * j.transpose() * (target[i] - q[i]);
  }
  a(0, 0) += 1.0 / (config.scale_prior_sigma * config.scale_prior_sigma);
  a(1, 1) += 1.0 / (config.rotation_prior_sigma * config.rotation_prior_sigma);
  return a.ldlt().solve(rhs);
}

Eigen::Vector2d applySimilarity(const Eigen::Vector4d& p, const Eigen::Vector2d& c, const Eigen::Vector2d& q) {
  const Eigen::Vector2d d = q - c;
  return q + Eigen::Vector2d(p(0) * d.x() - p(1) * d.y(), p(1) * d.x() + p(0) * d.y()) + p.tail<2>();
}

double wrapAngle(double a) { return std::remainder(a, 2.0 * M_PI); }

/// How far each image's content must turn (rad, counter-clockwise) to follow its pose's heading: minus the trend (a
/// straight line in time, least squares, without the images more than kMaxDriftRad or three median deviations off a
/// first fit) of the disagreement between the chain's placement at close and the poses' headings, taken relative to
/// its value mid-tile. A line over the whole tile averages the heading's noise over every image and takes the
/// chain's drift, which grows along the tile. Empty when fewer than 3 images have a heading (nothing to fit).
std::vector<double> contentTurnsRad(const TileRecord& record) {
  // A disagreement this far from the tile's median is a pose the filter got wrong (or a turn the stamps lag), not
  // the chain's drift.
  constexpr double kMaxDriftRad = 0.1;
  const std::size_t n = record.images.size();
  std::vector<double> stamps, drifts;
  for (const RecordedImage& image : record.images) {
    if (!image.closed_navigation_heading_rad) continue;
    const double d = compose::imageXDirectionRad(image.closed_ground_from_px, centreOf(image)) -
                     *image.closed_navigation_heading_rad;
    if (!std::isfinite(d) || !std::isfinite(image.stamp_s)) continue;
    stamps.push_back(image.stamp_s);
    drifts.push_back(wrapAngle(d));
  }
  if (drifts.size() < 3) return {};
  // On the circle: relative to the median.
  std::vector<double> sorted;
  for (double d : drifts) sorted.push_back(wrapAngle(d - drifts.front()));
  std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
  const double median = drifts.front() + sorted[sorted.size() / 2];
  for (double& d : drifts) d = wrapAngle(d - median);
  const double t0 = 0.5 * (stamps.front() + stamps.back());
  std::vector<bool> use(drifts.size());
  for (std::size_t i = 0; i < drifts.size(); ++i) use[i] = std::abs(drifts[i]) <= kMaxDriftRad;
  Eigen::Vector2d line = Eigen::Vector2d::Zero();  // drift = line(0) + line(1) (t - t0)
  for (int pass = 0; pass < 2; ++pass) {
    Eigen::Matrix2d a = Eigen::Matrix2d::Zero();
    Eigen::Vector2d b = Eigen::Vector2d::Zero();
    int used = 0;
    for (std::size_t i = 0; i < drifts.size(); ++i) {
      if (!use[i]) continue;
      const Eigen::Vector2d j(1.0, stamps[i] - t0);
      a += j * j.transpose();
      b += j * drifts[i];
      ++used;
    }
    if (used < 3 || std::abs(a.determinant()) < 1e-12) return {};
    line = a.ldlt().solve(b);
    if (pass == 1) break;
    std::vector<double> deviations;
    for (std::size_t i = 0; i < drifts.size(); ++i)
      if (use[i]) deviations.push_back(std::abs(drifts[i] - line(0) - line(1) * (stamps[i] - t0)));
    std::nth_element(deviations.begin(), deviations.begin() + deviations.size() / 2, deviations.end());
    const double limit = std::max(3.0 * deviations[deviations.size() / 2], 1e-4);
    for (std::size_t i = 0; i < drifts.size(); ++i)
      if (use[i]) use[i] = std::abs(drifts[i] - line(0) - line(1) * (stamps[i] - t0)) <= limit;
  }
  std::vector<double> turn(n);
  for (std::size_t i = 0; i < n; ++i) turn[i] = -line(1) * (record.images[i].stamp_s - t0);
  return turn;
}

}  // namespace

void applyTileAdjustment(TileRecord* record, const Eigen::Vector2d& centre_en_m, const Eigen::Vector2d& shift_en_m,
                         double rotation_rad, double scale_change) {
  // In the record's ground frame q = p - o:  q' = q + shift + B (q + o - c),  B = [s -r; r s].
  const double s = scale_change, r = rotation_rad;
  const Eigen::Vector2d d = record->ground_origin_en_m - centre_en_m;
  const Eigen::Vector2d t = shift_en_m + Eigen::Vector2d(s * d.x() - r * d.y(), r * d.x() + s * d.y());
  const cv::Matx33d move(1 + s, -r, t.x(), r, 1 + s, t.y(), 0, 0, 1);
  record->adjustment = compose::normalizeHomography(move * record->adjustment);
}

std::vector<cv::Matx33d> placementsAt(const TileRecord& record, const PositionCorrectionTrack& track,
                                      const RevisionConfig& config) {
  const std::string error = config.validate();
  if (!error.empty()) throw std::invalid_argument("placementsAt: " + error);
  const std::size_t n = record.images.size();
  std::vector<Eigen::Vector2d> q(n), target(n);
  std::vector<bool> use(n, false);
  Eigen::Vector2d c = Eigen::Vector2d::Zero();
  int targets = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const RecordedImage& image = record.images[i];
    q[i] = compose::applyHomography(image.closed_ground_from_px, centreOf(image));
    if (image.closed_navigation_m) {
      target[i] = *image.closed_navigation_m + (track.at(image.stamp_s) - image.closed_correction_m);
      use[i] = target[i].allFinite() && q[i].allFinite();
    }
    if (use[i]) {
      c += q[i];
      ++targets;
    }
  }
  std::vector<cv::Matx33d> out(n);
  if (targets == 0) {
    for (std::size_t i = 0; i < n; ++i) {
      const RecordedImage& image = record.images[i];
      out[i] = compose::normalizeHomography(record.adjustment *
                                            translation(track.at(image.stamp_s) - image.closed_correction_m) *
                                            image.closed_ground_from_px);
    }
    return out;
  }
  c /= targets;
  Eigen::Vector4d p = fitSimilarity(q, target, use, c, config);
  // One pass without the targets far from the fit (a pose the filter got wrong).
  std::vector<double> residuals;
  for (std::size_t i = 0; i < n; ++i)
    if (use[i]) residuals.push_back((target[i] - applySimilarity(p, c, q[i])).norm());
  std::nth_element(residuals.begin(), residuals.begin() + residuals.size() / 2, residuals.end());
  const double limit = std::max(3.0 * residuals[residuals.size() / 2], 2.0 * record.gsd_m);
  std::vector<bool> kept = use;
  for (std::size_t i = 0; i < n; ++i)
    if (use[i] && (target[i] - applySimilarity(p, c, q[i])).norm() > limit) kept[i] = false;
  if (std::count(kept.begin(), kept.end(), true) > 0) p = fitSimilarity(q, target, kept, c, config);

  // The similarity as a matrix on ground points: g -> g + A (g - c) + t.
  const cv::Matx33d similarity(1 + p(0), -p(1), p(2) - p(0) * c.x() + p(1) * c.y(), p(1), 1 + p(0),
                               p(3) - p(1) * c.x() - p(0) * c.y(), 0, 0, 1);
  std::vector<Eigen::Vector2d> residual(n, Eigen::Vector2d::Zero());
  for (std::size_t i = 0; i < n; ++i)
    if (kept[i]) residual[i] = target[i] - applySimilarity(p, c, q[i]);
  const std::vector<double> turn_rad =
      config.content_follows_heading ? contentTurnsRad(record) : std::vector<double>();
  const double similarity_rotation_rad = std::atan2(p(1), 1.0 + p(0));
  const int half = config.residual_window_images / 2;
  for (std::size_t i = 0; i < n; ++i) {
    cv::Matx33d placed = similarity * record.images[i].closed_ground_from_px;
    if (!turn_rad.empty()) {
      // The content turned about the image's centre: back from the similarity's rotation, and by the heading.
      const Eigen::Vector2d g = compose::applyHomography(placed, centreOf(record.images[i]));
      const double a = turn_rad[i] - similarity_rotation_rad, c = std::cos(a), sn = std::sin(a);
      const cv::Matx33d turn(c, -sn, g.x() - c * g.x() + sn * g.y(), sn, c, g.y() - sn * g.x() - c * g.y(), 0, 0, 1);
      placed = turn * placed;
    }
    Eigen::Vector2d bend = Eigen::Vector2d::Zero();
    if (config.residual_window_images > 0) {
      int count = 0;
      for (int k = -half; k <= half; ++k) {
        const long j = static_cast<long>(i) + k;
        if (j < 0 || j >= static_cast<long>(n) || !kept[j]) continue;
        bend += residual[j];
        ++count;
      }
      if (count > 0) bend /= count;
    }
    out[i] = compose::normalizeHomography(record.adjustment * translation(bend) * placed);
  }
  return out;
}

namespace {

/// Largest move of the images' corners from the record's current placements to `placements`.
double largestCornerMoveM(const TileRecord& record, const std::vector<cv::Matx33d>& placements) {
  double moved = 0;
  for (std::size_t i = 0; i < placements.size(); ++i) {
    const RecordedImage& image = record.images[i];
    const double w = image.width_px - 0.5, h = image.height_px - 0.5;
    for (const Eigen::Vector2d& corner : {Eigen::Vector2d(-0.5, -0.5), Eigen::Vector2d(w, -0.5), Eigen::Vector2d(w, h),
                                         Eigen::Vector2d(-0.5, h)})
      moved = std::max(moved, (compose::applyHomography(placements[i], corner) -
                               compose::applyHomography(image.ground_from_px, corner))
                                  .norm());
  }
  return moved;
}

}  // namespace

double tileDisplacementM(const TileRecord& record, const PositionCorrectionTrack& track,
                         const RevisionConfig& config) {
  return largestCornerMoveM(record, placementsAt(record, track, config));
}

void addImagePlacements(const TileRecord& record, const std::vector<cv::Matx33d>& ground_from_px,
                        const compose::LightingCorrector* lighting, const cv::Size& grid,
                        std::map<std::string, compose::ImagePlacement>* placements) {
  const cv::Matx33d en_from_ground(1, 0, record.ground_origin_en_m.x(), 0, 1, record.ground_origin_en_m.y(), 0, 0, 1);
  for (std::size_t i = 0; i < record.images.size(); ++i) {
    const RecordedImage& image = record.images[i];
    compose::ImagePlacement p;
    p.en_from_px = en_from_ground * (i < ground_from_px.size() ? ground_from_px[i] : image.ground_from_px);
    if (lighting) p.block_gain = lighting->gainGrid(cv::Size(image.width_px, image.height_px), grid);
    (*placements)[image.file] = p;
  }
}

cv::Mat withGain(const cv::Mat& image, const std::array<double, 3>& gain) {
  if (image.empty() || image.depth() != CV_8U) return image;
  cv::Mat out;
  if (image.channels() == 3)
    cv::multiply(image, cv::Scalar(gain[0], gain[1], gain[2]), out);
  else
    image.convertTo(out, -1, gain[0]);
  return out;
}

RevisedTile renderTileAt(const TileRecord& record, const PositionCorrectionTrack& track, const std::string& images_dir,
                         compose::PlacedImageRenderConfig render, const RevisionConfig& config,
                         const std::function<cv::Mat(const cv::Mat&)>& prepare) {
  return renderTileWith(record, placementsAt(record, track, config), images_dir, render, prepare);
}

RevisedTile renderTileWith(const TileRecord& record, const std::vector<cv::Matx33d>& placements,
                           const std::string& images_dir, compose::PlacedImageRenderConfig render,
                           const std::function<cv::Mat(const cv::Mat&)>& prepare) {
  RevisedTile out;
  out.record = record;
  out.record.version = record.version + 1;
  render.gsd_m = record.gsd_m;
  if (placements.size() != record.images.size()) {
    out.problem = "placements for " + std::to_string(placements.size()) + " images, the tile has " +
                  std::to_string(record.images.size());
    return out;
  }
  out.moved_max_m = largestCornerMoveM(record, placements);
  std::vector<compose::PlacedImage> placed;
  for (std::size_t i = 0; i < placements.size(); ++i) {
    RecordedImage& image = out.record.images[i];
    image.ground_from_px = placements[i];
    cv::Mat pixels = cv::imread(images_dir + "/" + image.file, cv::IMREAD_UNCHANGED);
    if (pixels.empty()) {
      ++out.images_missing;
      out.problem = "image " + images_dir + "/" + image.file + " cannot be read: left out";
      continue;
    }
    cv::Mat drawn = prepare ? prepare(pixels) : pixels;
    if (image.gain != std::array<double, 3>{1.0, 1.0, 1.0}) drawn = withGain(drawn, image.gain);
    placed.push_back({drawn, image.ground_from_px});
  }
  const compose::PlacedRaster drawn = compose::renderPlacedImages(placed, record.ground_origin_en_m, render);
  if (drawn.image.empty()) {
    out.problem = drawn.problem.empty() ? "nothing drawn" : drawn.problem;
    return out;
  }
  if (!drawn.problem.empty()) out.problem = drawn.problem;
  out.raster.image = drawn.image;
  out.raster.mask = drawn.mask;
  out.raster.origin_easting_m = drawn.origin_easting_m;
  out.raster.origin_northing_m = drawn.origin_northing_m;
  out.raster.gsd_m = drawn.gsd_m;
  out.raster.utm_zone = record.utm_zone;
  out.raster.northern_hemisphere = record.northern_hemisphere;
  out.raster.local_frame = record.local_frame;
  return out;
}

}  // namespace tiles
}  // namespace exocet_mosaic
