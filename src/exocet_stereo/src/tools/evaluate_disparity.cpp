// evaluate_disparity: Middlebury v2 bad-pixel rates (nonocc / all / disc) of a disparity map.
#include <cstdio>
#include <iostream>
#include <string>
#include <tuple>

#include <opencv2/imgcodecs.hpp>

#include "exocet_common/command_line.h"
#include "exocet_stereo/dense/evaluation.h"
#include "exocet_stereo/io/pfm.h"

namespace {

int badInput(const std::string& error) {
  std::cerr << "evaluate_disparity: " << error << "\n";
  return exocet_common::kExitBadInput;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace exocet_stereo;
  std::string disparity_path, scene_dir, gt_path, nonocc_path, all_path, disc_path;
  double threshold = 1.0, scale = 0.0;
  CLI::App app(
      "evaluate_disparity: Middlebury v2 bad-pixel rates (nonocc / all / disc) of a disparity map, against a\n"
      "scene folder or against a ground truth and its three masks.",
      "evaluate_disparity");
  app.add_option("--disparity", disparity_path,
                 "the disparity map: D.pfm read as is, D.png read as value / scale (0 = unknown)")
      ->type_name("D.pfm|D.png")
      ->required()
      ->check(CLI::ExistingFile);
  auto* scene_option = app.add_option("--scene", scene_dir,
                                      "Middlebury v2 folder (groundtruth.png, nonocc.png, all.png, disc.png, info.txt)")
                           ->check(CLI::ExistingDirectory);
  auto* gt_option = app.add_option("--groundtruth", gt_path, "ground-truth disparity PNG, read as value / scale")
                        ->type_name("GT.png")
                        ->check(CLI::ExistingFile)
                        ->excludes(scene_option);
  for (auto [name, path, what] : {std::tuple{"--nonocc", &nonocc_path, "mask of the non-occluded pixels"},
                                  {"--all", &all_path, "mask of the pixels with a ground truth"},
                                  {"--disc", &disc_path, "mask of the pixels near discontinuities"}})
    gt_option->needs(app.add_option(name, *path, std::string(what) + " (with --groundtruth)")
                         ->type_name("M.png")
                         ->check(CLI::ExistingFile)
                         ->excludes(scene_option));
  app.add_option("--threshold", threshold, "a pixel is bad when |d - gt| exceeds it (pixels), > 0")
      ->type_name("T")
      ->check(exocet_common::greaterThan(0.0))
      ->capture_default_str();
  app.add_option("--scale", scale,
                 "PNG disparity = value / scale; required (> 0) with --groundtruth, from info.txt with\n--scene")
      ->type_name("S");
  if (const auto exit_status = exocet_common::parseCommandLine(app, argc, argv)) return *exit_status;
  if (scene_dir.empty() && gt_path.empty())
    return badInput("give --scene DIR, or --groundtruth with --nonocc, --all and --disc");
  try {
    dense::MiddleburyScene scene;
    if (!scene_dir.empty()) {
      scene = dense::loadMiddleburyScene(scene_dir);
      if (scale <= 0.0) scale = scene.scale;
    } else {
      if (!(scale > 0.0)) return badInput("--scale S (> 0) is required with --groundtruth");
      scene.ground_truth_px = dense::readScaledDisparityPng(gt_path, scale, false);
      for (auto [path, mask] :
           {std::pair{nonocc_path, &scene.nonocc}, {all_path, &scene.all}, {disc_path, &scene.disc}}) {
        *mask = cv::imread(path, cv::IMREAD_GRAYSCALE);
        if (mask->empty()) return badInput("cannot read mask " + path);
      }
    }
    cv::Mat disparity;
    const bool is_pfm = disparity_path.size() > 4 && disparity_path.substr(disparity_path.size() - 4) == ".pfm";
    disparity = is_pfm ? io::readPfm(disparity_path) : dense::readScaledDisparityPng(disparity_path, scale, true);
    if (disparity.type() != CV_32FC1) return badInput("disparity must have one channel");
    if (disparity.size() != scene.ground_truth_px.size())
      return badInput("disparity size differs from the ground truth");
    const dense::BadPixelRates rates = dense::evaluateDisparity(disparity, scene, threshold);
    std::printf("bad pixels (|d - gt| > %.2f px): nonocc %.2f %%  all %.2f %%  disc %.2f %%\n", threshold, rates.nonocc,
                rates.all, rates.disc);
  } catch (const std::exception& e) {
    return badInput(e.what());
  }
  return 0;
}
