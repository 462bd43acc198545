#include "exocet_mosaic/fusion/image_heading.h"

#include <cmath>

namespace exocet_mosaic {
namespace fusion {

double yawChangeFromImageMotion_rad(const Eigen::Matrix3d& pixel_matrix, const Eigen::Matrix3d& camera_matrix,
                                    const Eigen::Isometry3d& base_from_camera) {
  const Eigen::Matrix3d normalized = camera_matrix.inverse() * pixel_matrix * camera_matrix;
  // The rotation of the image content about the optical axis; a vehicle yaw of +psi turns a downward camera by
  // -psi about its own axis, and the content by the opposite of the camera's turn.
  const double content_rotation_rad = std::atan2(normalized(1, 0) - normalized(0, 1), normalized(0, 0) + normalized(1, 1));
  const double optical_axis_up = (base_from_camera.linear().col(2)).z();  // -1 for a camera looking straight down
  return -optical_axis_up * content_rotation_rad;
}

}  // namespace fusion
}  // namespace exocet_mosaic
