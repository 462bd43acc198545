/**
 * @file composer_config.h
 * @brief Parameters of the mosaic composer (placement, closing, blending, lighting). validate() lists the allowed
 * ranges. No ROS in it.
 */
#pragma once

#include <string>

#include "exocet_mosaic/compose/lighting_corrector.h"

namespace exocet_mosaic {
namespace compose {

/// Parameters of MosaicComposer. Fields marked (geometric) take effect from the next mosaic on setConfig().
struct ComposerConfig {
  int frames_per_mosaic = 100;  ///< images added to a mosaic before it is closed, [2, 100000]
  /// (geometric) Pixel size of the mosaics (m), 0 or [1e-4, 100]; 0: the native GSD of each mosaic's first image
  /// (height / focal) rounded DOWN to 1, 2 or 5 x 10^k m.
  double gsd_m = 0.0;
  double max_extent_m = 100.0;   ///< close when the mosaic's east or north extent reaches this, [0.1, 100000]
  double max_memory_mb = 512.0;  ///< close when the open mosaic holds this much, [1, 1000000]
  /// Close ("navigation_jump") when a fused position departs from the chain's prediction by more than
  /// max(navigation_jump_min_m, navigation_jump_sigma * sigma of that difference). [1, 1000]
  double navigation_jump_sigma = 5.0;
  double navigation_jump_min_m = 1.0;  ///< [0, 100000]
  /// Consecutive images that must depart before it is a jump, [1, 1000]; the departing ones before stay in the
  /// mosaic, placed by the chain, and out of the fit (a single outlying fix does not cut the mosaic).
  int navigation_jump_confirm_frames = 3;
  std::string blend = "feather";       ///< "feather" | "multiband" | "none"
  double feather_power = 1.0;          ///< exponent of the feather weights, [0.1, 10]
  int multiband_bands = 5;             ///< pyramid levels of the multi-band blender, [1, 10]
  /// Compose an image only when its footprint moved by more than this fraction of the image's smaller side since the
  /// last composed image, [0, 1] (0: every image).
  double min_key_frame_shift_fraction = 0.1;
  /// Images are composed at 1/r of their resolution, r the largest power of two up to this ({1, 2, 4, 8}) with
  /// native GSD x r <= gsd_m: a 4K image at 0.75 mm drawn into 5 mm tiles is composed at 3 mm (r = 4), 1/16 of its
  /// pixels, instead of being sampled at 6.7 px per tile px (which aliases). 1: always at full resolution; with
  /// gsd_m 0 (native) r is 1. r changes only when the native GSD leaves a 10 % band around its bounds (altitude).
  int max_image_reduction = 8;
  /// Hand the composed images out with the closed mosaic (ClosedMosaic::images), for tiles drawn again later at other
  /// poses; they count in the open mosaic's memory.
  bool keep_composed_images = false;
  std::string anchor = "similarity";  ///< (geometric) local -> UTM fit: "similarity" | "translation"
  /// (geometric) Prior sigma of the fit's scale change and rotation (dimensionless / rad), [1e-6, 10]: the chain's
  /// scale and heading come from the first pose (altitude ~1-2 %, heading ~1 deg); over a tile shorter than a few
  /// metres the navigation noise determines them worse than that, and a free rotation would tilt the tile's ends.
  double anchor_prior_sigma = 0.02;
  /// (geometric) The next mosaic's fit follows where the closed one put their shared image within this slack (m),
  /// [0, 1000]: consecutive tiles stay aligned (no seam) while the navigation pulls the chain of tiles slowly, by
  /// 4 slack^2 / (4 slack^2 + sigma^2) of their disagreement per tile (sigma: the fused 1-sigma; a tile's images
  /// count as navigation_samples_per_mosaic independent fused positions), i.e. over about (sigma / 2 slack)^2 tiles. Large values make tiles
  /// independent.
  double tile_continuity_sigma_m = 0.005;
  /// (geometric) How many independent fused positions a mosaic's images are worth in the fit, [1, 10000]: the fused
  /// errors are correlated over seconds (a filter's), so N images are not N measurements. Fewer: the navigation moves
  /// the tiles less at their seams (PAL bench dive, consecutive tiles 0.9 px apart with 1, 1.4 px with 4, 1.9 px
  /// with 8) but corrects the chain's scale more slowly (HD bench dive landmarks: 15.5 mm median with 1, 10.8 with 4,
  /// 8.6 with 8).
  double navigation_samples_per_mosaic = 4.0;
  /// Rotation/scale of the fit are applied by resampling only if they move the tile's corners by more than this
  /// (px), [0, 1000]; otherwise only the origin moves (no resampling blur).
  double resample_threshold_px = 0.25;
  int block_size_px = 256;  ///< (geometric) side of the canvas blocks, [16, 4096]
  LightingConfig lighting;  ///< lighting correction

  /// Empty if usable, otherwise every bad field with its allowed range, separated by "; ".
  std::string validate() const;
};

}  // namespace compose
}  // namespace exocet_mosaic
