// register_images: registers two images and prints the motion as one JSON object, to check a pair by hand.
//   rosrun exocet_mosaic register_images [--method klt|rmr|auto] [--model similarity|affine|homography|translation]
//                                        A.png B.png
// Exit status: 0 registered, 3 the registration failed (the JSON says why), 2 bad arguments or unreadable images.
#include <iostream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "exocet_mosaic/registration/gray_converter.h"
#include "exocet_mosaic/registration/registration_config.h"
#include "exocet_common/json_file.h"
#include "exocet_common/command_line.h"

namespace {

using namespace exocet_mosaic::registration;

const char kDescription[] =
    "register_images: registers image A to image B (same size; 8-bit grey/BGR/BGRA or 16-bit grey) and prints one\n"
    "JSON object: matrix (2x3, or 3x3 for a homography: A's pixels to B's), homography (always 3x3), parameters and\n"
    "covariance (centred on centre_px), quality, failed, failure, failure_detail.";

/// The rows of `m` up to `row_count`, as a JSON array of arrays; NaN as null.
nlohmann::ordered_json rows(const Eigen::MatrixXd& m, int row_count) {
  nlohmann::ordered_json out = nlohmann::ordered_json::array();
  for (int r = 0; r < row_count; ++r) {
    nlohmann::ordered_json row = nlohmann::ordered_json::array();
    for (int c = 0; c < m.cols(); ++c) row.push_back(m(r, c));
    out.push_back(row);
  }
  return out;
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
  std::string method = toString(RegistrationMethod::kAuto), model = toString(MotionModel::kSimilarity);
  std::vector<std::string> files;
  CLI::App app(kDescription, "register_images");
  app.add_option("--method", method, "registration method: KLT, RMR, or KLT falling back on RMR")
      ->check(CLI::IsMember({toString(RegistrationMethod::kKlt), toString(RegistrationMethod::kRmr),
                             toString(RegistrationMethod::kAuto)}))
      ->capture_default_str();
  app.add_option("--model", model, "motion model fitted")
      ->check(CLI::IsMember({toString(MotionModel::kSimilarity), toString(MotionModel::kAffine),
                             toString(MotionModel::kHomography), toString(MotionModel::kTranslation)}))
      ->capture_default_str();
  app.add_option("images", files, "image A, then image B")
      ->type_name("A B")
      ->expected(2)
      ->required()
      ->check(CLI::ExistingFile);
  app.footer(
      "Exit status: 0 registered, 3 the registration failed (the JSON says why), 2 bad arguments or unreadable "
      "images.");
  if (const auto exit_status = exocet_common::parseCommandLine(app, argc, argv)) return *exit_status;
  RegistrationConfig config;
  config.method = registrationMethodFromString(method);
  config.model = motionModelFromString(model);
  try {
    const cv::Mat a = readGray(files[0]);
    const cv::Mat b = readGray(files[1]);
    if (a.size() != b.size())
      throw std::invalid_argument("the images differ in size: " + std::to_string(a.cols) + "x" +
                                  std::to_string(a.rows) + " and " + std::to_string(b.cols) + "x" +
                                  std::to_string(b.rows));
    std::unique_ptr<FrameRegistrar> registrar = makeRegistrar(config);
    const MotionEstimate e = registrar->registerPair(a, b);
    const Eigen::Matrix3d h = e.failed ? Eigen::Matrix3d::Identity() : Eigen::Matrix3d(e.pixel_matrix / e.pixel_matrix(2, 2));
    nlohmann::ordered_json json;
    json["matrix"] = rows(h, e.model == MotionModel::kHomography ? 3 : 2);
    json["homography"] = rows(h, 3);
    json["model"] = toString(e.model);
    json["method"] = toString(e.method);
    json["centre_px"] = {e.centre_px.x(), e.centre_px.y()};
    json["parameters"] = nullptr;
    if (!e.failed)
      json["parameters"] = std::vector<double>(e.parameters.data(), e.parameters.data() + e.parameters.size());
    json["covariance"] = e.failed ? nlohmann::ordered_json(nullptr) : rows(e.covariance, int(e.covariance.rows()));
    json["quality"] = {{"observations", e.observations},       {"inliers", e.inliers},
                       {"inlier_fraction", e.inlier_fraction}, {"residual_scale", e.residual_scale},
                       {"iterations", e.iterations},           {"elapsed_ms", e.elapsed_ms}};
    json["failed"] = e.failed;
    json["failure"] = toString(e.failure);
    json["failure_detail"] = e.failure_detail;
    std::cout << exocet_common::jsonText(json, -1) << "\n";
    return e.failed ? 3 : 0;
  } catch (const std::invalid_argument& e) {
    std::cerr << "register_images: " << e.what() << "\n";
    return exocet_common::kExitBadInput;
  }
}
