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
#include <vector>

#include <opencv2/core.hpp>

namespace exocet_mosaic {
namespace sim {

/**
 * @brief The bilinear cell of world point (x_m, y_m) in a grid of cols x rows texels whose texel (0, 0) is centred on
 * (x0_m, y0_m): its lower texel (ix, iy) and the weights (ax, ay) of the texels at ix + 1 and iy + 1, clamped to the
 * grid's border (weight 0 or 1 there). The one place every sampler of a texture or a height map computes it, so that
 * they all give the same bits.
 */
struct BilinearCell {
  int ix = 0, iy = 0;
  float ax = 0.f, ay = 0.f;
};

inline BilinearCell bilinearCell(double x_m, double y_m, double x0_m, double y0_m, double texel_m, int cols,
                                 int rows) {
  const double fx = (x_m - x0_m) / texel_m;
  const double fy = (y_m - y0_m) / texel_m;
  BilinearCell c;
  c.ix = static_cast<int>(std::floor(fx));
  c.iy = static_cast<int>(std::floor(fy));
  c.ax = static_cast<float>(fx - c.ix);
  c.ay = static_cast<float>(fy - c.iy);
  const int max_x = cols - 2;
  const int max_y = rows - 2;
  if (c.ix < 0) {
    c.ix = 0;
    c.ax = 0.f;
  }
  if (c.iy < 0) {
    c.iy = 0;
    c.ay = 0.f;
  }
  if (c.ix > max_x) {
    c.ix = max_x;
    c.ax = 1.f;
  }
  if (c.iy > max_y) {
    c.iy = max_y;
    c.ay = 1.f;
  }
  return c;
}

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
    const auto [ix, iy, ax, ay] = bilinearCell(x_m, y_m, x0_m, y0_m, texel_m, texels.cols, texels.rows);
    const T* r0 = texels[iy] + ix;
    const T* r1 = texels[iy + 1] + ix;
    return (r0[0] * (1.f - ax) + r0[1] * ax) * (1.f - ay) + (r1[0] * (1.f - ax) + r1[1] * ax) * ay;
  }
};

/**
 * @brief A window of one texture level for sampling, whose texels stay where the texture keeps them (the tiles of
 * its cache, or one contiguous patch) rather than being copied into one array.
 *
 * Window texel (i, j), 0 <= i < cols(), 0 <= j < rows(), is centred on (x0_m + i * texel_m, y0_m + j * texel_m), as
 * in TexturePatch, and sample() does exactly TexturePatch::sample()'s arithmetic on the same texels: a window and
 * the patch of the same request give the same bits. Tiles are shared with the texture's cache and kept alive by the
 * window, so a window stays valid whatever the cache evicts.
 */
template <typename T>
class TextureWindow {
 public:
  using Tile = std::shared_ptr<const cv::Mat_<T>>;

  TextureWindow() = default;

  /// A window over one contiguous patch.
  explicit TextureWindow(const TexturePatch<T>& patch)
      : x0_m_(patch.x0_m),
        y0_m_(patch.y0_m),
        texel_m_(patch.texel_m),
        level_(patch.level),
        cols_(patch.texels.cols),
        rows_(patch.texels.rows),
        tile_shift_(kOneTileShift),
        tiles_across_(1),
        tiles_{std::make_shared<const cv::Mat_<T>>(patch.texels)} {}

  /**
   * @brief A window over square tiles of 2^tile_shift texels a side.
   * @param offset_x, offset_y position of window texel (0, 0) in the tile grid, in texels from the corner of
   *        tiles[0]: window texel (i, j) is texel ((i + offset_x) mod n, (j + offset_y) mod n) of tile
   *        ((j + offset_y) / n) * tiles_across + (i + offset_x) / n, with n = 2^tile_shift
   * @param tiles row-major, rows going north like the texels; every tile n x n texels
   */
  TextureWindow(double x0_m, double y0_m, double texel_m, int level, int cols, int rows, int tile_shift, int offset_x,
                int offset_y, int tiles_across, std::vector<Tile> tiles)
      : x0_m_(x0_m),
        y0_m_(y0_m),
        texel_m_(texel_m),
        level_(level),
        cols_(cols),
        rows_(rows),
        tile_shift_(tile_shift),
        tiles_across_(tiles_across),
        offset_x_(offset_x),
        offset_y_(offset_y),
        tiles_(std::move(tiles)) {}

  int cols() const { return cols_; }
  int rows() const { return rows_; }
  int level() const { return level_; }
  double texelSize_m() const { return texel_m_; }

  /// Texel (i, j) of the window (no bounds check beyond the tiles').
  const T& texel(int i, int j) const {
    const int gx = i + offset_x_, gy = j + offset_y_;
    const int mask = (1 << tile_shift_) - 1;
    const cv::Mat_<T>& tile = *tiles_[(gy >> tile_shift_) * tiles_across_ + (gx >> tile_shift_)];
    return tile(gy & mask, gx & mask);
  }

  /**
   * @brief Asks the processor to start fetching the texels that sample(x_m, y_m) reads, so that a sample issued a
   * little later does not wait for memory. A hint: no effect on any result.
   */
  void prefetch(double x_m, double y_m) const {
    const int ix = std::clamp(static_cast<int>(std::floor((x_m - x0_m_) / texel_m_)), 0, cols_ - 2);
    const int iy = std::clamp(static_cast<int>(std::floor((y_m - y0_m_) / texel_m_)), 0, rows_ - 2);
    const T* r0 = &texel(ix, iy);
    const T* r1 = &texel(ix, iy + 1);
    prefetchLine(r0);
    prefetchLine(r0 + 1);
    prefetchLine(r1);
    prefetchLine(r1 + 1);
  }

  /// Bilinear sample at world point (x_m, y_m); clamped to the window's border as TexturePatch::sample().
  T sample(double x_m, double y_m) const {
    const auto [ix, iy, ax, ay] = bilinearCell(x_m, y_m, x0_m_, y0_m_, texel_m_, cols_, rows_);
    const int gx = ix + offset_x_, gy = iy + offset_y_;
    const int mask = (1 << tile_shift_) - 1;
    const int lx = gx & mask, ly = gy & mask;
    const cv::Mat_<T>& tile = *tiles_[(gy >> tile_shift_) * tiles_across_ + (gx >> tile_shift_)];
    if (lx + 1 < tile.cols && ly + 1 < tile.rows) {
      const T* r0 = tile[ly] + lx;
      const T* r1 = tile[ly + 1] + lx;
      return (r0[0] * (1.f - ax) + r0[1] * ax) * (1.f - ay) + (r1[0] * (1.f - ax) + r1[1] * ax) * ay;
    }
    // The 2 x 2 texels straddle a tile border (one sample in n): fetch them one by one.
    const T& t00 = texel(ix, iy);
    const T& t10 = texel(ix + 1, iy);
    const T& t01 = texel(ix, iy + 1);
    const T& t11 = texel(ix + 1, iy + 1);
    return (t00 * (1.f - ax) + t10 * ax) * (1.f - ay) + (t01 * (1.f - ax) + t11 * ax) * ay;
  }

 private:
  static void prefetchLine(const T* p) {
#if defined(__GNUC__) && (defined(__x86_64__) || defined(__i386__))
    // An asm statement: GCC 12 deletes __builtin_prefetch and _mm_prefetch of an address read through cv::Mat_.
    asm volatile("prefetcht0 %0" : : "m"(*reinterpret_cast<const char*>(p)));
#else
    __builtin_prefetch(p);
#endif
  }

  /// A contiguous patch is one tile larger than any window: index arithmetic then never leaves it.
  static constexpr int kOneTileShift = 30;

  double x0_m_ = 0.0, y0_m_ = 0.0, texel_m_ = 1.0;
  int level_ = 0;
  int cols_ = 0, rows_ = 0;
  int tile_shift_ = kOneTileShift;
  int tiles_across_ = 1;
  int offset_x_ = 0, offset_y_ = 0;
  std::vector<Tile> tiles_;
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
  /**
   * @brief The same texels as albedoPatch(level, area), for sampling: a texture that keeps its texels in tiles
   * hands them over without copying them (a frame's patches span millions of texels). Default: albedoPatch()'s.
   */
  virtual TextureWindow<cv::Vec3f> albedoWindow(int level, const WorldRect& area) {
    return TextureWindow<cv::Vec3f>(albedoPatch(level, area));
  }
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
