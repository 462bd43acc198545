// Calibrates a stereo rig from chessboard image pairs and writes it as OpenCV-compatible YAML.
//   calibrate_stereo_rig --folder DIR | --left-glob 'DIR/left*.jpg' --right-glob 'DIR/right*.jpg'
//                        [--pattern 9x6] [--square-mm 25] [--fix-intrinsics] --output rig.yaml
// With --folder, the pairs are DIR/left* and DIR/right* images (.jpg, .jpeg, .png), matched in sorted order.
#include <algorithm>
#include <iostream>
#include <string>
#include <vector>

#include <opencv2/core/utility.hpp>

#include "exocet_stereo/geometry/rig_calibration.h"

namespace {

using namespace exocet_stereo::geometry;

int usage(const std::string& error) {
  std::cerr << "calibrate_stereo_rig: " << error << "\n"
            << "usage: calibrate_stereo_rig (--folder DIR | --left-glob PATTERN --right-glob PATTERN) "
               "[--pattern COLSxROWS] [--square-mm MM] [--fix-intrinsics] --output FILE.yaml\n";
  return 2;
}

std::vector<std::string> imagesOf(const std::string& folder, const std::string& prefix) {
  std::vector<std::string> out;
  for (const char* ext : {"jpg", "jpeg", "png"}) {
    std::vector<cv::String> found;
    cv::glob(folder + "/" + prefix + "*." + ext, found, false);
    out.insert(out.end(), found.begin(), found.end());
  }
  std::sort(out.begin(), out.end());
  return out;
}

std::vector<std::string> globbed(const std::string& pattern) {
  std::vector<cv::String> found;
  cv::glob(pattern, found, false);
  std::vector<std::string> out(found.begin(), found.end());
  std::sort(out.begin(), out.end());
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  std::string folder, left_glob, right_glob, output, pattern_text = "9x6";
  double square_mm = 25.0;
  RigCalibrationConfig config;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) throw std::invalid_argument(arg + " needs a value");
      return argv[++i];
    };
    try {
      if (arg == "--folder")
        folder = value();
      else if (arg == "--left-glob")
        left_glob = value();
      else if (arg == "--right-glob")
        right_glob = value();
      else if (arg == "--pattern")
        pattern_text = value();
      else if (arg == "--square-mm")
        square_mm = std::stod(value());
      else if (arg == "--output")
        output = value();
      else if (arg == "--fix-intrinsics")
        config.fix_intrinsics_in_stereo = true;
      else if (arg == "--help" || arg == "-h") {
        usage("calibrates a stereo rig from chessboard pairs");
        return 0;
      } else
        return usage("unknown argument '" + arg + "'");
    } catch (const std::exception& e) {
      return usage(e.what());
    }
  }
  if (output.empty()) return usage("--output is required");
  if (folder.empty() == (left_glob.empty() || right_glob.empty()))
    return usage("give either --folder or both --left-glob and --right-glob");
  try {
    config.pattern.inner_corners = parsePatternSize(pattern_text);
    config.pattern.square_m = square_mm / 1000.0;
    const std::vector<std::string> left = folder.empty() ? globbed(left_glob) : imagesOf(folder, "left");
    const std::vector<std::string> right = folder.empty() ? globbed(right_glob) : imagesOf(folder, "right");
    if (left.empty() || left.size() != right.size())
      return usage("found " + std::to_string(left.size()) + " left and " + std::to_string(right.size()) +
                   " right images; they must be equal in number and not zero");
    RigCalibrationLog log;
    const StereoRig rig = calibrateStereoRig(left, right, config, &log);
    for (const auto& r : log.rejected) std::cerr << "skipped " << r << "\n";
    writeStereoRig(rig, output);
    std::cout << "pairs used " << rig.pairs_used << " of " << left.size() << "\n"
              << "RMS left " << rig.rms_left_px << " px, right " << rig.rms_right_px << " px, stereo "
              << rig.rms_stereo_px << " px\n"
              << "fx " << rig.K_left.at<double>(0, 0) << " / " << rig.K_right.at<double>(0, 0) << " px, baseline "
              << rig.baseline_m * 1000.0 << " mm, optical axes " << rig.optical_axes_angle_deg << " deg\n"
              << "written " << output << "\n";
  } catch (const std::exception& e) {
    std::cerr << "calibrate_stereo_rig: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
