/**
 * @file tile_writer_ros.h
 * @brief The tile writer's ROS bridge: camera images, their registration (/mosaic/motion), the fused pose
 * (/mosaic/odometry) and camera height (/mosaic/camera_height) in; geo-referenced GeoTIFF tiles on disk, one
 * exocet_msgs/Tile per tile, a preview of the open mosaic, tile footprints for rviz, an optional UDP datagram per
 * tile, and /diagnostics out. The composition and the files are the core libraries' (compose::MosaicComposer,
 * tiles::GeoTiffTileWriter); this class converts, synchronises and reports.
 *
 * Tiles are written by a worker thread so that a slow disk does not hold the images back; a failed write (full or
 * unwritable disk) is reported and retried, the node keeps composing; at shutdown the open mosaic is flushed.
 *
 * With ~graph_corrections_topic (the fusion's pose graph), each image is placed at its fused pose plus the graph's
 * correction at its time, and a third thread (at a lower CPU priority than the chain) draws a written tile again
 * from its kept images (tiles::renderTileAt) when the corrections have moved them by more than
 * ~rerender_threshold_gsd; the writer thread writes it as the tile's next version, removes the previous one once the
 * new one is complete, and announces it like a new tile (Tile message with its version, UDP, footprints). At
 * shutdown the tiles are brought to the last corrections received.
 *
 * With ~image_gain_compensation (and kept images, with or without the graph) the same thread solves a gain per kept
 * image over every overlap (compose::ImageGains) and draws a tile again when its images' gains changed: the levels of
 * one pass and the next, which a gain per tile cannot match along a whole tile, are matched per image.
 *
 * A run carries over restarts (tiles::TileWriterProgress): the writer saves its progress in the output folder at each
 * tile and every ~progress_period_s. An instance that finds an interrupted run there (killed, not ended normally) and
 * whose first image continues its stamps carries it on: the tile indices, the frame numbers and the counts go on,
 * the records of the tiles written before are read back (they can be drawn again by the graph or the image gains),
 * and the frames the killed instance held but had not written are counted as lost.
 */
#pragma once

#include <array>
#include <atomic>
#include <condition_variable>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <thread>

#include <diagnostic_updater/diagnostic_updater.h>
#include <dynamic_reconfigure/server.h>
#include <exocet_msgs/GeoDatum.h>
#include <exocet_msgs/ImageMotion.h>
#include <exocet_msgs/PositionCorrections.h>
#include <image_transport/image_transport.h>
#include <nav_msgs/Odometry.h>
#include <ros/ros.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/CompressedImage.h>
#include <sensor_msgs/Range.h>
#include <std_srvs/Trigger.h>

#include "exocet_mosaic/TileWriterConfig.h"
#include "exocet_mosaic/compose/mosaic_composer.h"
#include "exocet_mosaic/compose/tile_gain_compensator.h"
#include "exocet_mosaic/registration/image_undistorter.h"
#include "exocet_mosaic/ros/frame_assembler.h"
#include "exocet_mosaic/ros/keyed_throttle.h"
#include "exocet_mosaic/ros/tile_writer_parameters.h"
#include "exocet_mosaic/tiles/geotiff_tile_writer.h"
#include "exocet_mosaic/tiles/image_gain_window.h"
#include "exocet_mosaic/tiles/tile_network_adjustment.h"
#include "exocet_mosaic/tiles/tile_notifier.h"
#include "exocet_mosaic/tiles/tile_revisions.h"
#include "exocet_mosaic/tiles/tile_writer_resume.h"

namespace exocet_mosaic {

class TileWriterRos {
 public:
  /// @throws std::invalid_argument on a bad parameter (the message names it and its allowed range).
  TileWriterRos(ros::NodeHandle nh, ros::NodeHandle private_nh);
  /// Flushes the open mosaic and waits until every closed one is written.
  ~TileWriterRos();

 private:
  struct PendingTile {
    compose::ClosedMosaic mosaic;
    int attempts = 0;
    std::vector<Eigen::Vector2d> image_corrections_m;  ///< the graph correction in each image's pose (mosaic.images)
    std::optional<tiles::RevisedTile> revision;        ///< a written tile drawn again (mosaic holds its summary)
  };

  void onImage(const sensor_msgs::ImageConstPtr& msg);
  void onCompressed(const sensor_msgs::CompressedImageConstPtr& msg);
  void onMotion(const exocet_msgs::ImageMotionConstPtr& msg);
  void onOdometry(const nav_msgs::OdometryConstPtr& msg);
  void onCameraHeight(const sensor_msgs::RangeConstPtr& msg);
  void onDatum(const exocet_msgs::GeoDatumConstPtr& msg);
  void onCameraInfo(const sensor_msgs::CameraInfoConstPtr& msg);
  void onCorrections(const exocet_msgs::PositionCorrectionsConstPtr& msg);
  void onReconfigure(exocet_mosaic::TileWriterConfig& config, uint32_t level);
  bool onFlush(std_srvs::Trigger::Request& request, std_srvs::Trigger::Response& response);
  bool acceptTransport(const std::string& transport);
  void acceptImage(const std_msgs::Header& header, ImageDecoder decode, cv::Size image_size,
                   int image_channels);
  void checkClock(std::int64_t stamp_ns);
  /// Adds a part to the assembler under the lock, then composes what is ready; false (nothing done) when `add`
  /// refused the part (a late part, a repeated image).
  bool addAndProcess(const std::function<bool(double now_s)>& add);

  void processReady(std::vector<AssembledFrame> frames);
  void compose(const AssembledFrame& frame);
  void enqueue(compose::ClosedMosaic mosaic);
  /// Waits (at most kMaxWriteWaitS) until fewer than ~max_queued_tiles closed mosaics wait for the writer. Called by
  /// the composition without compose_mutex_ held (the writer takes it to save its progress).
  void waitForWriteRoom();
  /// Counts and logs the companions (COG, KMZ) a written tile lacks; write_mutex_ held.
  void noteCompanionErrorsLocked(const tiles::WrittenTile& tile);
  int tilesQueuedLocked() const;  ///< closed mosaics in write_queue_, revisions left out (they have their own bound)
  /// The closed mosaic with the graph corrections its images were placed with (pruned from used_corrections_).
  PendingTile pendingTile(compose::ClosedMosaic mosaic);
  /// Writer thread, write_mutex_ not held: keeps the new tile's images and record on disk (keep_images). With image
  /// gains, each image's gain in the record is the tile gain the tile was drawn with where the image lies (a gain
  /// commutes with the blend), so that the record draws the tile as written and lends those gains as an anchor.
  /// *levels_added: the images whose levels were added to the gain solve's (the caller counts them once the record
  /// is in records_).
  std::optional<tiles::TileRecord> keepRecord(const PendingTile& pending, const tiles::WrittenTile& tile,
                                              const tiles::GeoTiffTileWriter& writer,
                                              const std::optional<compose::TileGains>& tile_gains, int* levels_added);
  /// Writer thread, write_mutex_ not held: writes a revision, removes the previous version, announces it.
  void writeRevision(PendingTile& pending, tiles::GeoTiffTileWriter* writer, std::unique_lock<std::mutex>& lock);
  void rerenderLoop();
  /// Draws again the written tiles the corrections moved (every tile: all of them, with the lighting field as it is
  /// now) and queues them for the writer; returns how many.
  int rerenderDue(bool every_tile = false);
  /// Waits until the writer holds fewer than kMaxQueuedRevisions drawn tiles. @return false when the writer stops,
  /// or (interruptible) when the rerender thread is asked to stop.
  bool waitForRevisionRoom(bool interruptible);
  static constexpr long kMaxQueuedRevisions = 2;
  /// Rerender thread: solves the images' gains when images were added since the last solve (or `always`) at their
  /// current placements and the lighting given, into intended_gains_ for the tiles it took.
  void solveImageGains(const compose::LightingCorrector& lighting, bool always);
  /// Rerender thread: the gain an image of a tile is to be drawn with: the last solve that took the tile's (1 for an
  /// image it left without a gain) until a drawing with it is on disk, otherwise the one its version was drawn with.
  std::array<double, 3> intendedGain(int tile, const tiles::RecordedImage& image) const;
  /// Rerender thread: the levels of those kept images that are not in image_gains_, read from their files
  /// (`new_images`: counted as added, so that the gains are solved again). @return how many were read; `unreadable`
  /// (optional) counts the files that could not be
  int readKeptLevels(const std::vector<std::string>& files, bool new_images, int* unreadable);
  /// Rerender thread: marks the window's tiles used and drops the levels of the tiles least recently used beyond
  /// ~image_gain_levels_cache_tiles (but not those of `window_files`).
  void letGoOfLevels(const tiles::GainWindow& window, const std::set<std::string>& window_files);
  void saveCorrections();
  /// <images_dir_>/<prefix>_NNNN.json, atomically; a failure is logged (the tile stays, not its redrawing).
  void saveRecord(const tiles::TileRecord& record, const tiles::GeoTiffTileWriter& writer);
  /// Waits until the writer thread has nothing queued nor in hand, at most timeout_s.
  void waitWriterIdle(double timeout_s);
  /// Rewrites <output_dir>/<prefix>_mosaic.vrt (mosaic_vrt) when tiles changed, at most every 2 s unless `now`.
  void updateMosaicVrt(bool now);
  /// Registers the written tiles with each other and adds each one's move to its record (the next look draws them
  /// again); nothing while a tile waits to be written. Returns how many tiles it adjusted.
  int adjustWrittenTiles();
  void flushAll(const std::string& reason);
  void writerLoop();
  void publishTile(const tiles::WrittenTile& tile, const compose::ClosedMosaic& mosaic);
  void publishFootprints();
  void publishPreview();
  void onTimer();
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& status);
  /// Why no tile was written, in one line (empty when one was).
  std::string noTileReason();
  /// <output_dir>/run_summary.json: tiles written, images received and composed, and noTileReason(); logged as an
  /// error when no tile was written. Called once the writer thread has stopped.
  void writeRunSummary();
  void reject(const std::string& why);

  // A run carried over restarts.
  /// Reads the progress an earlier instance left in the output folder (and, for an interrupted run, its tiles'
  /// records) at start-up.
  void loadPreviousRun();
  /// At the first image: carries the interrupted run on, or starts a new one, and says which.
  void decideRun(double first_stamp_s);
  /// Takes the interrupted run's counts and frame numbers (and, with `adopt_tiles`, its tiles' records) as this
  /// instance's starting point.
  void continueRun(const tiles::TileWriterProgress& previous, bool adopt_tiles);
  /// Writes the run's progress (tiles::tileWriterProgressPath) atomically; `finished` at a normal end.
  void saveProgress(bool finished);
  /// Frames received but in no tile on disk (write_mutex_ held); `next_frame` is the index the next image takes.
  int framesNotOnDiskLocked(int next_frame) const;
  /// Rerender thread: the levels of the kept images of a continued run, for the image gains.
  void loadKeptImageLevels();

  ros::NodeHandle nh_, private_nh_;
  TileWriterNodeConfig config_;
  image_transport::ImageTransport image_transport_;
  image_transport::Subscriber raw_sub_;
  image_transport::Publisher preview_pub_;
  ros::Subscriber compressed_sub_, motion_sub_, odometry_sub_, height_sub_, datum_sub_, camera_info_sub_;
  ros::Publisher tile_pub_, footprints_pub_;
  ros::ServiceServer flush_srv_;
  ros::SteadyTimer timer_, diagnostics_timer_;
  ros::SteadyTimer free_heap_timer_;
  static constexpr double kFreeHeapPeriod_s = 10.0;
  diagnostic_updater::Updater updater_;
  std::unique_ptr<dynamic_reconfigure::Server<exocet_mosaic::TileWriterConfig>> reconfigure_server_;
  boost::recursive_mutex reconfigure_mutex_;  // dynamic_reconfigure wants a boost mutex

  // Composition (callback thread; the mutex guards it against dynamic_reconfigure's thread and the destructor).
  std::mutex compose_mutex_;
  compose::MosaicComposer composer_;
  FrameAssembler assembler_;
  std::string active_transport_;
  std::optional<std::int64_t> newest_stamp_ns_;
  std::optional<std::int64_t> last_composed_stamp_ns_;
  std::atomic<int> next_frame_index_{0};     ///< frames are numbered across the run's instances
  std::vector<double> tile_fused_sigmas_m_;  ///< fused 1-sigma of the open mosaic's images (m)
  sensor_msgs::CameraInfoConstPtr camera_info_;
  // Shared with the loaders of images not decoded yet (the composer may decode one after a calibration change).
  // Element i undistorts the images decoded at 1/2^i (i = 0..3: reductions 1, 2, 4, 8), all made from one calibration.
  using Undistorters = std::array<std::shared_ptr<const registration::ImageUndistorter>, 4>;
  std::shared_ptr<const Undistorters> undistorters_;
  std::optional<int> utm_zone_;
  bool northern_ = true;
  /// The fused poses' frame when it is not the UTM frame (~frame_id): the dive is not geo-referenced and the tiles are
  /// written in that local metric frame. Guarded by write_mutex_.
  std::string local_frame_;
  std::optional<Eigen::Vector2d> map_origin_en_m_;
  ros::WallTime last_input_wall_;
  ros::WallTime last_preview_wall_;  // per instance: several tile writers (nodelets) can share a process
  bool received_input_ = false;
  bool shutting_down_ = false;

  // Writing (worker thread).
  std::mutex write_mutex_;
  std::condition_variable write_cv_;
  std::deque<PendingTile> write_queue_;
  std::deque<PendingTile> failed_tiles_;
  bool stop_writer_ = false;
  bool writing_ = false;  ///< the worker is writing a tile (the queue may be empty meanwhile)
  bool last_write_failed_ = false;
  std::thread writer_thread_;
  std::unique_ptr<tiles::GeoTiffTileWriter> writer_;
  std::optional<tiles::TileWriterConfig> files_update_;  ///< from dynamic_reconfigure, for the next write
  std::unique_ptr<tiles::TileNotifier> notifier_;
  compose::TileGainCompensator gains_;       ///< writer thread only
  std::string last_gain_note_;               ///< the last tile's gain correction, for /diagnostics (write_mutex_)
  std::vector<tiles::WrittenTile> written_;  ///< for the footprints (bounded)
  std::vector<std::array<Eigen::Vector2d, 4>> written_outlines_;

  // Tiles that follow the pose graph.
  ros::Subscriber corrections_sub_;
  std::string images_dir_;  ///< <output_dir>/.exocet_images (keep_images)
  std::mutex corrections_mutex_;
  tiles::PositionCorrectionTrack corrections_;
  /// The graph's 1-sigma with the latest corrections: key frame stamp (s) -> (east m, north m, correlation); saved
  /// beside the corrections for the checks made after the dive (corrections_mutex_).
  std::map<double, std::array<double, 3>> correction_sigmas_;
  std::int64_t corrections_received_ = 0, corrections_saved_ = 0;
  std::map<int, Eigen::Vector2d> used_corrections_;  ///< frame index -> correction added to its pose (compose thread)
  std::map<int, tiles::TileRecord> records_;         ///< written tiles by index (write_mutex_)
  std::set<int> revision_pending_;                   ///< tiles drawn again, not written yet (write_mutex_)
  std::map<int, std::int64_t> revision_failed_at_;   ///< tile -> corrections_received_ when drawing it failed
  std::mutex rerender_mutex_;
  std::condition_variable rerender_cv_;
  bool stop_rerender_ = false;
  std::thread rerender_thread_;
  std::int64_t tiles_rerendered_ = 0, rerender_failures_ = 0, images_kept_ = 0, images_not_kept_ = 0;
  double last_rerender_ms_ = 0, max_tile_move_m_ = 0;
  std::string last_rerender_problem_;
  bool tiles_changed_since_adjustment_ = false;  ///< write_mutex_
  bool vrt_stale_ = false;                       ///< writer thread
  ros::WallTime last_vrt_wall_;
  std::int64_t tile_adjustments_ = 0;
  /// The tile pairs measured by the registrations of the tiles with each other: each registers only the pairs with a
  /// tile drawn since (rerender thread; the destructor's after it stops).
  tiles::TilePairCache tile_pairs_;
  std::int64_t tile_pairs_measured_ = 0, tile_pairs_reused_ = 0;  ///< (write_mutex_)
  double last_adjustment_pair_max_px_ = 0;
  bool redraws_ = false;  ///< the rerender thread runs (graph corrections, or image gains)
  // Gains of the kept images.
  std::mutex image_gains_mutex_;
  compose::ImageGains image_gains_;        ///< levels of the kept images (image_gains_mutex_)
  std::int64_t image_levels_added_ = 0;    ///< (image_gains_mutex_)
  std::int64_t image_levels_solved_ = -1;  ///< rerender thread
  /// Per tile, by image file, the gains the last solve that took the tile gave its images, kept until the tile's
  /// version on disk is drawn with them, so that a tile that leaves the window before it is drawn again still is,
  /// and lends them as an anchor meanwhile (rerender thread).
  std::map<int, std::map<std::string, std::array<double, 3>>> intended_gains_;
  std::unique_ptr<tiles::TileLevelsCache> levels_cache_;   ///< tiles whose levels are in image_gains_ (rerender thread)
  std::int64_t levels_read_back_ = 0, levels_let_go_ = 0;  ///< images' levels (write_mutex_)
  compose::ImageGainSolution last_image_gains_;            ///< its figures, gains left out (write_mutex_)
  double last_image_gain_ms_ = 0;                          ///< (write_mutex_)
  std::int64_t image_gain_solves_ = 0, tiles_redrawn_for_gains_ = 0;  ///< (write_mutex_)

  // A run carried over restarts.
  std::optional<tiles::TileWriterProgress> previous_run_;  ///< found in the folder at start-up
  tiles::KeptTiles kept_tiles_;                            ///< the interrupted run's records, until decideRun()
  std::atomic<bool> run_decided_{false};
  std::string run_note_;                ///< new run or continued, and why (callback thread)
  tiles::TileWriterProgress run_base_;  ///< counts of the run's earlier instances (write_mutex_)
  int frames_lost_at_restart_ = -1;     ///< -1: this instance did not carry a run on (write_mutex_)
  int newest_frame_on_disk_ = -1;       ///< last frame of the newest tile written (write_mutex_)
  std::atomic<double> newest_image_stamp_s_{0.0};
  std::mutex progress_mutex_;  ///< one progress write at a time (writer thread and timer)
  ros::WallTime last_progress_wall_;
  std::int64_t progress_images_ = -1;        ///< images_ at the last progress save (timer)
  std::int64_t progress_failures_ = 0;       ///< (progress_mutex_)
  std::string last_progress_error_;          ///< (progress_mutex_)
  std::vector<std::string> levels_to_load_;  ///< kept images whose levels the gains need (image_gains_mutex_)
  std::set<std::string> levels_unreadable_;  ///< kept images whose file could not be read (image_gains_mutex_)

  // Counters for /diagnostics.
  std::atomic<std::int64_t> images_{0};
  std::int64_t frames_composed_calls_ = 0, rejected_ = 0, clock_jumps_ = 0;
  std::int64_t poses_ = 0, camera_heights_ = 0;  ///< fused poses and camera heights received
  std::int64_t tiles_written_ = 0, write_failures_ = 0, tiles_dropped_ = 0, udp_failures_ = 0;
  std::int64_t composition_waits_ = 0;  ///< times the composition waited for the writer (write_mutex_)
  double composition_wait_s_ = 0.0;     ///< wall time it waited (write_mutex_)
  int tiles_queued_max_ = 0;            ///< most closed mosaics that waited for the writer at once (write_mutex_)
  std::string last_problem_, last_write_error_;
  std::int64_t companion_failures_ = 0;  ///< COG / KMZ files left out of a written tile (write_mutex_)
  bool last_tile_lacks_companion_ = false;  ///< the newest tile written lacks one (write_mutex_)
  std::string last_companion_error_;        ///< (write_mutex_)
  KeyedThrottle reject_log_{5.0};  ///< callback thread
};

}  // namespace exocet_mosaic
