#include "exocet_stereo/geometry/rig_calibration.h"

#include <sstream>
#include <stdexcept>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>

namespace exocet_stereo {
namespace geometry {

std::string RigCalibrationConfig::validate() const {
  std::ostringstream errors;
  const std::string pattern_errors = pattern.validate();
  if (!pattern_errors.empty()) errors << "pattern: " << pattern_errors;
  if (min_pairs < 3 || min_pairs > 1000) errors << (errors.tellp() > 0 ? "; " : "") << "min_pairs must be in [3, 1000]";
  return errors.str();
}

StereoRig calibrateStereoRig(const std::vector<std::string>& left_paths, const std::vector<std::string>& right_paths,
                             const RigCalibrationConfig& config, RigCalibrationLog* log) {
  const std::string error = config.validate();
  if (!error.empty()) throw std::invalid_argument("RigCalibrationConfig: " + error);
  if (left_paths.size() != right_paths.size())
    throw std::invalid_argument("calibrateStereoRig: " + std::to_string(left_paths.size()) + " left images but " +
                                std::to_string(right_paths.size()) + " right images");
  RigCalibrationLog local_log;
  if (!log) log = &local_log;

  std::vector<std::vector<cv::Point3f>> object_points;
  std::vector<std::vector<cv::Point2f>> left_points, right_points;
  cv::Size size;
  for (size_t i = 0; i < left_paths.size(); ++i) {
    const cv::Mat left = cv::imread(left_paths[i], cv::IMREAD_GRAYSCALE);
    const cv::Mat right = cv::imread(right_paths[i], cv::IMREAD_GRAYSCALE);
    if (left.empty()) throw std::runtime_error("calibrateStereoRig: cannot read '" + left_paths[i] + "'");
    if (right.empty()) throw std::runtime_error("calibrateStereoRig: cannot read '" + right_paths[i] + "'");
    if (size.empty()) size = left.size();
    if (left.size() != size || right.size() != size)
      throw std::runtime_error("calibrateStereoRig: '" + left_paths[i] + "' or '" + right_paths[i] +
                               "' differs in size from the first image (" + std::to_string(size.width) + "x" +
                               std::to_string(size.height) + ")");
    std::vector<cv::Point2f> cl, cr;
    const bool found_left = detectChessboard(left, config.pattern, cl);
    const bool found_right = detectChessboard(right, config.pattern, cr);
    if (!found_left || !found_right) {
      log->rejected.push_back(left_paths[i] + (found_left ? "" : " (board not found in left)") +
                              (found_right ? "" : " (board not found in right)"));
      continue;
    }
    log->used.push_back(left_paths[i]);
    left_points.push_back(cl);
    right_points.push_back(cr);
    object_points.push_back(config.pattern.objectPoints());
  }
  if (static_cast<int>(object_points.size()) < config.min_pairs)
    throw std::runtime_error("calibrateStereoRig: the board was found in both images of " +
                             std::to_string(object_points.size()) + " pairs; at least " +
                             std::to_string(config.min_pairs) + " are needed (min_pairs)");

  int flags = 0;
  if (config.zero_tangential) flags |= cv::CALIB_ZERO_TANGENT_DIST;
  if (config.fix_k3) flags |= cv::CALIB_FIX_K3;
  StereoRig rig;
  rig.image_size = size;
  rig.pairs_used = static_cast<int>(object_points.size());
  const cv::TermCriteria criteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 100, 1e-9);
  cv::Mat std_extrinsics, per_view;
  std::vector<cv::Mat> rvecs, tvecs;
  rig.rms_left_px = cv::calibrateCamera(object_points, left_points, size, rig.K_left, rig.dist_left, rvecs, tvecs,
                                        rig.std_intrinsics_left, std_extrinsics, per_view, flags, criteria);
  rig.rms_right_px = cv::calibrateCamera(object_points, right_points, size, rig.K_right, rig.dist_right, rvecs, tvecs,
                                         rig.std_intrinsics_right, std_extrinsics, per_view, flags, criteria);
  // The per-camera intrinsics start the joint estimate; the joint problem then refines them with the rig pose
  // (or keeps them, if asked), as the OpenCV stereo sample does.
  const int stereo_flags =
      flags | (config.fix_intrinsics_in_stereo ? cv::CALIB_FIX_INTRINSIC : cv::CALIB_USE_INTRINSIC_GUESS);
  rig.rms_stereo_px =
      cv::stereoCalibrate(object_points, left_points, right_points, rig.K_left, rig.dist_left, rig.K_right,
                          rig.dist_right, size, rig.R, rig.T, rig.E, rig.F, stereo_flags, criteria);
  rig.has_extrinsics = true;
  rig.updateDerived();
  return rig;
}

}  // namespace geometry
}  // namespace exocet_stereo
