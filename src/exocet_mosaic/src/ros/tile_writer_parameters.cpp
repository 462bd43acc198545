#include "exocet_mosaic/ros/tile_writer_parameters.h"

#include <stdexcept>

#include <image_transport/camera_common.h>

#include "exocet_common/ros/parameter_reader.h"

namespace exocet_mosaic {

namespace {

void readComposer(const exocet_common::ParameterReader& p, compose::ComposerConfig* c) {
  p.readInt("frames_per_mosaic", &c->frames_per_mosaic, 2, 100000, "images per mosaic before it is closed");
  p.readDouble("gsd_m", &c->gsd_m, 0.0, 100.0,
               "pixel size of the tiles (m), 0: native, rounded down to a preferred number (ISO 3 R'10)");
  p.readDouble("max_extent_m", &c->max_extent_m, 0.1, 100000.0, "east or north extent that closes a mosaic (m)");
  p.readDouble("max_memory_mb", &c->max_memory_mb, 1.0, 1000000.0, "memory of the open mosaic that closes it (MB)");
  p.readDouble("navigation_jump_sigma", &c->navigation_jump_sigma, 1.0, 1000.0,
               "navigation jump, in sigmas of the chain's prediction, that closes a mosaic");
  p.readDouble("navigation_jump_min_m", &c->navigation_jump_min_m, 0.0, 100000.0,
               "smallest navigation jump that closes a mosaic (m)");
  p.readInt("navigation_jump_confirm_frames", &c->navigation_jump_confirm_frames, 1, 1000,
            "consecutive images departing from the chain before it is a navigation jump");
  p.readString("blend", &c->blend, {"feather", "multiband", "none"}, "blending of overlapping images");
  p.readDouble("feather_power", &c->feather_power, 0.1, 10.0, "exponent of the feathering weights");
  p.readInt("multiband_bands", &c->multiband_bands, 1, 10, "pyramid levels of the multi-band blender");
  p.readDouble("min_key_frame_shift_fraction", &c->min_key_frame_shift_fraction, 0.0, 1.0,
               "footprint shift (fraction of the image) between composed images, 0: every image");
  p.readInt("max_image_reduction", &c->max_image_reduction, 1, 8,
            "largest factor (1, 2, 4 or 8) by which images are reduced to be composed at about the tiles' GSD");
  p.readString("anchor", &c->anchor, {"similarity", "translation"}, "fit of the chain to the fused navigation");
  p.readDouble("tile_continuity_sigma_m", &c->tile_continuity_sigma_m, 0.0, 1000.0,
               "how strongly a tile is tied to the previous one where they share an image (m)");
  p.readDouble("navigation_samples_per_mosaic", &c->navigation_samples_per_mosaic, 1.0, 10000.0,
               "independent fused positions a mosaic's images are worth in its placement");
  p.readBool("lighting/enabled", &c->lighting.enabled,
             "correct the lamp cone and vignetting estimated from the images");
  p.readInt("lighting/warmup_frames", &c->lighting.warmup_frames, 1, 100000, "images averaged before correcting");
  p.readInt("lighting/memory_frames", &c->lighting.memory_frames, 1, 10000000,
            "time constant of the lighting field's running average (images)");
  p.readDouble("lighting/max_gain", &c->lighting.max_gain, 1.0, 100.0, "largest correction gain");
  const std::string error = c->validate();
  if (!error.empty()) throw std::invalid_argument("tile writer parameters: " + error);
}

void readFiles(const exocet_common::ParameterReader& p, tiles::TileWriterConfig* c) {
  p.readOptionalString("output_dir", &c->output_dir, "folder of the GeoTIFF tiles (must exist)");
  if (c->output_dir.empty())
    throw std::invalid_argument("parameter ~output_dir is required: the folder where the tiles are written");
  p.readOptionalString("prefix", &c->prefix, "file name prefix of the tiles");
  p.readString("compression", &c->compression, {"DEFLATE", "LZW", "JPEG", "NONE"}, "GeoTIFF compression");
  p.readInt("block_size_px", &c->block_size_px, 16, 4096, "GeoTIFF internal tile side (multiple of 16)");
  p.readBool("write_world_file", &c->write_world_file, "write a .tfw world file beside each GeoTIFF");
  p.readBool("write_cog", &c->write_cog, "also write a Cloud Optimized GeoTIFF copy");
  p.readBool("write_kmz", &c->write_kmz, "also write a KMZ for Google Earth");
  p.readInt("kmz_max_side_px", &c->kmz_max_side_px, 256, 32768, "largest side of the KMZ raster");
  const std::string error = c->validate();
  if (!error.empty()) throw std::invalid_argument("tile writer parameters: " + error);
}

}  // namespace

TileWriterNodeConfig readTileWriterNodeConfig(const ros::NodeHandle& private_nh) {
  TileWriterNodeConfig c;
  const exocet_common::ParameterReader p(private_nh);
  readComposer(p, &c.composer);
  readFiles(p, &c.files);
  p.readTopic("image_topic", &c.image_topic);
  p.readString("transport", &c.transport, {"auto", "raw", "compressed"},
               "image topic: raw (image_transport), compressed (<image_topic>/compressed) or auto");
  p.readInt("queue_size", &c.queue_size, 1, 1000, "images waiting to be composed");
  c.camera_info_topic = image_transport::getCameraInfoTopic(c.image_topic);
  p.readTopic("camera_info_topic", &c.camera_info_topic);
  p.readTopic("motion_topic", &c.motion_topic);
  p.readTopic("odometry_topic", &c.odometry_topic);
  p.readTopic("camera_height_topic", &c.camera_height_topic);
  p.readTopic("datum_topic", &c.datum_topic);
  p.readInt("utm_zone", &c.utm_zone, 0, 60, "UTM zone of the tiles, 0: from the datum topic");
  p.readBool("northern_hemisphere", &c.northern_hemisphere, "hemisphere of ~utm_zone");
  p.readBool("undistort", &c.undistort, "undistort the images as the registration did");
  p.readTopic("tile_topic", &c.tile_topic);
  p.readTopic("preview_topic", &c.preview_topic);
  p.readTopic("footprints_topic", &c.footprints_topic);
  p.readOptionalString("frame_id", &c.frame_id, "UTM frame of the tiles");
  p.readOptionalString("map_frame", &c.map_frame, "frame of the rviz markers (map origin from the datum)");
  p.readDouble("preview_period_s", &c.preview_period_s, 0.0, 3600.0, "period of the preview image, 0: none");
  p.readInt("preview_max_side_px", &c.preview_max_side_px, 64, 8192, "largest side of the preview image");
  p.readOptionalString("dive_name", &c.dive_name, "dive name written into the tiles' metadata");
  p.readOptionalString("udp_host", &c.udp_host, "host of the GIS to notify by UDP, empty: none");
  p.readInt("udp_port", &c.udp_port, 0, 65535, "UDP port of the GIS notification");
  p.readOptionalString("udp_bind_address", &c.udp_bind_address,
                       "local address of the UDP socket (loopback: this computer only), empty: the system's choice");
  if (!c.udp_host.empty() && c.udp_port == 0)
    throw std::invalid_argument("parameter ~udp_port must be in [1, 65535] when ~udp_host is set");
  p.readPositiveDouble("sync_timeout_s", &c.sync_timeout_s, 600.0,
                       "wall seconds an image waits for its motion, pose and height");
  p.readInt("max_pending_frames", &c.max_pending_frames, 1, 100000, "images waiting for their motion and pose");
  p.readPositiveDouble("clock_jump_s", &c.clock_jump_s, 1e6, "backward stamp jump that restarts the mosaic (s)");
  p.readDouble("exit_when_idle_s", &c.exit_when_idle_s, 0.0, 1e6,
               "flush and shut down after this many wall seconds without input, 0: never");
  p.readInt("max_failed_tiles_kept", &c.max_failed_tiles_kept, 0, 100, "closed mosaics kept for a write retry");
  p.readInt("max_queued_tiles", &c.max_queued_tiles, 1, 100,
            "closed mosaics waiting to be written before the composition waits for the writer");
  p.readPositiveDouble("retry_period_s", &c.retry_period_s, 3600.0, "period of write retries (s)");
  p.readPositiveDouble("resume_max_gap_s", &c.resume_max_gap_s, 1e6,
                       "an interrupted run is carried on when the first image comes at most this much after it (s)");
  p.readPositiveDouble("progress_period_s", &c.progress_period_s, 60.0,
                       "wall seconds between two saves of the run's progress");
  p.readOptionalString("graph_corrections_topic", &c.graph_corrections_topic,
                       "pose graph corrections to follow (exocet_msgs/PositionCorrections), empty: none");
  p.readDouble("rerender_threshold_gsd", &c.rerender_threshold_gsd, 0.05, 1000.0,
               "image move (ground sample distances) that makes a written tile drawn again");
  p.readDouble("rerender_period_s", &c.rerender_period_s, 0.05, 600.0, "wall seconds between looks at the tiles");
  p.readBool("revision_follows_heading", &c.revision.content_follows_heading,
             "a tile drawn again turns its images to their poses' headings (false: the chain's orientation)");
  p.readDouble("tile_adjustment_period_s", &c.tile_adjustment_period_s, 0.0, 3600.0,
               "wall seconds between registrations of the written tiles with each other, 0: none");
  if (c.tile_adjustment_period_s > 0.0 && c.tile_adjustment_period_s < 1.0)
    throw std::invalid_argument("parameter ~tile_adjustment_period_s must be 0 or in [1, 3600]");
  p.readBool("keep_images", &c.keep_images, "keep the tiles' images for drawing them again");
  p.readInt("kept_image_quality", &c.kept_image_quality, 50, 100, "JPEG quality of the kept images");
  p.readBool("gain_compensation", &c.gain_compensation, "match each new tile's gains to the written tiles");
  p.readBool("image_gain_compensation", &c.image_gain_compensation,
             "solve a gain per kept image over all overlaps and draw the tiles again with them");
  p.readDouble("image_gain_redraw_change", &c.image_gain_redraw_change, 0.001, 1.0,
               "relative change of an image's gain that makes its tile drawn again");
  p.readInt("image_gain_window_tiles", &c.image_gain_window_tiles, 0, 100000,
            "newest tiles whose images' gains each solve takes (0: every tile)");
  p.readInt("image_gain_levels_cache_tiles", &c.image_gain_levels_cache_tiles, 1, 100000,
            "tiles whose image levels stay in memory");
  p.readBool("mosaic_vrt", &c.mosaic_vrt, "keep a GDAL virtual mosaic over the newest tiles");
  if (!c.graph_corrections_topic.empty()) c.keep_images = true;
  if (!c.keep_images) c.image_gain_compensation = false;  // the gains draw the kept images
  c.composer.keep_composed_images = c.keep_images;
  return c;
}

}  // namespace exocet_mosaic
