/**
 * @file tile_writer_parameters.h
 * @brief Parameters of tile_writer_node (read from its private namespace, each validated with its allowed range).
 * config/tiles/README.md lists them.
 */
#pragma once

#include <string>

#include <ros/node_handle.h>

#include "exocet_mosaic/compose/composer_config.h"
#include "exocet_mosaic/tiles/geotiff_tile_writer.h"
#include "exocet_mosaic/tiles/tile_revisions.h"

namespace exocet_mosaic {

struct TileWriterNodeConfig {
  compose::ComposerConfig composer;
  tiles::TileWriterConfig files;  ///< output_dir is required

  // Inputs.
  std::string image_topic = "/camera/image_raw";
  std::string transport = "auto";  ///< raw | compressed | auto (the first that delivers)
  /// Subscriber queue of the images [1, 1000] (the motions, poses and heights get at least 500): a replay's images
  /// wait here while a burst of key frames (a U-turn) is composed.
  int queue_size = 200;
  std::string camera_info_topic;  ///< default: next to image_topic
  std::string motion_topic = "/mosaic/motion";
  std::string odometry_topic = "/mosaic/odometry";
  std::string camera_height_topic = "/mosaic/camera_height";
  std::string datum_topic = "/mosaic/datum";
  int utm_zone = 0;  ///< 0: from datum_topic; otherwise this zone (1..60)
  bool northern_hemisphere = true;
  bool undistort = true;  ///< undistort the colour images as the registration did (when it says it did)

  // Outputs.
  std::string tile_topic = "/mosaic/tile";
  std::string preview_topic = "/mosaic/preview";
  std::string footprints_topic = "/mosaic/tile_footprints";
  std::string frame_id = "utm";   ///< frame of the footprints and tiles
  std::string map_frame = "map";  ///< markers are drawn in this frame when map_origin is known (rviz: single precision)
  double preview_period_s = 1.0;
  int preview_max_side_px = 800;
  std::string dive_name;
  std::string udp_host;  ///< empty: no UDP notification
  int udp_port = 0;
  /// Local address the UDP socket is bound to: loopback unless set to the station's address on the GIS's network.
  std::string udp_bind_address = "127.0.0.1";

  // Synchronisation and life cycle.
  double sync_timeout_s = 10.0;  // the chain may lag behind the images by seconds on a replay
  int max_pending_frames = 300;
  double clock_jump_s = 1.0;      ///< an image older than the newest by this much restarts the mosaic (bag loop)
  double exit_when_idle_s = 0;    ///< > 0: flush and shut down after this many wall seconds without input (replays)
  int max_failed_tiles_kept = 2;  ///< closed mosaics kept in memory for a retry after a write failure
  /// Closed mosaics waiting for the writer. Beyond, the composition waits for it: the images wait in the subscriber's
  /// queue as compressed messages (or are dropped there) instead of the node's memory growing with the backlog.
  int max_queued_tiles = 4;
  double retry_period_s = 10.0;
  /// An interrupted run left in the output folder is carried on when the first image comes at most this much after its
  /// newest image (s, (0, 1e6]); see tiles::continuationRefusal.
  double resume_max_gap_s = 600.0;
  double progress_period_s = 1.0;  ///< wall seconds between two saves of the run's progress, (0, 60]
  // Tiles that follow the pose graph.
  /// exocet_msgs/PositionCorrections of the fusion's pose graph; empty: the tiles stay as written. When set, each
  /// image is placed at the fused pose plus the graph's correction at its time, and a written tile is drawn again
  /// (a new version) when the corrections move its images by more than rerender_threshold_gsd.
  std::string graph_corrections_topic;
  double rerender_threshold_gsd = 0.5;  ///< in ground sample distances, [0.05, 1000]
  double rerender_period_s = 1.0;       ///< wall seconds between two looks at the written tiles, [0.05, 600]
  /// How a tile drawn again places its images (tiles::placementsAt); ~revision_follows_heading sets
  /// content_follows_heading.
  tiles::RevisionConfig revision;
  /// With graph_corrections_topic: at most this often (wall s, [1, 3600]) and when tiles changed, the written tiles
  /// are registered with their overlapping neighbours (tiles::measureAndSolve, as adjust_tiles) and each moved by one
  /// similarity on top of the graph's placement; 0 turns it off.
  double tile_adjustment_period_s = 10.0;
  /// Keep each tile's images (as drawn, JPEG) and its record in <output_dir>/.exocet_images/, for the tiles drawn
  /// again and recompose_tiles after the dive. Forced on by graph_corrections_topic.
  bool keep_images = true;
  int kept_image_quality = 95;  ///< JPEG quality of the kept images, [50, 100]
  /// Gains of each new tile matched to the tiles already written where they overlap (compose::TileGainCompensator);
  /// a tile drawn again keeps its gains.
  bool gain_compensation = true;
  /// With keep_images: a gain per kept image and channel solved over all their overlaps in the background
  /// (compose::ImageGains, every rerender_period_s when images were added); a written tile is drawn again (a new
  /// version) when its images' gains changed by more than image_gain_redraw_change, and a tile drawn again then takes
  /// its images' gains instead of a tile gain.
  bool image_gain_compensation = true;
  double image_gain_redraw_change = 0.01;  ///< relative change of an image's gain, [0.001, 1]
  /// Tiles whose images' gains each solve takes, the newest, [0, 100000]; the older tiles they overlap are anchors
  /// (their images keep the gains they were drawn with, a first version's tile gain included), the others stay as
  /// drawn: the solve's time and memory do not grow with the dive (tiles::gainWindow). 0: every tile at each solve,
  /// whose levels and working set grow with the dive.
  int image_gain_window_tiles = 24;
  /// Tiles whose image levels stay in memory, the most recently used, [1, 100000]; the others are read back from the
  /// kept images when a solve takes them again. Not used with image_gain_window_tiles 0.
  int image_gain_levels_cache_tiles = 48;
  /// <output_dir>/<prefix>_mosaic.vrt: a GDAL virtual mosaic over the newest version of every tile (one layer for a
  /// GIS), rewritten atomically at most every 2 s as tiles are written or drawn again, and at shutdown.
  bool mosaic_vrt = true;
};

/// @throws std::invalid_argument naming the parameter, its value and its allowed range.
TileWriterNodeConfig readTileWriterNodeConfig(const ros::NodeHandle& private_nh);

}  // namespace exocet_mosaic
