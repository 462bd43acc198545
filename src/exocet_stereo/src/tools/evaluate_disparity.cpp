// evaluate_disparity: Middlebury v2 bad-pixel rates (nonocc / all / disc) of a disparity map.
#include <cstdio>
#include <iostream>
#include <string>

#include <opencv2/imgcodecs.hpp>

#include "exocet_stereo/dense/evaluation.h"
#include "exocet_stereo/io/pfm.h"

namespace {

int usage(const std::string& error) {
  if (!error.empty()) std::cerr << "evaluate_disparity: " << error << "\n";
  std::cerr << "usage: evaluate_disparity --disparity D.pfm|D.png --scene DIR [--threshold 1.0] [--scale S]\n"
               "       evaluate_disparity --disparity D --groundtruth GT.png --scale S --nonocc M1 --all M2 --disc M3\n"
               "  DIR: Middlebury v2 folder (groundtruth.png, nonocc.png, all.png, disc.png, info.txt).\n"
               "  D.png is read as value / scale (scale from info.txt unless --scale), 0 = unknown; D.pfm as is.\n";
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace exocet_stereo;
  std::string disparity_path, scene_dir, gt_path, nonocc_path, all_path, disc_path;
  double threshold = 1.0, scale = 0.0;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--help" || arg == "-h") return usage(""), 0;
    if (i + 1 >= argc) return usage("option " + arg + " needs a value");
    const std::string value = argv[++i];
    try {
      if (arg == "--disparity")
        disparity_path = value;
      else if (arg == "--scene")
        scene_dir = value;
      else if (arg == "--groundtruth")
        gt_path = value;
      else if (arg == "--nonocc")
        nonocc_path = value;
      else if (arg == "--all")
        all_path = value;
      else if (arg == "--disc")
        disc_path = value;
      else if (arg == "--threshold")
        threshold = std::stod(value);
      else if (arg == "--scale")
        scale = std::stod(value);
      else
        return usage("unknown option " + arg);
    } catch (const std::exception&) {
      return usage("option " + arg + " needs a number, got '" + value + "'");
    }
  }
  if (disparity_path.empty()) return usage("--disparity is required");
  if (scene_dir.empty() && (gt_path.empty() || nonocc_path.empty() || all_path.empty() || disc_path.empty()))
    return usage("give --scene DIR, or --groundtruth with --nonocc, --all and --disc");
  if (!(threshold > 0.0)) return usage("--threshold must be > 0");
  try {
    dense::MiddleburyScene scene;
    if (!scene_dir.empty()) {
      scene = dense::loadMiddleburyScene(scene_dir);
      if (scale <= 0.0) scale = scene.scale;
    } else {
      if (!(scale > 0.0)) return usage("--scale S (> 0) is required with --groundtruth");
      scene.ground_truth_px = dense::readScaledDisparityPng(gt_path, scale, false);
      for (auto [path, mask] :
           {std::pair{nonocc_path, &scene.nonocc}, {all_path, &scene.all}, {disc_path, &scene.disc}}) {
        *mask = cv::imread(path, cv::IMREAD_GRAYSCALE);
        if (mask->empty()) return usage("cannot read mask " + path);
      }
    }
    cv::Mat disparity;
    const bool is_pfm = disparity_path.size() > 4 && disparity_path.substr(disparity_path.size() - 4) == ".pfm";
    disparity = is_pfm ? io::readPfm(disparity_path) : dense::readScaledDisparityPng(disparity_path, scale, true);
    if (disparity.type() != CV_32FC1) return usage("disparity must have one channel");
    if (disparity.size() != scene.ground_truth_px.size()) return usage("disparity size differs from the ground truth");
    const dense::BadPixelRates rates = dense::evaluateDisparity(disparity, scene, threshold);
    std::printf("bad pixels (|d - gt| > %.2f px): nonocc %.2f %%  all %.2f %%  disc %.2f %%\n", threshold, rates.nonocc,
                rates.all, rates.disc);
  } catch (const std::exception& e) {
    return usage(e.what());
  }
  return 0;
}
