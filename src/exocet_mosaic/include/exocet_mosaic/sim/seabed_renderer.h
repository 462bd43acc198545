/**
 * @file seabed_renderer.h
 * @brief Renders what a downward camera sees of the seabed: exact per-pixel ray casting on the relief, distortion,
 * anti-aliased texture sampling (trilinear over the texture's levels), underwater image formation and noise.
 */
#pragma once

#include <functional>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "exocet_common/camera_model.h"
#include "exocet_mosaic/sim/imaging_config.h"
#include "exocet_mosaic/sim/seabed_texture.h"

namespace exocet_mosaic {
namespace sim {

/**
 * @brief A surveyed target on the seabed: a square with a 2x2 checker whose centre is a saddle point that detectors
 * locate to a fraction of a pixel. Its centre is the known position used to check geometry and geo-referencing.
 */
struct Landmark {
  int id = 0;
  double x_m = 0.0, y_m = 0.0;  ///< local frame; the centre lies on the relief at heightAt_m(x, y)
  double size_m = 0.3;          ///< side of the square
};

/**
 * @brief Renders frames of the seabed. Every frame is a function of its pose, time and index alone (noise and
 * marine snow come from streams seeded by the frame and the place, not drawn in sequence), and the renderer keeps no
 * state between frames: several threads may render different frames at once, provided the texture and relief
 * allow concurrent calls (the procedural ones and ImageSeabed do).
 */
class SeabedRenderer {
 public:
  /**
   * @param reference_altitude_m nominal altitude: the lamp and attenuation are normalised there (a seabed of
   *        albedo a seen at that altitude in clear water appears with value ~ a in the green channel).
   */
  SeabedRenderer(const exocet_common::CameraModel& camera, const ImagingConfig& imaging, SeabedTexture* texture,
                 SeabedRelief* relief, std::vector<Landmark> landmarks, uint64_t seed, double reference_altitude_m);

  /**
   * @brief Linear RGB radiance (CV_32FC3) seen from `world_from_camera` (local frame; camera optical frame: z along
   * the optical axis, x right, y down) at dive time t (for the water segments and marine snow). Optionally the
   * depth of each pixel along the optical axis (CV_32F, metres). Throws std::runtime_error if a pixel's ray does
   * not reach the seabed (camera looking at the horizon).
   */
  cv::Mat renderRadiance(const Eigen::Isometry3d& world_from_camera, double t_s, int frame_index,
                         cv::Mat* depth_z_m = nullptr) const;

  /**
   * @brief The camera's image at dive time t: motion blur over the exposure (poses from `pose_at`), camera response,
   * noise and quantisation, in `encoding` (bgr8, rgb8, mono8, mono16, bayer_rggb8).
   */
  cv::Mat render(const std::function<Eigen::Isometry3d(double)>& pose_at, double t_s, int frame_index,
                 const std::string& encoding) const;

  /// Converts linear radiance to the camera's encoded output with noise (deterministic in seed and frame).
  cv::Mat encode(const cv::Mat& radiance_rgb, int frame_index, const std::string& encoding) const;

  const exocet_common::CameraModel& camera() const { return camera_; }
  const std::vector<Landmark>& landmarks() const { return landmarks_; }

  static bool isSupportedEncoding(const std::string& encoding);

 private:
  void addMarineSnow(const Eigen::Isometry3d& world_from_camera, double t_s, const cv::Mat& depth_z_m,
                     cv::Mat* radiance) const;

  exocet_common::CameraModel camera_;
  ImagingConfig imaging_;
  SeabedTexture* texture_;
  SeabedRelief* relief_;
  std::vector<Landmark> landmarks_;
  uint64_t seed_;
  double reference_altitude_m_;
  cv::Mat rays_;          ///< per-pixel normalised ray (x, y), CV_32FC2
  cv::Mat vignette_;      ///< per-pixel vignetting factor, CV_32F
  cv::Mat pixel_angle_;   ///< per-pixel angular size (rad), CV_32F
  std::vector<float> gaussian_table_;  ///< N(0, 1) samples for fast sensor noise
};

}  // namespace sim
}  // namespace exocet_mosaic
