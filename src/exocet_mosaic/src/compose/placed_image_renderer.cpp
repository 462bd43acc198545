#include "exocet_mosaic/compose/placed_image_renderer.h"

#include <cmath>
#include <sstream>
#include <stdexcept>

#include <opencv2/imgproc.hpp>

#include "canvas_warp.h"
#include "exocet_mosaic/compose/block_canvas.h"
#include "exocet_mosaic/compose/feather_weights.h"
#include "exocet_mosaic/compose/ground_projection.h"
#include "multiband_blend.h"

namespace exocet_mosaic {
namespace compose {

std::string PlacedImageRenderConfig::validate() const {
  std::ostringstream out;
  const auto bad = [&](const std::string& what) { out << (out.tellp() > 0 ? "; " : "") << what; };
  if (!(gsd_m > 0 && std::isfinite(gsd_m))) bad("gsd_m must be > 0 (got " + std::to_string(gsd_m) + ")");
  if (blend != "feather" && blend != "multiband" && blend != "none")
    bad("blend must be feather, multiband or none (got '" + blend + "')");
  if (!(feather_power > 0 && feather_power <= 10))
    bad("feather_power must be in (0, 10] (got " + std::to_string(feather_power) + ")");
  if (multiband_bands < 1 || multiband_bands > 10)
    bad("multiband_bands must be in [1, 10] (got " + std::to_string(multiband_bands) + ")");
  if (block_size_px < 16 || block_size_px > 4096)
    bad("block_size_px must be in [16, 4096] (got " + std::to_string(block_size_px) + ")");
  return out.str();
}

PlacedRaster renderPlacedImages(const std::vector<PlacedImage>& images, const Eigen::Vector2d& origin_en_m,
                                const PlacedImageRenderConfig& config) {
  const std::string error = config.validate();
  if (!error.empty()) throw std::invalid_argument("renderPlacedImages: " + error);
  PlacedRaster out;
  out.gsd_m = config.gsd_m;
  const double g = config.gsd_m;
  int channels = 0;
  for (const auto& p : images)
    if (!p.image.empty()) {
      channels = p.image.channels();
      break;
    }
  if (channels != 1 && channels != 3) {
    out.problem = images.empty() ? "no image to draw" : "no image of 1 or 3 channels to draw";
    return out;
  }
  // Canvas pixel (x, y) covers E in [Q.x + x g, Q.x + (x + 1) g], N in [Q.y - (y + 1) g, Q.y - y g], Q = the origin
  // on the GSD grid.
  const Eigen::Vector2d q(std::round(origin_en_m.x() / g) * g, std::round(origin_en_m.y() / g) * g);
  const Eigen::Vector2d d = origin_en_m - q;
  const cv::Matx33d canvas_from_ground(1 / g, 0, d.x() / g - 0.5, 0, -1 / g, -d.y() / g - 0.5, 0, 0, 1);
  BlockCanvas canvas(channels, config.block_size_px);
  FeatherWeights feather;
  std::vector<WarpedFrame> kept;
  const bool replace = config.blend == "none";
  for (const auto& p : images) {
    if (p.image.empty() || p.image.depth() != CV_8U) {
      out.problem = "an image that is empty or not 8-bit was left out";
      continue;
    }
    cv::Mat image = p.image;
    if (image.channels() != channels) {
      cv::Mat converted;
      cv::cvtColor(image, converted, channels == 3 ? cv::COLOR_GRAY2BGR : cv::COLOR_BGR2GRAY);
      image = converted;
    }
    const cv::Mat& w = replace ? feather.get(image.size(), 1e-9) : feather.get(image.size(), config.feather_power);
    CanvasWarp warp;
    if (!warpOntoCanvas(image, w, normalizeHomography(canvas_from_ground * p.ground_from_px), &warp, &out.problem))
      continue;
    canvas.accumulateAlpha(warp.image_alpha, warp.roi.tl(), replace);
    if (config.blend == "multiband") {
      std::vector<cv::Mat> planes;
      cv::split(warp.image_alpha, planes);
      cv::Mat weight, colour;
      planes.back().convertTo(weight, CV_32F, 1.0 / 255.0);
      planes.pop_back();
      cv::merge(planes, colour);
      kept.push_back({colour, weight, warp.roi});
    }
    std::array<Eigen::Vector2d, 4> corners;
    const double h = 0.5;  // canvas px -> UTM of the pixel's centre convention above
    for (int i = 0; i < 4; ++i)
      corners[i] = Eigen::Vector2d(q.x() + (warp.corners_canvas[i].x() + h) * g,
                                   q.y() - (warp.corners_canvas[i].y() + h) * g);
    out.footprints_en_m.push_back(corners);
    ++out.images_drawn;
  }
  const cv::Rect region = canvas.dataBounds();
  if (region.empty()) {
    if (out.problem.empty()) out.problem = "nothing drawn";
    return out;
  }
  if (config.blend == "multiband")
    blendMultiband(kept, region, config.multiband_bands, channels, &out.image, &out.mask);
  else
    canvas.render(region, &out.image, &out.mask);
  out.origin_easting_m = q.x() + region.x * g;
  out.origin_northing_m = q.y() - region.y * g;
  return out;
}

}  // namespace compose
}  // namespace exocet_mosaic
