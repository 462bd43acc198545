#include "exocet_common/camera_model.h"

#include <cmath>
#include <fstream>
#include <iomanip>
#include <sstream>
#include <stdexcept>

#include <yaml-cpp/yaml.h>
#include <Eigen/LU>

#include "exocet_common/atomic_file.h"

namespace exocet_common {

namespace {
CameraModel centred(int width, int height, double hfov_deg) {
  CameraModel c;
  c.width = width;
  c.height = height;
  c.fx = c.fy = 0.5 * width / std::tan(0.5 * hfov_deg * M_PI / 180.0);
  c.cx = 0.5 * (width - 1);
  c.cy = 0.5 * (height - 1);
  return c;
}
}  // namespace

CameraModel CameraModel::pal(double hfov_deg) { return centred(720, 576, hfov_deg); }
CameraModel CameraModel::hd(double hfov_deg) { return centred(1920, 1080, hfov_deg); }
CameraModel CameraModel::uhd(double hfov_deg) { return centred(3840, 2160, hfov_deg); }

bool CameraModel::hasDistortion() const {
  for (double d : distortion)
    if (d != 0.0) return true;
  return false;
}

Eigen::Vector2d CameraModel::distortNormalized(const Eigen::Vector2d& xy) const {
  const double x = xy.x(), y = xy.y();
  const double k1 = distortion[0], k2 = distortion[1], p1 = distortion[2], p2 = distortion[3], k3 = distortion[4];
  const double r2 = x * x + y * y;
  const double radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
  return {x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
          y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y};
}

Eigen::Vector2d CameraModel::undistortNormalized(const Eigen::Vector2d& xy_distorted) const {
  if (!hasDistortion()) return xy_distorted;
  Eigen::Vector2d xy = xy_distorted;
  // Newton's method on f(xy) = distort(xy) - target with a numerical Jacobian: quadratic convergence.
  for (int it = 0; it < 30; ++it) {
    const Eigen::Vector2d f = distortNormalized(xy) - xy_distorted;
    if (f.squaredNorm() < 1e-26) break;
    const double h = 1e-7;
    Eigen::Matrix2d J;
    J.col(0) =
        (distortNormalized(xy + Eigen::Vector2d(h, 0)) - distortNormalized(xy - Eigen::Vector2d(h, 0))) / (2 * h);
    J.col(1) =
        (distortNormalized(xy + Eigen::Vector2d(0, h)) - distortNormalized(xy - Eigen::Vector2d(0, h))) / (2 * h);
    xy -= J.inverse() * f;
  }
  return xy;
}

bool CameraModel::project(const Eigen::Vector3d& p_cam, Eigen::Vector2d* pixel) const {
  if (p_cam.z() <= 0.0) return false;
  const Eigen::Vector2d d = distortNormalized(Eigen::Vector2d(p_cam.x() / p_cam.z(), p_cam.y() / p_cam.z()));
  *pixel = Eigen::Vector2d(fx * d.x() + cx, fy * d.y() + cy);
  return true;
}

cv::Mat CameraModel::rayMap() const {
  cv::Mat rays(height, width, CV_32FC2);
  for (int v = 0; v < height; ++v) {
    auto* row = rays.ptr<cv::Vec2f>(v);
    for (int u = 0; u < width; ++u) {
      const Eigen::Vector2d xy = undistortNormalized(Eigen::Vector2d((u - cx) / fx, (v - cy) / fy));
      row[u] = cv::Vec2f(static_cast<float>(xy.x()), static_cast<float>(xy.y()));
    }
  }
  return rays;
}

std::string CameraModel::validate() const {
  std::ostringstream err;
  if (width < 16 || width > 16384) err << "camera width " << width << " out of range [16, 16384] pixels; ";
  if (height < 16 || height > 16384) err << "camera height " << height << " out of range [16, 16384] pixels; ";
  if (!(fx > 0.0) || !(fy > 0.0) || !std::isfinite(fx) || !std::isfinite(fy))
    err << "camera focal lengths fx=" << fx << ", fy=" << fy << " must be finite and > 0 pixels; ";
  if (!(cx >= 0.0 && cx <= width) || !(cy >= 0.0 && cy <= height))
    err << "camera principal point (" << cx << ", " << cy << ") must lie inside the image [0, " << width << "] x [0, "
        << height << "]; ";
  for (double d : distortion)
    if (!std::isfinite(d) || std::abs(d) > 10.0) {
      err << "camera distortion coefficients must be finite and within [-10, 10]; ";
      break;
    }
  std::string s = err.str();
  if (!s.empty()) s.resize(s.size() - 2);
  return s;
}

namespace {
std::vector<double> readNumbers(const YAML::Node& node, const std::string& path, const std::string& field) {
  YAML::Node list = node;
  if (node.IsMap()) list = node["data"];
  if (!list || !list.IsSequence()) throw std::runtime_error(path + ": field '" + field + "' must be a list of numbers");
  std::vector<double> v;
  for (const auto& x : list) v.push_back(x.as<double>());
  return v;
}
}  // namespace

CameraModel loadCameraModelYaml(const std::string& path) {
  YAML::Node root;
  try {
    root = YAML::LoadFile(path);
  } catch (const std::exception& e) {
    throw std::runtime_error("cannot read camera intrinsics '" + path + "': " + e.what());
  }
  CameraModel c;
  try {
    if (!root["image_width"] || !root["image_height"])
      throw std::runtime_error(path + ": fields 'image_width' and 'image_height' are required");
    c.width = root["image_width"].as<int>();
    c.height = root["image_height"].as<int>();
    const YAML::Node k_node = root["camera_matrix"] ? root["camera_matrix"] : root["K"];
    if (!k_node) throw std::runtime_error(path + ": field 'camera_matrix' (or 'K') is required");
    const std::vector<double> K = readNumbers(k_node, path, "camera_matrix");
    if (K.size() != 9) throw std::runtime_error(path + ": field 'camera_matrix' must hold 9 numbers");
    c.fx = K[0];
    c.cx = K[2];
    c.fy = K[4];
    c.cy = K[5];
    const YAML::Node d_node = root["distortion_coefficients"] ? root["distortion_coefficients"] : root["D"];
    if (d_node) {
      const std::vector<double> D = readNumbers(d_node, path, "distortion_coefficients");
      if (D.size() < 4 || D.size() > 5)
        throw std::runtime_error(path + ": field 'distortion_coefficients' must hold 4 or 5 numbers (plumb_bob)");
      for (size_t i = 0; i < D.size(); ++i) c.distortion[i] = D[i];
    }
    if (root["distortion_model"]) {
      const std::string model = root["distortion_model"].as<std::string>();
      if (model != "plumb_bob" && model != "rational_polynomial")
        throw std::runtime_error(path + ": distortion_model '" + model + "' is not supported (plumb_bob)");
    }
  } catch (const YAML::Exception& e) {
    throw std::runtime_error(path + ": malformed camera intrinsics: " + e.what());
  }
  const std::string problem = c.validate();
  if (!problem.empty()) throw std::runtime_error(path + ": " + problem);
  return c;
}

void saveCameraModelYaml(const std::string& path, const CameraModel& c, const std::string& camera_name) {
  std::ostringstream out;
  out << std::setprecision(17);
  out << "image_width: " << c.width << "\nimage_height: " << c.height << "\ncamera_name: " << camera_name << "\n";
  out << "camera_matrix:\n  rows: 3\n  cols: 3\n  data: [" << c.fx << ", 0, " << c.cx << ", 0, " << c.fy << ", " << c.cy
      << ", 0, 0, 1]\n";
  out << "distortion_model: plumb_bob\ndistortion_coefficients:\n  rows: 1\n  cols: 5\n  data: [";
  for (size_t i = 0; i < 5; ++i) out << (i ? ", " : "") << c.distortion[i];
  out << "]\nrectification_matrix:\n  rows: 3\n  cols: 3\n  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]\n";
  out << "projection_matrix:\n  rows: 3\n  cols: 4\n  data: [" << c.fx << ", 0, " << c.cx << ", 0, 0, " << c.fy << ", "
      << c.cy << ", 0, 0, 0, 1, 0]\n";
  exocet_common::writeFileAtomically(path, out.str());
}

}  // namespace exocet_common
