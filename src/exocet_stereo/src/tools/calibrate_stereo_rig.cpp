// Calibrates a stereo rig from chessboard image pairs and writes it as OpenCV-compatible YAML.
//   calibrate_stereo_rig --folder DIR | --left-glob 'DIR/left*.jpg' --right-glob 'DIR/right*.jpg'
//                        [--pattern 9x6] [--square-mm 25] [--fix-intrinsics] --output rig.yaml
// With --folder, the pairs are DIR/left* and DIR/right* images (.jpg, .jpeg, .png), matched in sorted order.
#include <algorithm>
#include <iostream>
#include <string>
#include <vector>

#include <opencv2/core/utility.hpp>

#include "exocet_common/command_line.h"
#include "exocet_stereo/geometry/rig_calibration.h"

namespace {

using namespace exocet_stereo::geometry;

int badInput(const std::string& error) {
  std::cerr << "calibrate_stereo_rig: " << error << "\n";
  return exocet_common::kExitBadInput;
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
  CLI::App app(
      "calibrate_stereo_rig: calibrates a stereo rig from chessboard image pairs and writes it as "
      "OpenCV-compatible YAML.",
      "calibrate_stereo_rig");
  auto* folder_option =
      app.add_option(
             "--folder", folder,
             "folder of the pairs: DIR/left* and DIR/right* images (.jpg, .jpeg, .png), matched in\nsorted order")
          ->check(CLI::ExistingDirectory);
  auto* left_option = app.add_option("--left-glob", left_glob, "left images, e.g. 'DIR/left*.jpg' (quoted)")
                          ->type_name("PATTERN")
                          ->excludes(folder_option);
  app.add_option("--right-glob", right_glob, "right images, matched with the left ones in sorted order")
      ->type_name("PATTERN")
      ->excludes(folder_option)
      ->needs(left_option);
  left_option->needs("--right-glob");
  app.add_option("--pattern", pattern_text, "inner corners of the chessboard, COLSxROWS, each in [2, 100]")
      ->type_name("COLSxROWS")
      ->check(CLI::Validator(
          [](std::string& text) {
            try {
              parsePatternSize(text);
              return std::string();
            } catch (const std::invalid_argument& e) {
              return std::string(e.what());
            }
          },
          ""))
      ->capture_default_str();
  app.add_option("--square-mm", square_mm, "side of a chessboard square (millimetres)")
      ->type_name("MM")
      ->capture_default_str();
  app.add_flag("--fix-intrinsics", config.fix_intrinsics_in_stereo,
               "keep each camera's intrinsics from its own calibration in the stereo fit");
  app.add_option("--output", output, "the rig's YAML")->type_name("FILE.yaml")->required();
  if (const auto exit_status = exocet_common::parseCommandLine(app, argc, argv)) return *exit_status;
  if (folder.empty() == left_glob.empty()) return badInput("give either --folder or both --left-glob and --right-glob");
  try {
    config.pattern.inner_corners = parsePatternSize(pattern_text);
    config.pattern.square_m = square_mm / 1000.0;
    const std::vector<std::string> left = folder.empty() ? globbed(left_glob) : imagesOf(folder, "left");
    const std::vector<std::string> right = folder.empty() ? globbed(right_glob) : imagesOf(folder, "right");
    if (left.empty() || left.size() != right.size())
      return badInput("found " + std::to_string(left.size()) + " left and " + std::to_string(right.size()) +
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
