#include "exocet_mosaic/sim/image_motion_truth.h"

#include <cmath>

#include <Eigen/Dense>

#include "exocet_mosaic/sim/dive_synthesizer.h"

namespace exocet_mosaic {
namespace sim {
namespace {

// K [r1 r2 t]: maps a point (X, Y) of the plane z = 0 to the camera's homogeneous pixel.
Eigen::Matrix3d planeToImage(const exocet_common::CameraModel& camera, const Eigen::Isometry3d& local_from_camera) {
  const Eigen::Isometry3d camera_from_local = local_from_camera.inverse();
  Eigen::Matrix3d m;
  m.col(0) = camera_from_local.linear().col(0);
  m.col(1) = camera_from_local.linear().col(1);
  m.col(2) = camera_from_local.translation();
  Eigen::Matrix3d k;
  k << camera.fx, 0.0, camera.cx, 0.0, camera.fy, camera.cy, 0.0, 0.0, 1.0;
  return k * m;
}

}  // namespace

Eigen::Matrix3d seabedPlaneHomography(const exocet_common::CameraModel& camera, const Eigen::Isometry3d& local_from_a,
                                      const Eigen::Isometry3d& local_from_b) {
  Eigen::Matrix3d h = planeToImage(camera, local_from_b) * planeToImage(camera, local_from_a).inverse();
  return h / h(2, 2);
}

bool transferThroughSeabed(const exocet_common::CameraModel& camera, const Eigen::Isometry3d& local_from_a,
                           const Eigen::Isometry3d& local_from_b, const SeabedRelief& relief,
                           const Eigen::Vector2d& pixel_a, Eigen::Vector2d* pixel_b) {
  const Eigen::Vector2d xy =
      camera.undistortNormalized(Eigen::Vector2d((pixel_a.x() - camera.cx) / camera.fx, (pixel_a.y() - camera.cy) / camera.fy));
  const Eigen::Vector3d direction = local_from_a.linear() * Eigen::Vector3d(xy.x(), xy.y(), 1.0).normalized();
  const double range_m = rayToSeabed_m(local_from_a.translation(), direction, relief);
  if (!std::isfinite(range_m)) return false;
  const Eigen::Vector3d seabed_point = local_from_a.translation() + range_m * direction;
  return camera.project(local_from_b.inverse() * seabed_point, pixel_b);
}

}  // namespace sim
}  // namespace exocet_mosaic
