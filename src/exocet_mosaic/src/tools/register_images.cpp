// register_images: registers two images and prints the motion as one JSON object, to check a pair by hand.
//   rosrun exocet_mosaic register_images [--method klt|rmr|auto] [--model similarity|affine|homography|translation]
//                                        A.png B.png
// Exit status: 0 registered, 3 the registration failed (the JSON says why), 2 bad arguments or unreadable images.
#include <cmath>
#include <iomanip>
#include <iostream>
#include <limits>
#include <sstream>
#include <string>

#include <opencv2/imgcodecs.hpp>

#include "exocet_mosaic/registration/gray_converter.h"
#include "exocet_mosaic/registration/registration_config.h"

namespace {

using namespace exocet_mosaic::registration;

const char kUsage[] =
    "usage: register_images [--method klt|rmr|auto] [--model similarity|affine|homography|translation] A B\n"
    "Prints one JSON object: matrix (2x3, or 3x3 for a homography: A's pixels to B's), homography (always 3x3),\n"
    "parameters and covariance (centred on centre_px), quality, failed, failure, failure_detail.\n"
    "Defaults: --method auto --model similarity.\n";

std::string number(double v) {
  if (!std::isfinite(v)) return "null";
  std::ostringstream s;
  s << std::setprecision(std::numeric_limits<double>::max_digits10) << v;
  return s.str();
}

std::string jsonString(const std::string& text) {
  std::string out = "\"";
  for (char c : text) {
    if (c == '"' || c == '\\') out += '\\';
    if (c == '\n') {
      out += "\\n";
      continue;
    }
    out += c;
  }
  return out + "\"";
}

std::string rows(const Eigen::MatrixXd& m, int row_count) {
  std::string out = "[";
  for (int r = 0; r < row_count; ++r) {
    out += r ? ", [" : "[";
    for (int c = 0; c < m.cols(); ++c) out += (c ? ", " : "") + number(m(r, c));
    out += "]";
  }
  return out + "]";
}

std::string vectorJson(const Eigen::VectorXd& v) {
  std::string out = "[";
  for (int i = 0; i < v.size(); ++i) out += (i ? ", " : "") + number(v[i]);
  return out + "]";
}

cv::Mat readGray(const std::string& path) {
  cv::Mat image = cv::imread(path, cv::IMREAD_UNCHANGED);
  if (image.empty()) throw std::invalid_argument("cannot read image '" + path + "'");
  GrayConverter converter;
  switch (image.type()) {
    case CV_8UC1:
      return image;
    case CV_8UC3:
      return converter.convert(image, "bgr8");
    case CV_8UC4:
      return converter.convert(image, "bgra8");
    case CV_16UC1:
      return converter.convert(image, "mono16");
    default:
      throw std::invalid_argument("image '" + path + "' has an unsupported pixel type (8-bit grey/BGR/BGRA or 16-bit grey)");
  }
}

}  // namespace

int main(int argc, char** argv) {
  RegistrationConfig config;
  std::vector<std::string> files;
  try {
    for (int i = 1; i < argc; ++i) {
      const std::string a = argv[i];
      if (a == "-h" || a == "--help") {
        std::cout << kUsage;
        return 0;
      }
      if ((a == "--method" || a == "--model") && i + 1 < argc) {
        if (a == "--method")
          config.method = registrationMethodFromString(argv[++i]);
        else
          config.model = motionModelFromString(argv[++i]);
      } else if (!a.empty() && a[0] == '-') {
        throw std::invalid_argument("unknown option '" + a + "'");
      } else {
        files.push_back(a);
      }
    }
    if (files.size() != 2) throw std::invalid_argument("two images are needed, got " + std::to_string(files.size()));
    const cv::Mat a = readGray(files[0]);
    const cv::Mat b = readGray(files[1]);
    if (a.size() != b.size())
      throw std::invalid_argument("the images differ in size: " + std::to_string(a.cols) + "x" +
                                  std::to_string(a.rows) + " and " + std::to_string(b.cols) + "x" +
                                  std::to_string(b.rows));
    std::unique_ptr<FrameRegistrar> registrar = makeRegistrar(config);
    const MotionEstimate e = registrar->registerPair(a, b);
    const Eigen::Matrix3d h = e.failed ? Eigen::Matrix3d::Identity() : Eigen::Matrix3d(e.pixel_matrix / e.pixel_matrix(2, 2));
    std::cout << "{\"matrix\": " << rows(h, e.model == MotionModel::kHomography ? 3 : 2)
              << ", \"homography\": " << rows(h, 3) << ", \"model\": " << jsonString(toString(e.model))
              << ", \"method\": " << jsonString(toString(e.method)) << ", \"centre_px\": ["
              << number(e.centre_px.x()) << ", " << number(e.centre_px.y()) << "], \"parameters\": "
              << (e.failed ? std::string("null") : vectorJson(e.parameters))
              << ", \"covariance\": "
              << (e.failed ? std::string("null") : rows(e.covariance, int(e.covariance.rows())))
              << ", \"quality\": {\"observations\": " << e.observations << ", \"inliers\": " << e.inliers
              << ", \"inlier_fraction\": " << number(e.inlier_fraction)
              << ", \"residual_scale\": " << number(e.residual_scale) << ", \"iterations\": " << e.iterations
              << ", \"elapsed_ms\": " << number(e.elapsed_ms) << "}, \"failed\": " << (e.failed ? "true" : "false")
              << ", \"failure\": " << jsonString(toString(e.failure))
              << ", \"failure_detail\": " << jsonString(e.failure_detail) << "}\n";
    return e.failed ? 3 : 0;
  } catch (const std::invalid_argument& e) {
    std::cerr << "register_images: " << e.what() << "\n" << kUsage;
    return 2;
  }
}
