/**
 * @file vent_renderer.h
 * @brief Image-level scene for the servo simulation: a textured vent-like chimney (truncated cone with a flat top)
 * standing on a textured seabed plane, rendered by ray casting into an 8-bit gray image with its depth map. The
 * textures are procedural (multi-scale noise, blobs, cracks) so that SIFT and KLT find many features; they are
 * mip-mapped (level from the pixel footprint) and each pixel is supersampled, so that the far seabed does not alias
 * and features stay stable as the camera moves. Lambertian shading with a fixed light (view-independent: both
 * cameras see the same radiance) and underwater attenuation with distance. No ROS in it.
 *
 * World frame: z up (as point_scene.h); camera frame: x right, y down, z forward; depth = Z in the camera frame.
 */
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "exocet_servo/sim/point_scene.h"

namespace exocet_servo {
namespace sim {

/// The scene; validate() lists the allowed ranges.
struct VentSceneConfig {
  Eigen::Vector3d base_m = Eigen::Vector3d::Zero();  ///< centre of the chimney's base, on the seabed (world)
  double height_m = 0.3;                             ///< (0, 100]
  double base_radius_m = 0.1;                        ///< (0, 100]
  double top_radius_m = 0.05;                        ///< (0, 100]
  bool draw_seabed = true;                           ///< the plane z = base_m.z()
  double seabed_half_size_m = 3.0;                   ///< textured square around the base, (0, 1000]
  double chimney_texel_m = 0.001;                    ///< texel size of the chimney texture, [1e-5, 0.1]
  double seabed_texel_m = 0.0025;                    ///< [1e-5, 1]
  int supersampling = 2;                             ///< n x n rays per pixel, [1, 8]
  double attenuation_per_m = 0.35;                   ///< underwater light attenuation, [0, 100]
  double water_gray = 40.0;                          ///< radiance of the water (missed rays, far field), [0, 255]
  unsigned seed = 7;                                 ///< of the textures
  /// "" or every bad field with its allowed range ("; "-joined).
  std::string validate() const;
};

/**
 * @brief Exact distance (m) from a world point to the scene's drawn surfaces, rims included: in the half-plane
 * (distance from the axis, height above the base) the chimney is the polyline base rim -> top rim -> axis (side and
 * top cap), and the seabed (when drawn) is the plane outside the chimney's foot. The ground truth of the
 * reconstruction's accuracy figures.
 */
double distanceToScene(const VentSceneConfig& scene, const Eigen::Vector3d& point_w);

/// What a ray hit.
enum class SurfaceKind { kNone, kChimney, kTop, kSeabed };

/// One rendered view.
struct RenderedView {
  cv::Mat image;    ///< CV_8UC1
  cv::Mat depth_m;  ///< CV_32FC1, Z in the camera frame of the ray through each pixel centre; +inf where none hit

  /// Depth at a sub-pixel position, refused across discontinuities: vision::screenedDepthAt on depth_m.
  /// @return false outside the image, on the water, or across a discontinuity.
  bool smoothDepthAt(const Eigen::Vector2d& px, int radius_px, double max_relative_step, double* depth_m) const;
};

/// Ray caster of the scene.
class VentRenderer {
 public:
  /// Builds the textures (a few hundred ms). @throws std::invalid_argument with config.validate()'s message.
  explicit VentRenderer(const VentSceneConfig& config);

  /// Renders the camera's image (camera.width_px x camera.height_px) and depth map. Parallel over rows with
  /// cv::parallel_for_ (follows cv::setNumThreads).
  RenderedView render(const PinholeCamera& camera, const Eigen::Isometry3d& world_T_camera) const;

  /// Exact depth (Z in the camera frame, m) of the surface seen at a sub-pixel position; +inf when none is hit.
  double depthAt(const PinholeCamera& camera, const Eigen::Isometry3d& world_T_camera, const Eigen::Vector2d& px,
                 SurfaceKind* kind = nullptr) const;

  /// Exact distance (m) from a world point to the nearest drawn surface (0 on the surface), distanceToScene().
  double distanceToSurface(const Eigen::Vector3d& point_w) const;

  const VentSceneConfig& config() const { return config_; }

 private:
  struct Hit {
    double t = 0.0;  ///< ray parameter (the depth when the direction has camera z = 1)
    SurfaceKind kind = SurfaceKind::kNone;
  };
  Hit cast(const Eigen::Vector3d& origin_w, const Eigen::Vector3d& direction_w) const;
  /// Radiance of a hit (before attenuation); footprint_m is the size of the pixel on the surface.
  double shade(const Eigen::Vector3d& point_w, SurfaceKind kind, const Eigen::Vector3d& direction_w,
               double footprint_m) const;

  VentSceneConfig config_;
  std::vector<cv::Mat> chimney_mips_;  ///< CV_32FC1 albedo in [0, 1], u = azimuth, v = height; level 0 finest
  std::vector<cv::Mat> seabed_mips_;   ///< u = x, v = y over the seabed square
  Eigen::Vector3d light_w_;            ///< unit, towards the light
};

}  // namespace sim
}  // namespace exocet_servo
