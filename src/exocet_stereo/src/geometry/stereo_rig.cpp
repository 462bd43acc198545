#include "exocet_stereo/geometry/stereo_rig.h"

#include <cmath>
#include <stdexcept>

namespace exocet_stereo {
namespace geometry {

void StereoRig::updateDerived() {
  if (T.empty() || R.empty()) return;
  baseline_m = cv::norm(T);
  // The right optical axis in left coordinates is R^T e_z; its angle with e_z.
  const double cos_angle = R.at<double>(2, 2);
  optical_axes_angle_deg = std::acos(std::max(-1.0, std::min(1.0, cos_angle))) * 180.0 / M_PI;
}

void writeStereoRig(const StereoRig& rig, const std::string& path) {
  cv::FileStorage fs(path, cv::FileStorage::WRITE);
  if (!fs.isOpened()) throw std::runtime_error("writeStereoRig: cannot write '" + path + "'");
  fs << "image_width" << rig.image_size.width << "image_height" << rig.image_size.height;
  fs << "M1" << rig.K_left << "D1" << rig.dist_left << "M2" << rig.K_right << "D2" << rig.dist_right;
  if (rig.has_extrinsics) fs << "R" << rig.R << "T" << rig.T << "E" << rig.E << "F" << rig.F;
  fs << "baseline_m" << rig.baseline_m << "optical_axes_angle_deg" << rig.optical_axes_angle_deg;
  fs << "rms_left_px" << rig.rms_left_px << "rms_right_px" << rig.rms_right_px << "rms_stereo_px" << rig.rms_stereo_px
     << "pairs_used" << rig.pairs_used;
  if (!rig.std_intrinsics_left.empty()) fs << "std_intrinsics_left" << rig.std_intrinsics_left;
  if (!rig.std_intrinsics_right.empty()) fs << "std_intrinsics_right" << rig.std_intrinsics_right;
}

StereoRig readStereoRig(const std::string& path) {
  cv::FileStorage fs(path, cv::FileStorage::READ);
  if (!fs.isOpened()) throw std::runtime_error("readStereoRig: cannot read '" + path + "'");
  StereoRig rig;
  auto required = [&](const char* key, cv::Mat& m) {
    fs[key] >> m;
    if (m.empty()) throw std::runtime_error("readStereoRig: '" + path + "' has no matrix '" + key + "'");
    m.convertTo(m, CV_64F);
  };
  required("M1", rig.K_left);
  required("D1", rig.dist_left);
  required("M2", rig.K_right);
  required("D2", rig.dist_right);
  fs["R"] >> rig.R;
  fs["T"] >> rig.T;
  rig.has_extrinsics = !rig.R.empty() && !rig.T.empty();
  if (rig.has_extrinsics) {
    rig.R.convertTo(rig.R, CV_64F);
    rig.T.convertTo(rig.T, CV_64F);
    rig.T = rig.T.reshape(1, 3);
    fs["E"] >> rig.E;
    fs["F"] >> rig.F;
  }
  if (!fs["image_width"].empty()) rig.image_size = cv::Size(int(fs["image_width"]), int(fs["image_height"]));
  if (!fs["rms_left_px"].empty()) rig.rms_left_px = double(fs["rms_left_px"]);
  if (!fs["rms_right_px"].empty()) rig.rms_right_px = double(fs["rms_right_px"]);
  if (!fs["rms_stereo_px"].empty()) rig.rms_stereo_px = double(fs["rms_stereo_px"]);
  if (!fs["pairs_used"].empty()) rig.pairs_used = int(fs["pairs_used"]);
  fs["std_intrinsics_left"] >> rig.std_intrinsics_left;
  fs["std_intrinsics_right"] >> rig.std_intrinsics_right;
  rig.updateDerived();
  return rig;
}

}  // namespace geometry
}  // namespace exocet_stereo
