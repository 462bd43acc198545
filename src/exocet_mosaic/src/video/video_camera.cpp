#include "exocet_mosaic/video/video_camera.h"

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <sstream>
#include <stdexcept>

#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "exocet_mosaic/selfcal/self_calibration.h"

namespace exocet_mosaic {
namespace video {

exocet_common::CameraModel pinholeFromHfov(int width_px, int height_px, double hfov_deg) {
  exocet_common::CameraModel camera;
  camera.width = width_px;
  camera.height = height_px;
  camera.fx = camera.fy = 0.5 * width_px / std::tan(0.5 * hfov_deg * M_PI / 180.0);
  camera.cx = 0.5 * width_px;
  camera.cy = 0.5 * height_px;
  camera.distortion.fill(0.0);
  return camera;
}

CameraChoice selfCalibrateVideo(const std::string& video_path, int max_frames, double hfov_deg,
                                const std::atomic<bool>& stop) {
  cv::VideoCapture capture(video_path);
  if (!capture.isOpened()) throw std::runtime_error("cannot open the video " + video_path);
  selfcal::TrackerConfig tracking;
  // A key frame every ~2 s of a 5-25 frames/s survey video, at least 10 key frames over the frames read.
  const int container_frames = static_cast<int>(capture.get(cv::CAP_PROP_FRAME_COUNT));
  const int frames = container_frames > 0 ? std::min(max_frames, container_frames) : max_frames;
  tracking.step = std::clamp(frames / 12, 2, 10);
  selfcal::FeatureTrackBuilder tracks(tracking);
  cv::Mat frame, gray;
  int read = 0;
  while (read < max_frames && !stop && capture.read(frame) && !frame.empty()) {
    if (frame.channels() == 3)
      cv::cvtColor(frame, gray, cv::COLOR_BGR2GRAY);
    else
      gray = frame;
    tracks.addFrame(gray);
    ++read;
  }
  CameraChoice choice;
  const cv::Size size = tracks.imageSize().area() > 0
                            ? tracks.imageSize()
                            : cv::Size(int(capture.get(cv::CAP_PROP_FRAME_WIDTH)),
                                       int(capture.get(cv::CAP_PROP_FRAME_HEIGHT)));
  choice.camera = pinholeFromHfov(size.width, size.height, hfov_deg);
  choice.source = "hfov";
  choice.scale_approximate = true;
  choice.details["frames_read"] = read;
  choice.details["key_frames"] = tracks.keyFrameCount();
  std::ostringstream hfov_text;
  hfov_text << "a pinhole of " << hfov_deg << " deg horizontal field of view (fx = fy = " << std::fixed
            << std::setprecision(1) << choice.camera.fx << " px): the tiles' scale is approximate";
  if (stop) {
    choice.summary = "interrupted";
    return choice;
  }
  selfcal::SelfCalibrationConfig config;
  config.intrinsics.initial_hfov_deg = hfov_deg;
  config.planar_intrinsics.initial_hfov_deg = hfov_deg;
  config.allow_planar = true;
  try {
    if (tracks.keyFrameCount() < config.min_key_frames)
      throw selfcal::CalibrationImpossible(selfcal::CalibrationImpossible::Reason::kTooFewTracks,
                                           std::to_string(tracks.keyFrameCount()) + " key frames from " +
                                               std::to_string(read) + " frames, at least " +
                                               std::to_string(config.min_key_frames) + " needed");
    const selfcal::SelfCalibrationResult result = selfcal::selfCalibrate(tracks.keyFramePairs(), size, config);
    const selfcal::IntrinsicsEstimate& k = result.intrinsics;
    choice.camera.fx = k.value.alpha_u;
    choice.camera.fy = k.value.alpha_v;
    choice.camera.cx = k.value.u0;
    choice.camera.cy = k.value.v0;
    choice.source = "selfcal";
    choice.scale_approximate = false;
    std::ostringstream text;
    text << std::fixed << std::setprecision(1) << "self-calibrated from " << read << " frames ("
         << selfcal::toString(result.method) << (result.scene_planar ? ", flat seabed" : ", relief")
         << "): fx " << k.value.alpha_u << " +- " << k.sigma.alpha_u << " px, fy " << k.value.alpha_v << " +- "
         << k.sigma.alpha_v << " px, cx " << k.value.u0 << " +- " << k.sigma.u0 << " px, cy " << k.value.v0 << " +- "
         << k.sigma.v0 << " px (1-sigma; distortion not estimated)";
    choice.summary = text.str();
    choice.details["method"] = selfcal::toString(result.method);
    choice.details["scene_planar"] = result.scene_planar;
    choice.details["pairs_used"] = result.pairs_used;
    choice.details["sigma_px"] = {{"fx", k.sigma.alpha_u}, {"fy", k.sigma.alpha_v}, {"cx", k.sigma.u0},
                                  {"cy", k.sigma.v0}};
  } catch (const selfcal::CalibrationImpossible& e) {
    std::string why = e.what();
    std::replace(why.begin(), why.end(), '\n', ' ');
    choice.summary = "self-calibration refused (" + why + "); using " + hfov_text.str();
    choice.details["refused"] = why;
  }
  return choice;
}

}  // namespace video
}  // namespace exocet_mosaic
