/**
 * @file dive_synthesizer.h
 * @brief Runs a simulated dive: the vehicle's trajectory, its navigation sensors and the downward camera's images,
 * with ground truth, delivered in time order to a sink (a bag writer, a test, a benchmark). No ROS in it.
 */
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "exocet_common/camera_model.h"
#include "exocet_mosaic/dive/dive_records.h"
#include "exocet_mosaic/sim/imaging_config.h"
#include "exocet_mosaic/sim/navigation_sensors.h"
#include "exocet_mosaic/sim/seabed_renderer.h"
#include "exocet_mosaic/sim/seabed_texture.h"
#include "exocet_mosaic/sim/vehicle_trajectory.h"

namespace exocet_mosaic {
namespace sim {

/// The downward camera and how it sits on the vehicle.
struct CameraRig {
  exocet_common::CameraModel camera = exocet_common::CameraModel::pal();
  double fps = 25.0;
  std::string encoding = "bgr8";
  /// Camera optical centre in base_link (metres): forward, left, up.
  Eigen::Vector3d lever_arm_m = Eigen::Vector3d(0.3, 0.0, -0.2);
  /// Deviation of the camera from looking straight down, as roll, pitch, yaw about its own axes (degrees).
  Eigen::Vector3d mounting_rpy_deg = Eigen::Vector3d::Zero();
  double drop_probability = 0.0;  ///< probability that a frame is lost (a gap in the image stream)

  /// base_link -> camera_optical: z down the optical axis, image x to starboard, image up = forward.
  Eigen::Isometry3d baseFromCamera() const;
  std::string validate() const;
};

/// Everything that defines a simulated dive except the seabed (given as texture and relief objects).
struct DiveSynthesisConfig {
  uint64_t seed = 1;
  double start_time_unix_s = 1780300800.0;  ///< 2026-06-01T08:00:00Z
  double duration_s = 0.0;                  ///< 0: the whole trajectory
  double seabed_depth_m = 60.0;             ///< depth of the reference seabed plane
  exocet_common::GeoReference geo;                         ///< from the origin's latitude/longitude
  TrajectoryConfig trajectory;
  NavigationSensorConfig navigation;
  ImagingConfig imaging;
  CameraRig rig;
  double ground_truth_rate_hz = 50.0;
  std::vector<Landmark> landmarks;
  /// Frames rendered at once, each on its own thread (1: in the calling thread). The result does not depend on it.
  int threads = 1;

  std::string validate() const;
};

/// One rendered frame with its ground truth.
struct FrameTruth {
  dive::CameraFrame frame;
  bool dropped = false;                     ///< the frame was lost: `frame.image` is empty
  VehicleState vehicle;                     ///< local frame
  Eigen::Isometry3d world_from_camera;      ///< UTM frame (E, N, up)
  double camera_altitude_m = 0.0;           ///< distance along the optical axis to the seabed
  double ground_sample_distance_m = 0.0;    ///< camera_altitude_m / focal length
  Eigen::Vector2d latlon_deg = Eigen::Vector2d::Zero();  ///< camera centre
};

/**
 * @brief Where a dive goes. Everything but prepare_frame is called on the thread that runs the dive, in time order.
 */
struct DiveSink {
  NavigationSinks navigation;
  std::function<void(const dive::PoseRecord&)> ground_truth;   ///< base_link in UTM at ground_truth_rate_hz
  std::function<void(const FrameTruth&)> frame;
  std::function<void(int frames_done, int frames_total)> progress;
  /**
   * Optional work on each frame that is not dropped, right after it is rendered and before `frame` receives it,
   * e.g. compressing the image. With DiveSynthesisConfig::threads > 1 it runs on the rendering threads, for several
   * frames at once and out of order: it must touch nothing but the frame it is given.
   */
  std::function<void(FrameTruth*)> prepare_frame;
};

class DiveSynthesizer {
 public:
  /// Validates everything (throws std::invalid_argument naming the field); texture and relief outlive the object.
  DiveSynthesizer(const DiveSynthesisConfig& config, SeabedTexture* texture, SeabedRelief* relief);

  double duration_s() const { return duration_s_; }
  int frameCount() const;
  /**
   * @brief Runs the whole dive into the sink. With config.threads > 1 the frames are rendered ahead on that many
   * threads (at most 2 * threads frames held at once) and delivered in order: the sink sees the same calls with the
   * same records as with one thread. An exception from rendering or from the sink stops the dive and propagates.
   */
  void run(const DiveSink& sink);

  const VehicleTrajectory& trajectory() const { return trajectory_; }
  SeabedRenderer& renderer() { return renderer_; }
  /// Camera pose in the local frame at dive time t.
  Eigen::Isometry3d cameraPoseLocal(double t_s) const;
  /// Bounding box (local frame) of the image's footprint on the reference plane at dive time t.
  WorldRect footprintOnReferencePlane(double t_s) const;
  /// Local frame -> UTM frame.
  Eigen::Vector3d toWorld(const Eigen::Vector3d& local) const;

 private:
  /// Frame k's truth and image (none if dropped): a function of k alone, safe to call on several threads at once.
  FrameTruth renderFrame(int k, bool dropped, const DiveSink& sink) const;

  DiveSynthesisConfig config_;
  SeabedRelief* relief_;
  VehicleTrajectory trajectory_;
  SeabedRenderer renderer_;
  double duration_s_;
};

/// Distance from `origin` along `direction` (local frame) to the seabed (relief on the reference plane).
double rayToSeabed_m(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction, const SeabedRelief& relief);

/// Landmarks spread along a trajectory: `count` targets at regular times, alternately offset left and right.
std::vector<Landmark> landmarksAlongTrajectory(const VehicleTrajectory& trajectory, int count, double size_m,
                                               double lateral_offset_m);

}  // namespace sim
}  // namespace exocet_mosaic
