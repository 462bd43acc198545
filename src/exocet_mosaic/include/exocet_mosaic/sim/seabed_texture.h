/**
 * @file seabed_texture.h
 * @brief The seabed's appearance (albedo) and shape (height), served as patches for rendering.
 *
 * The world frame is the dive's local metric frame: x east, y north, z up (metres), origin at the dive
 * origin. A texture is a pyramid of levels; level L has texels of baseTexelSize_m() * 2^L. The renderer asks,
 * once per frame, for the patch that covers the camera footprint at the levels it needs, then samples the
 * patch bilinearly: so a texture may be procedural and unbounded (generated lazily in tiles, cached within a
 * memory budget) or an image held in memory, and the renderer does not know which.
 *
 * The simulator renders several frames at once: albedoPatch() and heightPatch() must allow concurrent calls.
 */
#pragma once

#include <algorithm>
#include <cmath>
#include <memory>

#include <opencv2/core.hpp>

namespace exocet_mosaic {
namespace sim {

/**
 * @brief A rectangular window of one texture level.
 *
 * Texel (col i, row j) of `texels` is centred on world point (x0_m + i * texel_m, y0_m + j * texel_m): rows go
 * north. The patch may be larger than requested; it is never smaller.
 */
template <typename T>
struct TexturePatch {
  cv::Mat_<T> texels;
  double x0_m = 0.0;
  double y0_m = 0.0;
  double texel_m = 1.0;
  int level = 0;

  /// Bilinear sample at world point (x_m, y_m); clamped to the patch border.
  T sample(double x_m, double y_m) const {
    const double fx = (x_m - x0_m) / texel_m;
    const double fy = (y_m - y0_m) / texel_m;
    int ix = static_cast<int>(std::floor(fx));
    int iy = static_cast<int>(std::floor(fy));
    float ax = static_cast<float>(fx - ix);
    float ay = static_cast<float>(fy - iy);
    const int max_x = texels.cols - 2;
    const int max_y = texels.rows - 2;
    if (ix < 0) { ix = 0; ax = 0.f; }
    if (iy < 0) { iy = 0; ay = 0.f; }
    if (ix > max_x) { ix = max_x; ax = 1.f; }
    if (iy > max_y) { iy = max_y; ay = 1.f; }
    const T* r0 = texels[iy] + ix;
    const T* r1 = texels[iy + 1] + ix;
    return (r0[0] * (1.f - ax) + r0[1] * ax) * (1.f - ay) + (r1[0] * (1.f - ax) + r1[1] * ax) * ay;
  }
};

/// An axis-aligned rectangle of the world (metres).
struct WorldRect {
  double x_min_m = 0.0, y_min_m = 0.0, x_max_m = 0.0, y_max_m = 0.0;
};

/**
 * @brief Seabed albedo: linear RGB reflectance in [0, 1] (cv::Vec3f in R, G, B order).
 */
class SeabedTexture {
 public:
  virtual ~SeabedTexture() = default;
  /// Texel size of level 0 (metres).
  virtual double baseTexelSize_m() const = 0;
  /// Coarsest level available (levels 0..maxLevel()).
  virtual int maxLevel() const = 0;
  /**
   * @brief The patch of level `level` covering `area` (with at least one texel of margin).
   * Not const: a procedural texture generates and caches tiles. Deterministic: the texels do not depend on
   * what was asked before.
   */
  virtual TexturePatch<cv::Vec3f> albedoPatch(int level, const WorldRect& area) = 0;
};

/**
 * @brief Seabed height above the dive's reference seabed plane (metres, up positive).
 */
class SeabedRelief {
 public:
  virtual ~SeabedRelief() = default;
  /// True if the seabed is the plane z = 0 everywhere (rendering then skips ray marching).
  virtual bool isFlat() const = 0;
  /// Highest and lowest heights anywhere (metres): bounds for ray casting.
  virtual double maxHeight_m() const = 0;
  virtual double minHeight_m() const = 0;
  /// An upper bound of the slope |grad h| anywhere (dimensionless): the step bound of ray marching.
  virtual double maxSlope() const = 0;
  /// Grid spacing of the height patches (metres).
  virtual double gridSpacing_m() const = 0;
  /// Height patch covering `area` (at least one sample of margin); deterministic like albedoPatch().
  virtual TexturePatch<float> heightPatch(const WorldRect& area) = 0;
  /// Height at one point, exact (for sensors and tests; slower than sampling a patch).
  virtual double heightAt_m(double x_m, double y_m) const = 0;
};

/// The flat seabed: z = 0 everywhere.
class FlatRelief : public SeabedRelief {
 public:
  bool isFlat() const override { return true; }
  double maxHeight_m() const override { return 0.0; }
  double minHeight_m() const override { return 0.0; }
  double maxSlope() const override { return 0.0; }
  double gridSpacing_m() const override { return 1.0; }
  TexturePatch<float> heightPatch(const WorldRect& area) override {
    TexturePatch<float> p;
    p.texels = cv::Mat_<float>::zeros(2, 2);
    p.x0_m = area.x_min_m;
    p.y0_m = area.y_min_m;
    p.texel_m = std::max(area.x_max_m - area.x_min_m, area.y_max_m - area.y_min_m) + 1.0;
    return p;
  }
  double heightAt_m(double, double) const override { return 0.0; }
};

}  // namespace sim
}  // namespace exocet_mosaic
