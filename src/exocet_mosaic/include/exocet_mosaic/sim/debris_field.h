/**
 * @file debris_field.h
 * @brief Objects with steep sides standing on the simulated seabed, for scenes of strong relief: the piled amphorae
 * and blocks of a wreck site, or a field of boulders. They give what real wreck, rock and reef footage gives and a
 * gently rolling seabed does not: parallax of tens of pixels between frames, occlusions, faces lit at grazing angles.
 *
 * Each object is an elliptical mound, h = foot + H g(q) with q the elliptical radius (1 on the outline): a rounded or
 * flat top (1 - q^m)^(1/m) capped by a ramp k (1 - q) so that no side is steeper than max_slope (rise over run). The
 * relief is the larger of the base seabed and every object, so overlapping objects make piles. Objects come from a
 * hashed grid of cells (a Poisson count per cell, modulated by a smooth "site" field: piles and bare sand), so any
 * area is generated on its own, in any order, on any thread; the texture and the relief draw the same objects.
 * The dominant plane stays the base seabed's: with a flat base, z = 0 is the plane the ground truth refers to.
 */
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "exocet_mosaic/sim/seabed_texture.h"

namespace exocet_mosaic {
namespace sim {

/// Parameters of a debris field. validate() lists the allowed ranges; preset() gives the named scenes.
struct DebrisFieldConfig {
  std::string preset = "wreck";  ///< wreck (elongated piles of amphorae, a few blocks) or boulders (rounded blocks)
  uint64_t seed = 1;
  double density_per_m2 = 0.5;  ///< mean objects per square metre, averaged over piles and bare patches [0, 5]
  double site_size_m = 6.0;     ///< size of the piles-and-bare-sand pattern (metres) [1, 100]
  double min_height_m = 0.2;    ///< object heights are drawn in [min, max] (before the slope cap) (0, 2]
  double max_height_m = 0.6;
  double max_slope = 3.0;  ///< steepest side, rise over run (3: 72 degrees) [0.5, 10]
  double embed_m = 0.03;   ///< how deep the objects sit in the sediment [0, 0.2]

  /// Empty if usable, otherwise every bad field with its allowed range, separated by "; ".
  std::string validate() const;
  /// The named preset ("wreck" or "boulders") with `seed`; throws std::invalid_argument naming the allowed names.
  static DebrisFieldConfig fromPreset(const std::string& name, uint64_t seed);
};

/// One object of a debris field (ground truth for tests and evaluation).
struct DebrisObject {
  enum class Kind { kPile, kBlock };
  Kind kind = Kind::kPile;
  double x_m = 0.0, y_m = 0.0;   ///< centre (local frame, metres)
  double yaw_rad = 0.0;          ///< direction of the long axis, counter-clockwise from east
  double half_length_m = 0.0;    ///< semi-axis along yaw
  double half_width_m = 0.0;     ///< semi-axis across (the smaller one)
  double foot_m = 0.0;           ///< height of the object's foot (the base seabed at its centre, minus the embedding)
  double nominal_height_m = 0.0; ///< H: height of the profile above the foot before the slope cap
  double top_height_m = 0.0;     ///< actual height of the top above the base seabed at the centre (after the cap)
  double top_exponent = 2.0;     ///< m: 2 a rounded top, 4 a flat one
  double ramp = 1.0;             ///< k = max_slope * half_width / H: the slope cap of the profile
  cv::Vec3f tint{1.f, 1.f, 1.f}; ///< multiplies the encrustation's albedo
  double band_period_m = 0.0;    ///< piles: spacing of the darker seams between the jars (0: none)

  /// Height above the foot at (x, y) (metres); negative outside the outline.
  double profileHeight_m(double x_m, double y_m) const;
  /// 1 - q: > 0 inside the outline, 1 at the centre.
  double insideness(double x_m, double y_m) const;
};

/**
 * @brief The relief of a base seabed with a debris field on it. The base relief is owned; the objects' feet follow it.
 * Thread-safe as far as the base relief is (the procedural one and FlatRelief are).
 */
class DebrisRelief final : public SeabedRelief {
 public:
  /// @throws std::invalid_argument with config.validate()'s message, or for a null base.
  DebrisRelief(const DebrisFieldConfig& config, std::unique_ptr<SeabedRelief> base);
  ~DebrisRelief() override;

  bool isFlat() const override { return false; }
  double maxHeight_m() const override;
  double minHeight_m() const override;
  double maxSlope() const override;
  double gridSpacing_m() const override;
  TexturePatch<float> heightPatch(const WorldRect& area) override;
  double heightAt_m(double x_m, double y_m) const override;

  /// Objects whose outline may reach into `area`, in a deterministic order.
  std::vector<DebrisObject> objects(const WorldRect& area) const;
  /// The object whose surface is the top at (x, y) among `objects` (index), or -1 where the base seabed is; with
  /// `height_m`, the height there.
  int topObject(const std::vector<DebrisObject>& objects, double x_m, double y_m, double base_height_m,
                double* height_m = nullptr) const;
  SeabedRelief& base() { return *base_; }
  const DebrisFieldConfig& config() const { return config_; }

 private:
  DebrisFieldConfig config_;
  std::unique_ptr<SeabedRelief> base_;
  struct Generator;
  std::unique_ptr<Generator> generator_;
};

/**
 * @brief The albedo of a base seabed with the debris field of `relief` on it: each object shows an encrusted surface
 * (a second procedural texture, tinted: terracotta piles with darker seams between the jars, grey blocks), blended
 * into the base over one texel at its outline. Thread-safe (the textures are).
 */
class DebrisTexture final : public SeabedTexture {
 public:
  /// `relief` must outlive this texture. @throws std::invalid_argument for a null base or relief.
  DebrisTexture(std::unique_ptr<SeabedTexture> base, DebrisRelief* relief, uint64_t seed);
  ~DebrisTexture() override;

  double baseTexelSize_m() const override;
  int maxLevel() const override;
  TexturePatch<cv::Vec3f> albedoPatch(int level, const WorldRect& area) override;

 private:
  std::unique_ptr<SeabedTexture> base_;
  std::unique_ptr<SeabedTexture> encrustation_;
  DebrisRelief* relief_;
};

}  // namespace sim
}  // namespace exocet_mosaic
