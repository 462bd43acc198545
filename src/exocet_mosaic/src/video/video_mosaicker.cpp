#include "exocet_mosaic/video/video_mosaicker.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include <Eigen/Eigenvalues>
#include <opencv2/imgproc.hpp>

#include "exocet_mosaic/registration/gray_converter.h"
#include "exocet_mosaic/tiles/closed_mosaic_tile.h"

namespace exocet_mosaic {
namespace video {

namespace {

/// Largest 1-sigma of a 2x2 covariance.
double largestSigma_m(const Eigen::Matrix2d& covariance_m2) {
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eigen(covariance_m2);
  return std::sqrt(std::max(0.0, eigen.eigenvalues().maxCoeff()));
}

constexpr char kCameraFrame[] = "camera";
constexpr char kAltimeterFrame[] = "altimeter";

}  // namespace

Eigen::Isometry3d downwardCameraMount() {
  // Columns: the optical frame's axes in base_link (x forward, y left, z up): image x to starboard, image y (down the
  // image) backwards, optical axis down.
  Eigen::Matrix3d r;
  r << 0, -1, 0,  //
      -1, 0, 0,   //
      0, 0, -1;
  Eigen::Isometry3d mount = Eigen::Isometry3d::Identity();
  mount.linear() = r;
  return mount;
}

std::string VideoMosaickerConfig::validate() const {
  std::ostringstream e;
  const std::string camera_error = camera.validate();
  if (!camera_error.empty()) e << "camera: " << camera_error << "; ";
  if (!(camera_height_m > 0.0 && camera_height_m <= 1000.0))
    e << "camera_height_m " << camera_height_m << " outside (0, 1000] m; ";
  if (!(start_sigma_m > 0.0 && start_sigma_m <= 10000.0)) e << "start_sigma_m outside (0, 10000] m; ";
  if (start_en_m && !start_en_m->allFinite()) e << "start_en_m not finite; ";
  if (!std::isfinite(start_enu_yaw_rad)) e << "start_enu_yaw_rad not finite; ";
  if (local_frame.empty() && (utm_zone < 0 || utm_zone > 60)) e << "utm_zone " << utm_zone << " outside [0, 60]; ";
  if (!(dead_reckoning_sigma_m > 0.0 && dead_reckoning_sigma_m <= 1000.0))
    e << "dead_reckoning_sigma_m outside (0, 1000] m; ";
  if (overview_max_side_px < 16 || overview_max_side_px > 20000) e << "overview_max_side_px outside [16, 20000]; ";
  if (tiles.files.output_dir.empty()) e << "tiles.files.output_dir is empty; ";
  std::string text = e.str();
  if (text.size() >= 2) text.resize(text.size() - 2);
  return text;
}

VideoMosaicker::VideoMosaicker(const VideoMosaickerConfig& config) : config_(config) {
  const std::string error = config_.validate();
  if (!error.empty()) throw std::invalid_argument("video mosaicker: " + error);

  registrar_ = std::make_unique<registration::SequenceRegistrar>(
      registration::makeRegistrar(config_.registration.registration), config_.registration.sequence);
  registration::CameraCalibration calibration;
  calibration.size = cv::Size(config_.camera.width, config_.camera.height);
  const cv::Matx33d k = config_.camera.K();
  for (int i = 0; i < 9; ++i) calibration.k[i] = k.val[i];
  for (int i = 0; i < 5; ++i) calibration.d[i] = config_.camera.distortion[i];
  calibration.distortion_model = "plumb_bob";
  registrar_->setCalibration(calibration);

  fusion::FusionFrontEndConfig fusion_config;
  fusion_config.keep_log = false;  // no smoothing here: the filtered track is the output
  fusion_config.default_camera_frame = kCameraFrame;
  const Eigen::Isometry3d mount = config_.base_from_camera;
  fusion_ = std::make_unique<fusion::FusionFrontEnd>(
      fusion_config, [mount](const std::string& frame) -> std::optional<Eigen::Isometry3d> {
        if (frame == kCameraFrame) return mount;
        if (frame == kAltimeterFrame) return Eigen::Isometry3d::Identity();  // the navigation's altitude: base_link
        return std::nullopt;
      });
  Eigen::Matrix3d k_eigen;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) k_eigen(r, c) = k(r, c);
  fusion_->setCameraMatrix(k_eigen);
  fusion_->setOperatorHeading(config_.start_enu_yaw_rad);
  fusion_->setOperatorHeight(config_.camera_height_m);

  composer_ = std::make_unique<compose::MosaicComposer>(config_.tiles.composer);
  writer_ = std::make_unique<tiles::GeoTiffTileWriter>(config_.tiles.files);
  writer_->removeStaleTemporaries();
}

VideoMosaicker::~VideoMosaicker() = default;

void VideoMosaicker::setNavigation(const std::vector<dive::NavigationRow>& rows, bool has_orientation) {
  navigation_ = rows;
  navigation_has_orientation_ = has_orientation;
  next_navigation_ = 0;
}

void VideoMosaicker::feedNavigationUpTo(double stamp_s) {
  const Eigen::Matrix2d covariance = Eigen::Matrix2d::Identity() * std::pow(config_.dead_reckoning_sigma_m, 2);
  while (next_navigation_ < navigation_.size() && navigation_[next_navigation_].pose.stamp_s <= stamp_s) {
    const dive::NavigationRow& row = navigation_[next_navigation_++];
    const double t = row.pose.stamp_s;
    if (navigation_has_orientation_) fusion_->addNavigationAttitude(t, row.pose.orientation.normalized());
    if (row.depth) fusion_->addDepth(row.depth->stamp_s, row.depth->depth_m);
    if (row.altitude) fusion_->addAltimeterRange(row.altitude->stamp_s, row.altitude->range_m, kAltimeterFrame);
    fusion_->addDeadReckoning(t, row.pose.position_m, covariance);
  }
}

std::optional<Eigen::Quaterniond> VideoMosaicker::vehicleAttitudeAt(double stamp_s) const {
  if (auto q = fusion_->attitudeAt(stamp_s)) return q;
  if (const auto& yaw = fusion_->operatorHeading())
    return Eigen::Quaterniond(Eigen::AngleAxisd(*yaw, Eigen::Vector3d::UnitZ()));
  return std::nullopt;
}

FramePlacement VideoMosaicker::addFrame(const cv::Mat& image, double stamp_s) {
  const cv::Size size(config_.camera.width, config_.camera.height);
  if (image.empty() || image.size() != size || (image.type() != CV_8UC3 && image.type() != CV_8UC1)) {
    std::ostringstream why;
    why << "frame " << track_.size() << ": " << image.cols << "x" << image.rows << " (type " << image.type()
        << "), expected an 8-bit grey or BGR image of the camera's size " << size.width << "x" << size.height;
    throw std::invalid_argument(why.str());
  }
  if (!(std::isfinite(stamp_s) && stamp_s > 0.0))
    throw std::invalid_argument("frame " + std::to_string(track_.size()) + ": stamp must be finite and positive");
  FramePlacement placement;
  placement.frame = static_cast<int>(track_.size());
  placement.stamp_s = stamp_s;

  registration::GrayConverter converter;
  const cv::Mat gray = converter.convert(image, image.channels() == 3 ? "bgr8" : "mono8");
  feedNavigationUpTo(stamp_s);
  // Without navigation the operator's first point starts the filter at the first frame, so that it is placed too.
  if (!fusion_->filter().initialized() && navigation_.empty()) {
    const Eigen::Vector2d start = config_.start_en_m.value_or(Eigen::Vector2d::Zero());
    fusion_->initialize(stamp_s, start, Eigen::Matrix2d::Identity() * std::pow(config_.start_sigma_m, 2));
  }

  const registration::SequenceStep step = registrar_->add(gray, stamp_s);
  if (step.has_motion) {
    const registration::MotionEstimate& m = step.motion;
    fusion::ImageMotionInput input;
    input.previous_stamp_s = step.previous_stamp_s;
    input.stamp_s = stamp_s;
    input.failed = m.failed;
    input.model = registration::toString(m.model);
    input.parameters = m.parameters;
    input.covariance = m.covariance;
    input.centre_px = m.centre_px;
    input.pixel_matrix = m.failed ? Eigen::Matrix3d::Identity() : m.pixel_matrix;
    input.camera_matrix = step.camera_matrix;
    fusion_->addImageMotion(input);
    if (!m.failed) {
      ++frames_registered_;
      placement.registered = true;
    }
  }

  compose::ComposerFrame frame;
  frame.index = placement.frame;
  frame.stamp_s = stamp_s;
  frame.image = step.undistorted && registrar_->undistorter().active() ? registrar_->undistorter().apply(image) : image;
  if (step.has_motion && !step.motion.failed && last_composed_stamp_s_ &&
      step.previous_stamp_s == *last_composed_stamp_s_) {
    cv::Matx33d h;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) h(r, c) = step.motion.pixel_matrix(r, c);
    frame.current_from_previous_px = h;
  }
  if (fusion_->filter().initialized()) {
    const fusion::FilterState state = fusion_->filter().predictedAt(stamp_s);
    placement.camera_en_m = state.position_en_m;
    placement.sigma_m = largestSigma_m(state.position_covariance_m2);
    const auto attitude = vehicleAttitudeAt(stamp_s);
    if (attitude) {
      if (const auto height_m = fusion_->cameraHeightAt(stamp_s, *attitude, config_.base_from_camera)) {
        compose::CameraGroundPose pose;
        pose.camera_en_m = state.position_en_m;
        pose.position_cov_m2 = state.position_covariance_m2;
        pose.world_from_camera = (*attitude * Eigen::Quaterniond(config_.base_from_camera.linear())).normalized();
        pose.camera_height_m = *height_m;
        const Eigen::Matrix3d k =
            step.camera_matrix ? *step.camera_matrix
                               : Eigen::Matrix3d(Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(
                                     config_.camera.K().val));
        for (int r = 0; r < 3; ++r)
          for (int c = 0; c < 3; ++c) pose.camera_matrix(r, c) = k(r, c);
        frame.pose = pose;
      }
    }
  }

  const compose::ComposerStats before = composer_->stats();
  std::optional<compose::ClosedMosaic> closed = composer_->add(frame);
  const compose::ComposerStats after = composer_->stats();
  last_composed_stamp_s_ = stamp_s;
  placement.placed = frame.pose.has_value() && after.frames_skipped_no_pose == before.frames_skipped_no_pose &&
                     after.frames_skipped_no_chain == before.frames_skipped_no_chain;
  if (placement.placed) ++frames_placed_;
  if (closed) writeTile(std::move(*closed));
  if (frame.pose) tile_fused_sigmas_m_.push_back(placement.sigma_m);
  track_.push_back(placement);
  return placement;
}

void VideoMosaicker::finish(const std::string& reason) {
  if (finished_) return;
  finished_ = true;
  if (auto closed = composer_->flush(reason)) writeTile(std::move(*closed));
}

void VideoMosaicker::writeTile(compose::ClosedMosaic mosaic) {
  // As tile_writer_node: the fit averages the navigation as if its errors were independent; the filter's are
  // correlated over many images, so the tile's position is no better than the median fused 1-sigma.
  if (!tile_fused_sigmas_m_.empty()) {
    std::nth_element(tile_fused_sigmas_m_.begin(), tile_fused_sigmas_m_.begin() + tile_fused_sigmas_m_.size() / 2,
                     tile_fused_sigmas_m_.end());
    mosaic.anchor_sigma_m = std::max(mosaic.anchor_sigma_m, tile_fused_sigmas_m_[tile_fused_sigmas_m_.size() / 2]);
  }
  tile_fused_sigmas_m_.clear();
  const tiles::TileRaster raster =
      tiles::tileRaster(mosaic, config_.utm_zone, config_.northern_hemisphere, config_.local_frame);
  tiles::TileMetadata metadata = tiles::tileMetadata(mosaic, config_.dive_name);
  metadata.extra["scale_approximate"] = config_.scale_approximate ? "true" : "false";
  if (config_.scale_approximate)
    metadata.extra["scale_note"] =
        "focal length guessed from a field of view (no calibration, self-calibration refused): the scale is "
        "approximate";
  const tiles::WrittenTile tile = writer_->write(raster, metadata);
  if (!tile.ok) {
    write_errors_.push_back(tile.error);
    return;
  }
  written_.push_back(tile);
  if (!mosaic.image.empty()) {
    MosaicThumbnail thumbnail;
    const double scale =
        std::min(1.0, double(config_.overview_max_side_px) / std::max(mosaic.image.cols, mosaic.image.rows));
    if (scale < 1.0) {
      cv::resize(mosaic.image, thumbnail.image, cv::Size(), scale, scale, cv::INTER_AREA);
      if (!mosaic.mask.empty())
        cv::resize(mosaic.mask, thumbnail.mask, thumbnail.image.size(), 0, 0, cv::INTER_NEAREST);
    } else {
      thumbnail.image = mosaic.image.clone();
      thumbnail.mask = mosaic.mask.clone();
    }
    if (thumbnail.mask.empty()) thumbnail.mask = cv::Mat(thumbnail.image.size(), CV_8UC1, cv::Scalar(255));
    thumbnail.origin_easting_m = mosaic.origin_easting_m;
    thumbnail.origin_northing_m = mosaic.origin_northing_m;
    thumbnail.gsd_m = mosaic.gsd_m * mosaic.image.cols / double(thumbnail.image.cols);
    thumbnails_.push_back(std::move(thumbnail));
  }
}

}  // namespace video
}  // namespace exocet_mosaic
