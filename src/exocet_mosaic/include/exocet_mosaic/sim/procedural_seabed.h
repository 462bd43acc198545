/**
 * @file procedural_seabed.h
 * @brief An unbounded, deterministic procedural seabed for the dive simulator: albedo (sediment colours, sand
 * ripples, rocks, shells, grain) and the matching relief (mounds, regional slope, ripples, rock domes).
 *
 * Everything is a pure function of (seed, level, world position): tiles are generated lazily, cached in an LRU
 * bounded by a memory budget, and regenerate bit for bit after eviction, in any order, on any number of threads.
 * Rocks and shells come from a hashed grid of cells (a Poisson count per cell), so any area is generated on its
 * own; the texture and the relief draw the same rocks, so that a rock in the albedo is a bump in the relief.
 *
 * Level L of the albedo has texels of base_texel_m * 2^L; texel (i, j) of level L covers
 * [i, i + 1) x [j, j + 1) * texel_m in world x (east) and y (north). Coarser levels are band-limited: grain
 * octaves finer than two texels are faded out, ripples are attenuated as by the cascade of 2x2 box filters
 * (Gaussian approximation), rock and shell edges are anti-aliased with area-preserving ramps averaged over 2x2
 * sub-samples, and from 128 mm texels on, shells and burrows only add their expected share of the mean. So a
 * texel of level L+1 is close to the mean of the four texels below it (area means agree to < 1 %).
 */
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "exocet_mosaic/sim/seabed_texture.h"

namespace exocet_mosaic {
namespace sim {

/**
 * @brief Parameters of the procedural seabed (texture and relief). validate() lists the allowed ranges.
 */
struct ProceduralSeabedConfig {
  uint64_t seed = 1;  ///< every texel and rock derives from it

  // --- Pyramid and cache ---
  double base_texel_m = 0.002;   ///< texel size of level 0 (metres)
  int tile_texels = 256;         ///< tile side (texels), a power of two
  double cache_budget_mb = 256;  ///< LRU cache budget of each texture or relief object (MiB)
  int max_level = 8;             ///< coarsest level (level L texel = base_texel_m * 2^L)

  // --- Appearance (albedo) ---
  double sediment_contrast = 0.6;     ///< [0, 1] metre-scale mixing of sand, mud and shelly sand
  double grain_contrast = 0.22;       ///< [0, 1] relative amplitude of the multi-scale grain (1 sigma)
  double ripple_coverage = 0.5;       ///< [0, 1] fraction of the seabed covered by ripple patches
  double ripple_wavelength_m = 0.12;  ///< crest spacing (metres)
  double ripple_contrast = 0.25;      ///< [0, 1] relative albedo modulation by the ripples (darker troughs)
  double ripple_direction_deg = 30;   ///< direction across the crests, counter-clockwise from east (degrees)
  double rock_density_per_m2 = 0.8;   ///< mean number of rocks per square metre (clustered in patches)
  double rock_radius_min_m = 0.015;   ///< smallest rock radius (metres); sizes follow a power law
  double rock_radius_max_m = 0.25;    ///< largest rock radius (metres)
  double shell_density_per_m2 = 6;    ///< mean number of shells (bright, 5-30 mm long) per square metre
  double burrow_density_per_m2 = 4;   ///< mean number of burrow openings (dark, 4-15 mm) per square metre

  // --- Relief (ProceduralRelief) ---
  bool relief_enabled = false;              ///< false: the relief is the plane z = 0
  double mound_amplitude_m = 0.3;           ///< bound of the broad mounds' height, |h| <= amplitude (metres)
  double mound_size_m = 6.0;                ///< lattice size of the broad mounds (metres)
  double regional_slope = 0.01;             ///< gradient of the regional slope (dimensionless, rise over run)
  double regional_slope_direction_deg = 0;  ///< direction of steepest ascent, counter-clockwise from east (deg)
  double regional_slope_extent_m = 200;     ///< half-width of the sloping region; beyond it levels off (tanh)
  double ripple_height_m = 0.008;           ///< crest-to-trough height of the ripples (metres)
  double rock_height_scale = 0.45;          ///< rock dome height / radius (each rock +-25 %, slope-capped)
  double relief_grid_m = 0.01;              ///< spacing of the height patches (metres)

  /// Empty if usable, otherwise every bad field with its allowed range, separated by "; ".
  std::string validate() const;
};

/// One rock of the procedural seabed (ground truth for tests and evaluation).
struct SeabedRock {
  double x_m = 0.0, y_m = 0.0;  ///< centre (world, metres)
  double radius_m = 0.0;        ///< nominal radius; the outline varies by up to ~15 % around it
  double height_m = 0.0;        ///< dome height above the surrounding sediment in the relief (0: flat pebble)
};

/// Rocks whose centre lies in `area`, in a deterministic order. Throws std::invalid_argument on a bad config.
std::vector<SeabedRock> proceduralRocks(const ProceduralSeabedConfig& config, const WorldRect& area);

/**
 * @brief Procedural seabed albedo, generated in cached tiles of tile_texels^2 texels per level.
 *
 * Thread-safe: calls are serialised on an internal mutex; tile generation itself runs rows in parallel
 * (cv::parallel_for_) with results independent of the thread count.
 */
class ProceduralSeabedTexture final : public SeabedTexture {
 public:
  /// Throws std::invalid_argument with config.validate()'s message if the config is not usable.
  explicit ProceduralSeabedTexture(const ProceduralSeabedConfig& config);
  ~ProceduralSeabedTexture() override;

  double baseTexelSize_m() const override;
  int maxLevel() const override;
  /// Throws std::out_of_range for a level outside [0, maxLevel()], std::invalid_argument for an empty or
  /// non-finite area or a patch above 64 Mtexels.
  TexturePatch<cv::Vec3f> albedoPatch(int level, const WorldRect& area) override;
  /// The texels of albedoPatch(level, area) left in the cached tiles (no copy); throws as albedoPatch().
  TextureWindow<cv::Vec3f> albedoWindow(int level, const WorldRect& area) override;

  /// Uncached evaluation of the level-`level` texel containing (x_m, y_m): equal bit for bit to the patches.
  cv::Vec3f albedoTexel(int level, double x_m, double y_m) const;

  /// Bytes of tile data held by the cache now (always <= the budget).
  size_t cachedBytes() const;
  /// Tiles generated since construction (a tile evicted and asked again counts twice).
  size_t tilesGenerated() const;
  const ProceduralSeabedConfig& config() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/**
 * @brief Procedural seabed height: regional slope + broad mounds + ripples + rock domes (same rocks as the
 * texture with the same config). With relief_enabled false it is the plane z = 0.
 *
 * h = slope + mounds + smooth_max(ripples, rock domes): rocks emerge from the rippled sand, and the Lipschitz
 * bound of a (smooth) maximum is the larger of the two. The rocks' domes are capped to the slope budget left by
 * the ground, so that maxSlope() stays near 1 (1.01 with the defaults); only steep ripples raise it, by about
 * 9 * ripple_height_m / ripple_wavelength_m. Rocks too small for the grid to resolve (bilinear error > 1.6 mm)
 * or too steep for the cap are lowered (see SeabedRock::height_m).
 */
class ProceduralRelief final : public SeabedRelief {
 public:
  /// Throws std::invalid_argument with config.validate()'s message if the config is not usable.
  explicit ProceduralRelief(const ProceduralSeabedConfig& config);
  ~ProceduralRelief() override;

  bool isFlat() const override;
  double maxHeight_m() const override;
  double minHeight_m() const override;
  double maxSlope() const override;
  double gridSpacing_m() const override;
  /// Sample (i, j) is the exact height at (x0_m + i * grid, y0_m + j * grid), stored as float.
  /// Throws std::invalid_argument for an empty or non-finite area or a patch above 64 Msamples.
  TexturePatch<float> heightPatch(const WorldRect& area) override;
  double heightAt_m(double x_m, double y_m) const override;
  /// Bounds of the height over `area` (metres): tighter than min/maxHeight_m(), which span the whole regional
  /// slope; for ray marching a frame's footprint.
  void heightBounds_m(const WorldRect& area, double* min_m, double* max_m) const;

  size_t cachedBytes() const;
  size_t tilesGenerated() const;
  const ProceduralSeabedConfig& config() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace sim
}  // namespace exocet_mosaic
