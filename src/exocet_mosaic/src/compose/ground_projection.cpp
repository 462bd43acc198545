#include "exocet_mosaic/compose/ground_projection.h"

#include <cmath>

#include <Eigen/Dense>

namespace exocet_mosaic {
namespace compose {
namespace {

Eigen::Matrix3d toEigen(const cv::Matx33d& m) {
  Eigen::Matrix3d e;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) e(r, c) = m(r, c);
  return e;
}

cv::Matx33d toCv(const Eigen::Matrix3d& e) {
  cv::Matx33d m;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) m(r, c) = e(r, c);
  return m;
}

}  // namespace

bool groundFromPixel(const CameraGroundPose& pose, const cv::Size& image_size, const Eigen::Vector2d& origin_en_m,
                     cv::Matx33d* ground_from_px) {
  if (!(pose.camera_height_m > 0.0) || image_size.width <= 0 || image_size.height <= 0) return false;
  const Eigen::Matrix3d k = toEigen(pose.camera_matrix);
  if (std::abs(k.determinant()) < 1e-12) return false;
  const Eigen::Matrix3d r = pose.world_from_camera.normalized().toRotationMatrix();
  // Ray of pixel p in the world: d = R K^-1 p. It meets the plane z = camera_z - h at t = h / (-d_z), so
  // ground - camera = h * d_xy / (-d_z): homogeneous (h * d_x + c_x * (-d_z), h * d_y + c_y * (-d_z), -d_z).
  const Eigen::Matrix3d m = r * k.inverse();
  const Eigen::Vector2d c = pose.camera_en_m - origin_en_m;
  const double h = pose.camera_height_m;
  Eigen::Matrix3d g;
  g.row(0) = h * m.row(0) - c.x() * m.row(2);
  g.row(1) = h * m.row(1) - c.y() * m.row(2);
  g.row(2) = -m.row(2);
  // Every image corner must look below the horizon (the plane in front of the camera).
  const double w = image_size.width, hh = image_size.height;
  const Eigen::Vector3d corners[4] = {{-0.5, -0.5, 1}, {w - 0.5, -0.5, 1}, {w - 0.5, hh - 0.5, 1}, {-0.5, hh - 0.5, 1}};
  for (const auto& p : corners) {
    const Eigen::Vector3d d = m * p;
    if (-d.z() <= 1e-6 * d.norm()) return false;
  }
  *ground_from_px = toCv(g);
  return true;
}

bool pixelFromGround(const CameraGroundPose& pose, const cv::Size& image_size, const Eigen::Vector2d& origin_en_m,
                     cv::Matx33d* px_from_ground) {
  cv::Matx33d g;
  if (!groundFromPixel(pose, image_size, origin_en_m, &g)) return false;
  *px_from_ground = normalizeHomography(g.inv());
  return true;
}

Eigen::Vector2d applyHomography(const cv::Matx33d& h, const Eigen::Vector2d& p) {
  const double x = h(0, 0) * p.x() + h(0, 1) * p.y() + h(0, 2);
  const double y = h(1, 0) * p.x() + h(1, 1) * p.y() + h(1, 2);
  const double z = h(2, 0) * p.x() + h(2, 1) * p.y() + h(2, 2);
  return Eigen::Vector2d(x / z, y / z);
}

double imageXDirectionRad(const cv::Matx33d& ground_from_px, const Eigen::Vector2d& at_px) {
  const Eigen::Vector2d d = applyHomography(ground_from_px, at_px + Eigen::Vector2d(0.5, 0.0)) -
                            applyHomography(ground_from_px, at_px - Eigen::Vector2d(0.5, 0.0));
  return std::atan2(d.y(), d.x());
}

cv::Matx33d normalizeHomography(const cv::Matx33d& h) {
  const double s = h(2, 2);
  if (std::abs(s) < 1e-300) return h;
  return h * (1.0 / s);
}

double nativeGsd(const CameraGroundPose& pose) {
  const double f = std::sqrt(std::abs(pose.camera_matrix(0, 0) * pose.camera_matrix(1, 1)));
  return f > 0 ? pose.camera_height_m / f : 0.0;
}

double roundGsdDown(double gsd_m) {
  if (!(gsd_m > 0) || !std::isfinite(gsd_m)) return 0.0;
  // ISO 3 preferred numbers (R'10): steps of about 25 %, so the tile keeps at least 80 % of the camera's resolution
  // (1-2-5 could drop 60 % of it, and cost the composer up to 6 times the pixels).
  static constexpr double kSeries[] = {1.0, 1.25, 1.6, 2.0, 2.5, 3.2, 4.0, 5.0, 6.3, 8.0};
  const double decade = std::pow(10.0, std::floor(std::log10(gsd_m) + 1e-12));
  const double mantissa = gsd_m / decade;  // in [1, 10)
  double step = 1.0;
  for (double v : kSeries)
    if (mantissa >= v - 1e-9) step = v;
  return step * decade;
}

}  // namespace compose
}  // namespace exocet_mosaic
