#include "exocet_mosaic/tiles/closed_mosaic_tile.h"

namespace exocet_mosaic {
namespace tiles {

TileRaster tileRaster(const compose::ClosedMosaic& mosaic, int utm_zone, bool northern,
                      const std::string& local_frame) {
  TileRaster raster;
  raster.image = mosaic.image;
  raster.mask = mosaic.mask;
  raster.origin_easting_m = mosaic.origin_easting_m;
  raster.origin_northing_m = mosaic.origin_northing_m;
  raster.gsd_m = mosaic.gsd_m;
  raster.utm_zone = utm_zone;
  raster.northern_hemisphere = northern;
  raster.local_frame = local_frame;
  return raster;
}

TileMetadata tileMetadata(const compose::ClosedMosaic& mosaic, const std::string& dive_name) {
  TileMetadata metadata;
  metadata.dive_name = dive_name;
  metadata.first_frame = mosaic.first_frame;
  metadata.last_frame = mosaic.last_frame;
  metadata.start_time_s = mosaic.start_time_s;
  metadata.end_time_s = mosaic.end_time_s;
  metadata.mean_altitude_m = mosaic.mean_camera_height_m;
  metadata.close_reason = mosaic.close_reason;
  metadata.extra["frames_composed"] = std::to_string(mosaic.frames_composed);
  metadata.extra["position_sigma_m"] = std::to_string(mosaic.anchor_sigma_m);
  metadata.extra["blend"] = mosaic.blend;
  return metadata;
}

}  // namespace tiles
}  // namespace exocet_mosaic
