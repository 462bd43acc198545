#include "exocet_mosaic/compose/mosaic_composer.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <sstream>
#include <stdexcept>

#include <Eigen/Dense>
#include <opencv2/imgproc.hpp>

#include "anchor_fit.h"
#include "canvas_warp.h"
#include "exocet_mosaic/compose/block_canvas.h"
#include "exocet_mosaic/compose/feather_weights.h"
#include "exocet_mosaic/compose/image_reduction.h"
#include "exocet_mosaic/compose/lighting_corrector.h"
#include "multiband_blend.h"

namespace exocet_mosaic {
namespace compose {
namespace {

cv::Matx33d translation(double tx, double ty) { return cv::Matx33d(1, 0, tx, 0, 1, ty, 0, 0, 1); }

/// The 3x3 (affine) matrix of a fit: local -> measured.
cv::Matx33d fitMatrix(const AnchorFit& fit) {
  const Eigen::Matrix2d a = fit.linear();
  const Eigen::Vector2d t = fit.centre_m + fit.params.tail<2>() - a * fit.centre_m;
  return cv::Matx33d(a(0, 0), a(0, 1), t.x(), a(1, 0), a(1, 1), t.y(), 0, 0, 1);
}

std::array<Eigen::Vector2d, 4> imageCorners(const cv::Size& s) {
  return {Eigen::Vector2d(-0.5, -0.5), Eigen::Vector2d(s.width - 0.5, -0.5),
          Eigen::Vector2d(s.width - 0.5, s.height - 0.5), Eigen::Vector2d(-0.5, s.height - 0.5)};
}

Eigen::Vector2d imageCentre(const cv::Size& s) { return Eigen::Vector2d(0.5 * (s.width - 1), 0.5 * (s.height - 1)); }

/// Where consecutive mosaics are tied: a 3 x 3 grid over the shared image (corners, edge midpoints, centre). The
/// closed tile places the image through the chain, the next one through its pose: the two differ by a little
/// perspective that a similarity cannot absorb; over the grid the fit matches them on average over the image, where
/// the tiles overlap, rather than at the four corners only.
std::vector<Eigen::Vector2d> tieGrid(const cv::Size& s) {
  std::vector<Eigen::Vector2d> grid;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) grid.emplace_back(-0.5 + 0.5 * c * s.width, -0.5 + 0.5 * r * s.height);
  return grid;
}

}  // namespace

/// Where the next mosaic's fit is tied to the closed one (their shared image).
struct ContinuityTie {
  bool valid = false;
  std::vector<Eigen::Vector2d> points_utm;  // the shared image's tieGrid() where the closed tile put it
  Eigen::MatrixXd error_cov;                // 2n x 2n: their joint uncertainty (closed fit + continuity slack)
  cv::Matx33d utm_from_px;                  // the closed mosaic's placement of the shared image, relative to utm_origin
  Eigen::Vector2d utm_origin = Eigen::Vector2d::Zero();
  double gsd_m = 0;
};

/// The open mosaic.
struct OpenMosaic {
  OpenMosaic(int channels, int block_size) : canvas(channels, block_size) {}
  double gsd_m = 0;
  Eigen::Vector2d ref_en_m = Eigen::Vector2d::Zero();  // UTM of the local frame's origin (multiple of gsd)
  cv::Matx33d p_first;                                 // first image px -> local ground (m)
  cv::Matx33d canvas_from_local;                       // local ground (m) -> canvas px (north-up)
  BlockCanvas canvas;
  int channels = 3;
  bool similarity = true;
  double prior_sigma = 0.05;
  cv::Matx33d chain = cv::Matx33d::eye();  // the last image's px -> first image px
  cv::Size last_size;                      // the last image's size
  bool has_composed = false;
  cv::Matx33d last_composed_chain = cv::Matx33d::eye();
  bool pending = false;  // the last image is not composed (kept to compose it if the mosaic closes now)
  cv::Mat pending_image;
  bool pending_reduced = false;  // pending_image is at 1/pending_reduction already (else at full resolution)
  std::function<cv::Mat(int)> pending_load;  // or how to get it (not decoded unless the mosaic closes on it)
  int pending_reduction = 1;
  cv::Size pending_size;
  int pending_channels = 0;
  cv::Matx33d pending_chain;
  std::vector<AnchorPoint> points;  // navigation points
  AnchorTie tie;                    // where the previous mosaic put the shared image (continued mosaics)
  AnchorAccumulator running;
  std::vector<std::array<Eigen::Vector2d, 4>> footprints_local;
  Eigen::Vector2d extent_min = Eigen::Vector2d::Constant(1e300), extent_max = Eigen::Vector2d::Constant(-1e300);
  int first_frame = -1, last_frame = -1, frames_added = 0, frames_composed = 0;
  int jump_streak = 0;  ///< consecutive images whose fused position departs from the chain
  double start_time_s = 0, end_time_s = 0, height_sum_m = 0;
  int height_count = 0;
  std::vector<WarpedFrame> kept;  // for multi-band blending at close
  struct Composed {
    int index;
    double stamp_s;
    cv::Mat image;
    int reduction;
    cv::Matx33d local_from_px;  // of `image`'s pixels
    std::optional<Eigen::Vector2d> navigation_m;  // where the image's own pose puts its centre (ground - ref)
    std::optional<double> navigation_heading_rad;  // and how it orients the image's x axis there
  };
  std::vector<Composed> composed;  // config.keep_composed_images: what was drawn, for ClosedMosaic::images
  std::size_t composed_bytes = 0;
  std::optional<Eigen::Vector2d> pending_navigation;  // the pending image's centre from its pose
  std::optional<double> pending_navigation_heading_rad;
  bool all_kept = true;
  std::size_t kept_bytes = 0;

  std::size_t memoryBytes() const {
    return canvas.memoryBytes() + kept_bytes + composed_bytes + (pending ? pending_image.total() * pending_image.elemSize() : 0);
  }
  double extentM() const {
    return frames_composed == 0 ? 0.0 : std::max(extent_max.x() - extent_min.x(), extent_max.y() - extent_min.y());
  }
};

struct MosaicComposer::Impl {
  explicit Impl(const ComposerConfig& config) : lighting(config.lighting) {}
  LightingCorrector lighting;
  FeatherWeights feather;
  ComposerStats stats;
  std::unique_ptr<OpenMosaic> open;
  bool previous_in_chain = false;  // the previous add() put its image into the open mosaic's chain
  ContinuityTie tie;
  double last_height_m = 0;
  int frames_since_lighting_sample = 0;  // images added since the lighting field last observed one
  int image_reduction = 0;               // the reduction images are composed at (0: none chosen yet)
};

MosaicComposer::MosaicComposer(const ComposerConfig& config) : config_(config) {
  const std::string error = config.validate();
  if (!error.empty()) throw std::invalid_argument("MosaicComposer: " + error);
  impl_ = std::make_unique<Impl>(config);
}

MosaicComposer::~MosaicComposer() = default;

const LightingCorrector& MosaicComposer::lighting() const { return impl_->lighting; }

LightingCorrector MosaicComposer::lightingSnapshot() const {
  return config_.lighting.enabled ? impl_->lighting.clone() : LightingCorrector(config_.lighting);
}

void MosaicComposer::setConfig(const ComposerConfig& config) {
  const std::string error = config.validate();
  if (!error.empty()) throw std::invalid_argument("MosaicComposer: " + error);
  config_ = config;
  impl_->lighting.setConfig(config.lighting);
}

ComposerStats MosaicComposer::stats() const {
  ComposerStats s = impl_->stats;
  s.lighting_ready = impl_->lighting.ready();
  s.image_reduction = std::max(1, impl_->image_reduction);
  if (impl_->open) {
    s.open_memory_bytes = impl_->open->memoryBytes();
    s.open_extent_m = impl_->open->extentM();
    s.open_frames = impl_->open->frames_added;
  }
  return s;
}

cv::Mat MosaicComposer::preview(int max_side_px) const {
  if (!impl_->open || max_side_px <= 0) return cv::Mat();
  const cv::Rect region = impl_->open->canvas.dataBounds();
  if (region.empty()) return cv::Mat();
  const double scale = std::min(1.0, static_cast<double>(max_side_px) / std::max(region.width, region.height));
  cv::Mat image, mask;
  impl_->open->canvas.render(region, &image, &mask, scale);
  if (image.channels() == 1) cv::cvtColor(image, image, cv::COLOR_GRAY2BGR);
  return image;
}

namespace {

/// Composes one image of the open mosaic (placed by chain, in full-resolution px) into the canvas; raw is the image
/// at 1/reduction.
void composeImage(OpenMosaic& m, const cv::Mat& raw, int reduction, const cv::Matx33d& chain, int frame_index,
                  double stamp_s, const ComposerConfig& config, const LightingCorrector& lighting,
                  FeatherWeights& feather, ComposerStats& stats) {
  cv::Mat image = config.lighting.enabled ? lighting.correct(raw) : raw;
  if (image.channels() != m.channels) {
    cv::Mat converted;
    cv::cvtColor(image, converted, m.channels == 3 ? cv::COLOR_GRAY2BGR : cv::COLOR_BGR2GRAY);
    image = converted;
  }
  const cv::Matx33d local_from_px = normalizeHomography(m.p_first * chain * fullFromReducedPx(reduction));
  const cv::Matx33d canvas_from_px = normalizeHomography(m.canvas_from_local * local_from_px);
  const auto corners = imageCorners(image.size());
  std::array<Eigen::Vector2d, 4> footprint;
  for (int i = 0; i < 4; ++i) footprint[i] = applyHomography(local_from_px, corners[i]);
  // Replicated border: the pixels half covered at the footprint's edge take the edge colour, not black; the alpha
  // fades there.
  const bool replace = config.blend == "none";
  const cv::Mat& w = replace ? feather.get(image.size(), 1e-9) : feather.get(image.size(), config.feather_power);
  CanvasWarp warp;
  if (!warpOntoCanvas(image, w, canvas_from_px, &warp, &stats.last_problem)) return;
  const cv::Mat& warped = warp.image_alpha;
  const cv::Rect& roi = warp.roi;
  if (config.keep_composed_images) {
    cv::Mat kept = raw;  // before the lighting correction (ComposedImage::image)
    if (kept.channels() != m.channels)
      cv::cvtColor(raw, kept, m.channels == 3 ? cv::COLOR_GRAY2BGR : cv::COLOR_BGR2GRAY);
    m.composed.push_back({frame_index, stamp_s, kept, reduction, local_from_px, std::nullopt, std::nullopt});
    m.composed_bytes += kept.total() * kept.elemSize();
  }
  m.canvas.accumulateAlpha(warped, roi.tl(), replace);
  if (config.blend == "multiband") {
    std::vector<cv::Mat> wp;
    cv::split(warped, wp);
    cv::Mat weight_f, colour;
    wp.back().convertTo(weight_f, CV_32F, 1.0 / 255.0);
    wp.pop_back();
    cv::merge(wp, colour);
    m.kept.push_back({colour, weight_f, roi});
    m.kept_bytes += colour.total() * colour.elemSize() + weight_f.total() * weight_f.elemSize();
  } else {
    m.all_kept = false;
  }
  m.footprints_local.push_back(footprint);
  for (const auto& p : footprint) {
    m.extent_min = m.extent_min.cwiseMin(p);
    m.extent_max = m.extent_max.cwiseMax(p);
  }
  ++m.frames_composed;
  ++stats.frames_composed;
  m.has_composed = true;
  m.last_composed_chain = chain;
  m.pending = false;
  m.pending_image.release();
  m.pending_load = nullptr;
}

/// The frame's image at 1/reduction, from its loader. Empty (and *problem set) when the loader fails or its image
/// has neither the announced shape nor that shape reduced.
cv::Mat loadImage(const std::function<cv::Mat(int)>& load, const cv::Size& size, int channels, int reduction,
                  int index, std::string* problem) {
  cv::Mat image;
  try {
    image = load(reduction);
  } catch (const std::exception& e) {
    *problem = "frame " + std::to_string(index) + " skipped: its image cannot be loaded: " + e.what();
    return cv::Mat();
  }
  const cv::Mat reduced = image.channels() == channels && image.depth() == CV_8U ? reduceImage(image, size, reduction)
                                                                                 : cv::Mat();
  if (reduced.empty()) {
    const cv::Size expected = reducedImageSize(size, reduction);
    *problem = "frame " + std::to_string(index) + " skipped: its image is " + std::to_string(image.cols) + "x" +
               std::to_string(image.rows) + "x" + std::to_string(image.channels()) + ", announced " +
               std::to_string(size.width) + "x" + std::to_string(size.height) + "x" + std::to_string(channels) +
               (reduction > 1 ? " (or " + std::to_string(expected.width) + "x" + std::to_string(expected.height) +
                                    " reduced by " + std::to_string(reduction) + ")"
                              : "");
    return cv::Mat();
  }
  return reduced;
}

/// True if the image placed by chain moved enough since the last composed one to be a key frame.
bool isKeyFrame(const OpenMosaic& m, const cv::Matx33d& chain, const cv::Size& size, double fraction) {
  if (!m.has_composed || fraction <= 0.0) return true;
  const cv::Matx33d current_from_last = chain.inv() * m.last_composed_chain;
  double moved = 0;
  for (const auto& c : imageCorners(size)) moved = std::max(moved, (applyHomography(current_from_last, c) - c).norm());
  return moved > fraction * std::min(size.width, size.height);
}

}  // namespace

std::optional<ClosedMosaic> MosaicComposer::add(const ComposerFrame& frame) {
  Impl& s = *impl_;
  ++s.stats.frames_added;
  const bool lazy = frame.image.empty() && frame.load_image;
  const cv::Size image_size = lazy ? frame.image_size : frame.image.size();
  const int image_channels = lazy ? frame.image_channels : frame.image.channels();
  auto skip = [&](const std::string& problem) {
    s.stats.last_problem = problem;
    ++s.stats.frames_skipped_no_chain;
    s.previous_in_chain = false;
    return std::nullopt;
  };
  if (image_size.empty() || (image_channels != 1 && image_channels != 3) || (!lazy && frame.image.depth() != CV_8U))
    return skip("frame " + std::to_string(frame.index) + " skipped: image must be CV_8UC1 or CV_8UC3");
  // The reduction this image is drawn at, from its pose's native GSD against the tiles' (image_reduction.h).
  if (frame.pose) {
    const double native_gsd_m = nativeGsd(*frame.pose);
    if (native_gsd_m > 0.0 && std::isfinite(native_gsd_m))
      s.image_reduction = chooseImageReduction(native_gsd_m, config_.gsd_m, config_.max_image_reduction,
                                               std::min(s.image_reduction, config_.max_image_reduction));
  }
  const int reduction = std::max(1, std::min(s.image_reduction, config_.max_image_reduction));
  // The image as drawn (at 1/reduction), loaded once; false when it cannot be had.
  cv::Mat drawn;
  auto materialize = [&]() {
    if (!drawn.empty()) return true;
    if (lazy) {
      drawn = loadImage(frame.load_image, image_size, image_channels, reduction, frame.index, &s.stats.last_problem);
    } else {
      drawn = reduceImage(frame.image, image_size, reduction);
      if (drawn.empty()) s.stats.last_problem = "frame " + std::to_string(frame.index) + " skipped: cannot reduce it";
    }
    return !drawn.empty();
  };
  // The lighting field observes every image decoded anyway (key frames, the first image of a mosaic), before it is
  // corrected, and when none came for sample_interval_frames images one more is decoded for it: decoding is the
  // composer's main cost, and moving key frames are the decorrelated samples of the seabed the average needs.
  bool lighting_observed = false;
  auto observeLighting = [&]() {
    if (!config_.lighting.enabled || lighting_observed || drawn.empty()) return;
    s.lighting.observe(drawn);
    s.frames_since_lighting_sample = 0;
    lighting_observed = true;
  };
  ++s.frames_since_lighting_sample;
  const bool lighting_due =
      config_.lighting.enabled && s.frames_since_lighting_sample >= config_.lighting.sample_interval_frames;
  // A frame that starts a mosaic is drawn: load it now, before any state changes.
  if ((lighting_due || !s.open) && !materialize()) return skip(s.stats.last_problem);
  if (lighting_due || !s.open) observeLighting();

  // The pose's ground projection, relative to the open mosaic's origin (or absolute UTM when none is open).
  const Eigen::Vector2d origin = s.open ? s.open->ref_en_m : Eigen::Vector2d::Zero();
  cv::Matx33d p_frame;
  bool has_pose = false;
  if (frame.pose) {
    has_pose = groundFromPixel(*frame.pose, image_size, origin, &p_frame);
    if (!has_pose)
      s.stats.last_problem = "frame " + std::to_string(frame.index) + ": pose does not see the seabed";
    else
      s.last_height_m = frame.pose->camera_height_m;
  }

  if (!s.open) {
    if (!has_pose) {
      ++s.stats.frames_skipped_no_pose;
      s.stats.last_problem = "frame " + std::to_string(frame.index) + " skipped: no pose to start a mosaic";
      s.previous_in_chain = false;
      return std::nullopt;
    }
    startMosaic(frame, drawn, reduction, image_size, false);
    return std::nullopt;
  }

  OpenMosaic& m = *s.open;
  const AnchorFit running = m.running.solve(m.similarity, m.prior_sigma);
  cv::Matx33d chain;
  bool bridged = false;
  if (frame.current_from_previous_px && s.previous_in_chain) {
    chain = normalizeHomography(m.chain * frame.current_from_previous_px->inv());
  } else if (has_pose) {
    // Bridge the chain with the pose: C_i = P_first^-1 o S^-1 o P_i (S the current local -> UTM fit).
    chain = normalizeHomography(m.p_first.inv() * fitMatrix(running).inv() * p_frame);
    bridged = true;
    ++s.stats.registration_fallbacks;
  } else {
    ++s.stats.frames_skipped_no_chain;
    s.stats.last_problem = "frame " + std::to_string(frame.index) + " skipped: neither registration nor pose";
    s.previous_in_chain = false;
    return std::nullopt;
  }

  const cv::Size size = image_size;
  const Eigen::Vector2d centre_px = imageCentre(size);
  std::optional<AnchorPoint> point;
  std::optional<double> point_heading_rad;  // the image's x axis on the ground by its pose, with point
  if (has_pose && !bridged) {
    AnchorPoint p;
    p.local_m = applyHomography(m.p_first * chain, centre_px);
    p.measured_m = applyHomography(p_frame, centre_px);
    p.cov_m2 = frame.pose->position_cov_m2;
    // Navigation jump: the fused position departs from where the chain (after the current fit) puts the image.
    const Eigen::Vector2d residual = p.measured_m - running.apply(p.local_m);
    const Eigen::Matrix2d cov = p.cov_m2 + running.covAt(p.local_m);
    const double sigma = std::sqrt(std::max(0.0, Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d>(cov).eigenvalues()(1)));
    const double threshold = std::max(config_.navigation_jump_min_m, config_.navigation_jump_sigma * sigma);
    const bool departs = m.running.points() > 0 && residual.norm() > threshold;
    m.jump_streak = departs ? m.jump_streak + 1 : 0;
    if (departs && m.jump_streak < config_.navigation_jump_confirm_frames) {
      // One outlying fused position (a USBL outlier the filter let through) must not cut the mosaic: the image is
      // placed by the chain and its position left out of the fit until the departure persists.
      std::ostringstream msg;
      msg << "frame " << frame.index << ": fused position " << residual.norm() << " m from the chain (threshold "
          << threshold << " m), not used";
      s.stats.last_problem = msg.str();
    } else if (departs) {
      std::ostringstream msg;
      msg << "navigation jump at frame " << frame.index << ": " << residual.norm() << " m from the chain (threshold "
          << threshold << " m)";
      s.stats.last_problem = msg.str();
      ++s.stats.navigation_jumps;
      std::optional<ClosedMosaic> closed = closeMosaic("navigation_jump");
      s.tie.valid = false;  // the navigation moved: start afresh at the new pose
      if (groundFromPixel(*frame.pose, size, Eigen::Vector2d::Zero(), &p_frame) && materialize()) {
        observeLighting();
        startMosaic(frame, drawn, reduction, image_size, false);
      }
      return closed;
    } else {
      point = p;
      point_heading_rad = imageXDirectionRad(p_frame, centre_px);
    }
  }

  // Into the open mosaic.
  m.chain = chain;
  m.last_size = size;
  ++m.frames_added;
  m.last_frame = frame.index;
  m.end_time_s = frame.stamp_s;
  if (has_pose) {
    m.height_sum_m += frame.pose->camera_height_m;
    ++m.height_count;
  }
  if (point) {
    m.points.push_back(*point);
    m.running.add(*point);
  }
  s.previous_in_chain = true;
  if (isKeyFrame(m, chain, size, config_.min_key_frame_shift_fraction)) {
    // A key frame whose image cannot be loaded is left out; the chain (from the registration) goes on.
    if (materialize()) {
      observeLighting();
      composeImage(m, drawn, reduction, chain, frame.index, frame.stamp_s, config_, s.lighting, s.feather, s.stats);
      if (point && !m.composed.empty() && m.composed.back().index == frame.index) {
        m.composed.back().navigation_m = point->measured_m;
        m.composed.back().navigation_heading_rad = point_heading_rad;
      }
    }
  } else {
    m.pending = true;
    m.pending_navigation = point ? std::optional<Eigen::Vector2d>(point->measured_m) : std::nullopt;
    m.pending_navigation_heading_rad = point_heading_rad;
    m.pending_chain = chain;
    m.pending_size = image_size;
    m.pending_channels = image_channels;
    m.pending_reduction = reduction;
    m.pending_reduced = !drawn.empty();
    if (!drawn.empty()) {
      m.pending_image = drawn.clone();  // a copy: the caller may reuse its buffer
      m.pending_load = nullptr;
    } else if (!lazy) {
      frame.image.copyTo(m.pending_image);  // reduced only if the mosaic closes on this image
      m.pending_load = nullptr;
    } else {
      m.pending_image.release();  // decoded only if the mosaic closes on this image
      m.pending_load = frame.load_image;
    }
  }

  std::string reason;
  if (m.frames_added >= config_.frames_per_mosaic)
    reason = "frames";
  else if (m.extentM() >= config_.max_extent_m)
    reason = "extent";
  else if (m.memoryBytes() >= config_.max_memory_mb * 1024.0 * 1024.0)
    reason = "memory";
  if (reason.empty()) return std::nullopt;
  std::optional<ClosedMosaic> closed = closeMosaic(reason);
  if (materialize()) {  // the image also starts the next mosaic: consecutive tiles overlap
    observeLighting();
    startMosaic(frame, drawn, reduction, image_size, true);
  }
  return closed;
}

std::optional<ClosedMosaic> MosaicComposer::flush(const std::string& reason) {
  if (!impl_->open) return std::nullopt;
  std::optional<ClosedMosaic> closed = closeMosaic(reason);
  impl_->tie.valid = false;
  impl_->previous_in_chain = false;
  return closed;
}

void MosaicComposer::startMosaic(const ComposerFrame& frame, const cv::Mat& drawn, int reduction,
                                 const cv::Size& image_size, bool continued) {
  Impl& s = *impl_;
  s.open.reset();
  const cv::Size size = image_size;
  const Eigen::Vector2d centre_px = imageCentre(size);
  // This image's placement in UTM (utm = utm_origin + utm_from_px(px)): from its fused pose when it has one (P_first),
  // otherwise (a continued mosaic) where the closed mosaic put it.
  cv::Matx33d utm_from_px;
  Eigen::Vector2d utm_origin = Eigen::Vector2d::Zero();
  bool from_pose = false;
  if (frame.pose && groundFromPixel(*frame.pose, size, frame.pose->camera_en_m, &utm_from_px)) {
    utm_origin = frame.pose->camera_en_m;
    from_pose = true;
  } else if (continued && s.tie.valid) {
    utm_from_px = s.tie.utm_from_px;
    utm_origin = s.tie.utm_origin;
  } else {
    s.previous_in_chain = false;
    return;
  }
  double gsd = config_.gsd_m;
  if (gsd <= 0.0) {
    if (from_pose)
      gsd = roundGsdDown(nativeGsd(*frame.pose));
    else
      gsd = s.tie.gsd_m;
  }
  if (!(gsd > 0.0)) {
    s.stats.last_problem = "frame " + std::to_string(frame.index) + ": no ground sample distance (focal length 0?)";
    s.previous_in_chain = false;
    return;
  }
  const Eigen::Vector2d centre_utm = utm_origin + applyHomography(utm_from_px, centre_px);
  // The local frame's origin on a multiple of the GSD: the canvas grid is then aligned with round UTM coordinates.
  const Eigen::Vector2d ref(std::round(centre_utm.x() / gsd) * gsd, std::round(centre_utm.y() / gsd) * gsd);
  auto m = std::make_unique<OpenMosaic>(drawn.channels(), config_.block_size_px);
  m->channels = drawn.channels();
  m->gsd_m = gsd;
  m->ref_en_m = ref;
  m->p_first = normalizeHomography(translation(utm_origin.x() - ref.x(), utm_origin.y() - ref.y()) * utm_from_px);
  // Canvas pixel (col, row) has its centre at local (E, N) = ((col + 0.5) gsd, -(row + 0.5) gsd): north-up.
  m->canvas_from_local = cv::Matx33d(1.0 / gsd, 0, -0.5, 0, -1.0 / gsd, -0.5, 0, 0, 1);
  m->similarity = config_.anchor == "similarity";
  m->prior_sigma = config_.anchor_prior_sigma;
  m->running.reset(applyHomography(m->p_first, centre_px));
  m->first_frame = m->last_frame = frame.index;
  m->start_time_s = m->end_time_s = frame.stamp_s;
  m->frames_added = 1;
  m->last_size = size;
  std::optional<Eigen::Vector2d> first_navigation;
  std::optional<double> first_navigation_heading_rad;
  if (from_pose) {
    m->height_sum_m = frame.pose->camera_height_m;
    m->height_count = 1;
    AnchorPoint p;
    p.local_m = p.measured_m = applyHomography(m->p_first, centre_px);
    p.cov_m2 = frame.pose->position_cov_m2;
    m->points.push_back(p);
    m->running.add(p);
    first_navigation = p.measured_m;
    first_navigation_heading_rad = imageXDirectionRad(m->p_first, centre_px);
  }
  if (continued && s.tie.valid && s.tie.points_utm.size() == tieGrid(size).size()) {
    // Tied with the continuity slack only: the tiles stay aligned; the closed tile's own uncertainty enters the
    // reported covariance (sandwich), not the weights. The grid's points are one position known within the slack
    // (each weighs 1/n of it), against the few independent fused positions the tile's images are worth (closeMosaic()).
    const auto grid = tieGrid(size);
    const double n = static_cast<double>(grid.size());
    const double slack = std::max(1e-4, config_.tile_continuity_sigma_m);
    for (std::size_t i = 0; i < grid.size(); ++i) {
      AnchorPoint p;
      p.local_m = applyHomography(m->p_first, grid[i]);
      p.measured_m = s.tie.points_utm[i] - ref;
      p.cov_m2 = Eigen::Matrix2d::Identity() * n * slack * slack;
      m->tie.points.push_back(p);
      m->running.add(p);
    }
    m->tie.error_cov = s.tie.error_cov;
  }
  s.tie.valid = false;
  composeImage(*m, drawn, reduction, cv::Matx33d::eye(), frame.index, frame.stamp_s, config_, s.lighting, s.feather,
               s.stats);
  if (!m->composed.empty()) {
    m->composed.back().navigation_m = first_navigation;
    m->composed.back().navigation_heading_rad = first_navigation_heading_rad;
  }
  s.open = std::move(m);
  s.previous_in_chain = true;
}

std::optional<ClosedMosaic> MosaicComposer::closeMosaic(const std::string& reason) {
  Impl& s = *impl_;
  if (!s.open) return std::nullopt;
  std::unique_ptr<OpenMosaic> holder = std::move(s.open);
  OpenMosaic& m = *holder;
  // The last image before a close is always composed.
  cv::Mat pending_drawn;
  if (m.pending && m.pending_image.empty() && m.pending_load)
    pending_drawn = loadImage(m.pending_load, m.pending_size, m.pending_channels, m.pending_reduction, m.last_frame,
                              &s.stats.last_problem);
  else if (m.pending)
    pending_drawn = m.pending_reduced ? m.pending_image
                                      : reduceImage(m.pending_image, m.pending_size, m.pending_reduction);
  if (m.pending && !pending_drawn.empty()) {
    composeImage(m, pending_drawn, m.pending_reduction, m.pending_chain, m.last_frame, m.end_time_s, config_, s.lighting,
                 s.feather, s.stats);
    if (!m.composed.empty() && m.composed.back().index == m.last_frame) {
      m.composed.back().navigation_m = m.pending_navigation;
      m.composed.back().navigation_heading_rad = m.pending_navigation_heading_rad;
    }
  }
  const cv::Rect region = m.canvas.dataBounds();
  if (region.empty()) return std::nullopt;

  // The fused positions of a tile's images share most of their error: the filter's errors are correlated over
  // seconds (USBL fixes filtered by dead reckoning), so a tile's N images are a few independent measurements of where
  // the tile is, not N. Weighed as N, they outweighed the continuity tie (the shared image jumped between tiles by
  // 10-30 % of the navigation's disagreement with the chain: PAL bench dive 4 px) and their noise set the tile's
  // scale and rotation (+-1-2 % over a 3 m tile). They weigh as navigation_samples_per_mosaic positions, spread over
  // the images (an outlier among them moves the fit by 1/N of their share; add() leaves out those that depart).
  // The value trades the seams against how soon the navigation corrects the chain's scale (composer_config.h).
  std::vector<AnchorPoint> navigation = m.points;
  const double n_nav = static_cast<double>(navigation.size());
  for (auto& p : navigation) p.cov_m2 *= std::max(1.0, n_nav / config_.navigation_samples_per_mosaic);
  const AnchorFit fit =
      fitAnchor(navigation, m.tie.points.empty() ? nullptr : &m.tie, m.similarity, m.prior_sigma, true);
  ClosedMosaic out;
  if (config_.blend == "multiband" && m.all_kept && !m.kept.empty()) {
    blendMultiband(m.kept, region, config_.multiband_bands, m.channels, &out.image, &out.mask);
    out.blend = "multiband";
  } else {
    m.canvas.render(region, &out.image, &out.mask);
    out.blend = config_.blend == "none" ? "none" : "feather";
  }
  const double g = m.gsd_m;
  const Eigen::Vector2d centre_local((region.x + 0.5 * region.width) * g, -(region.y + 0.5 * region.height) * g);
  const Eigen::Vector2d shift = fit.apply(centre_local) - centre_local;
  // How far the fit's rotation/scale move the tile's corners: |[da -b; b da]| = sqrt(da^2 + b^2) times the radius.
  const double half_diagonal_px = 0.5 * std::hypot(region.width, region.height);
  const double effect_px = std::hypot(fit.params(0), fit.params(1)) * half_diagonal_px;
  out.gsd_m = g;
  if (effect_px > config_.resample_threshold_px) {
    // One resampling onto a north-up grid aligned on multiples of the GSD.
    double e_min = 1e300, e_max = -1e300, n_min = 1e300, n_max = -1e300;
    const double xe[2] = {region.x * g, (region.x + region.width) * g};
    const double yn[2] = {-region.y * g, -(region.y + region.height) * g};
    for (double e : xe)
      for (double n : yn) {
        const Eigen::Vector2d u = m.ref_en_m + fit.apply(Eigen::Vector2d(e, n));
        e_min = std::min(e_min, u.x());
        e_max = std::max(e_max, u.x());
        n_min = std::min(n_min, u.y());
        n_max = std::max(n_max, u.y());
      }
    const double e0 = std::floor(e_min / g) * g, n0 = std::ceil(n_max / g) * g;
    const cv::Size out_size(static_cast<int>(std::ceil((e_max - e0) / g - 1e-6)),
                            static_cast<int>(std::ceil((n0 - n_min) / g - 1e-6)));
    // Output pixel centre (c, r) -> UTM -> local (inverse fit) -> tile pixel: affine, from three points.
    auto tile_px = [&](double c, double r) {
      const Eigen::Vector2d u(e0 + (c + 0.5) * g, n0 - (r + 0.5) * g);
      const Eigen::Vector2d l = fit.applyInverse(u - m.ref_en_m);
      return Eigen::Vector2d(l.x() / g - 0.5 - region.x, -l.y() / g - 0.5 - region.y);
    };
    const Eigen::Vector2d p00 = tile_px(0, 0), p10 = tile_px(1, 0), p01 = tile_px(0, 1);
    const cv::Matx23d a(p10.x() - p00.x(), p01.x() - p00.x(), p00.x(), p10.y() - p00.y(), p01.y() - p00.y(), p00.y());
    cv::Mat image, mask;
    cv::warpAffine(out.image, image, a, out_size, cv::INTER_LINEAR | cv::WARP_INVERSE_MAP, cv::BORDER_CONSTANT);
    cv::warpAffine(out.mask, mask, a, out_size, cv::INTER_LINEAR | cv::WARP_INVERSE_MAP, cv::BORDER_CONSTANT);
    cv::threshold(mask, mask, 254, 255, cv::THRESH_BINARY);  // only pixels fully inside the data
    image.setTo(cv::Scalar::all(0), mask == 0);
    out.image = image;
    out.mask = mask;
    out.origin_easting_m = e0;
    out.origin_northing_m = n0;
    out.resampled = true;
  } else {
    out.origin_easting_m = m.ref_en_m.x() + region.x * g + shift.x();
    out.origin_northing_m = m.ref_en_m.y() - region.y * g + shift.y();
  }
  const cv::Matx33d ground_from_local =
      out.resampled ? fitMatrix(fit) : translation(shift.x(), shift.y());  // as the raster was drawn
  out.ground_origin_en_m = m.ref_en_m;
  for (const auto& c : m.composed)
    out.images.push_back(
        {c.index, c.stamp_s, c.image, c.reduction, normalizeHomography(ground_from_local * c.local_from_px),
         c.navigation_m, c.navigation_heading_rad});
  for (const auto& f : m.footprints_local) {
    std::array<Eigen::Vector2d, 4> u;
    for (int i = 0; i < 4; ++i) u[i] = m.ref_en_m + (out.resampled ? fit.apply(f[i]) : Eigen::Vector2d(f[i] + shift));
    out.footprints_en_m.push_back(u);
  }
  out.first_frame = m.first_frame;
  out.last_frame = m.last_frame;
  out.frames_added = m.frames_added;
  out.frames_composed = m.frames_composed;
  out.start_time_s = m.start_time_s;
  out.end_time_s = m.end_time_s;
  out.mean_camera_height_m = m.height_count > 0 ? m.height_sum_m / m.height_count : 0.0;
  out.close_reason = reason;
  out.anchor_correction_m = shift;
  out.anchor_sigma_m = std::sqrt(0.5 * fit.covAt(centre_local).trace());

  // The next mosaic starts with the last image: tie its fit to where this one put that image.
  ContinuityTie& tie = s.tie;
  const cv::Matx33d local_from_px = normalizeHomography(m.p_first * m.chain);
  tie.utm_from_px = normalizeHomography(fitMatrix(fit) * local_from_px);
  tie.utm_origin = m.ref_en_m;
  tie.gsd_m = g;
  const double q2 = config_.tile_continuity_sigma_m * config_.tile_continuity_sigma_m;
  const auto grid = tieGrid(m.last_size);
  const int n = static_cast<int>(grid.size());
  Eigen::MatrixXd j(2 * n, 4);
  tie.points_utm.clear();
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector2d l = applyHomography(local_from_px, grid[i]);
    tie.points_utm.push_back(m.ref_en_m + fit.apply(l));
    const Eigen::Vector2d d = l - fit.centre_m;
    j.block<2, 4>(2 * i, 0) << d.x(), -d.y(), 1, 0, d.y(), d.x(), 0, 1;
  }
  tie.error_cov = j * fit.cov * j.transpose() + q2 * Eigen::MatrixXd::Identity(2 * n, 2 * n);
  tie.valid = true;
  ++s.stats.mosaics_closed;
  return out;
}

}  // namespace compose
}  // namespace exocet_mosaic
