/**
 * @file web_map.h
 * @brief The web map of a dive: its site folder (the page, web tiles cut from the GeoTIFF mosaic tiles, the state
 * files), kept up to date by a worker thread as tiles are written and the vehicle moves, with the live events for
 * the pages watching. No ROS in it: the ROS layer (ros/web_map_ros.h) feeds it messages, a command-line tool a
 * finished dive's folder.
 *
 * Site folder (config site_dir):
 * - index.html, web_map.js, geo.js, web_map.css, leaflet/: the page (site_assets.h);
 * - tiles/<z>/<x>/<y>.png: the web tiles (tiles/web_tile_cutter.h);
 * - state.json: the whole state (tiles and their metadata, web tiles of the finest level, track, USBL fixes,
 *   vehicle, datum, zoom levels), the same as the server's /state.json; state.js: the same as a script setting
 *   window.EXOCET_STATE, for a page opened from disk (file://, where a page may not fetch JSON);
 * - tiles.json (the GeoTIFF tiles, with what a restart needs to know which are already cut), track.json (the track
 *   and USBL fixes);
 * - mosaic.gpkg (GeoPackage, for QGIS) and, if wanted, mosaic.mbtiles, at shutdown (tiles/tile_packages.h).
 * Every file is replaced atomically, rewritten at most every state_period_s while something changed, and at
 * shutdown.
 *
 * At start() the site adopts the web tiles a previous run cut from the same GeoTIFFs (tiles.json: same name,
 * version, size, modification time, zoom levels), and queues the GeoTIFFs of tiles_dir that are new or changed: a
 * restarted node, or one pointed at a finished dive's folder, rebuilds what is missing only. The track comes back
 * from track.json, else from tiles_dir/fused_track.csv (the fusion's, in the tiles' UTM zone). queueUnseenGeoTiffs()
 * finds the GeoTIFFs written since without a message (a node restarted, or not yet connected to the tile writer).
 */
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "exocet_web/server/event_stream.h"
#include "exocet_web/tiles/web_tile_cutter.h"

namespace exocet_web {
namespace site {

/// Settings of the web map. validate() lists the allowed values.
struct WebMapConfig {
  std::string tiles_dir;  ///< folder of the GeoTIFF tiles (loaded at start; may be empty: then none)
  std::string site_dir;   ///< the site folder, created when missing; required
  std::string leaflet_dir = "/usr/share/javascript/leaflet";
  /// The fusion's track of a finished dive (stamp_s,easting_m,northing_m,... in the tiles' UTM zone), read when no
  /// track.json exists; empty: tiles_dir/fused_track.csv.
  std::string track_csv;
  std::string dive_name;                ///< page title and MBTiles name
  tiles::CutterConfig cutter;           ///< output_dir is set to site_dir/tiles
  double state_period_s = 2.0;          ///< state files rewritten at most this often, [0.1, 3600] s
  double track_min_spacing_m = 0.1;     ///< a track point closer than this to the last one kept is dropped, [0, 100] m
  int max_track_points = 20000;         ///< beyond, every other point of the older half goes, [100, 10^7]
  int max_usbl_fixes = 5000;            ///< the oldest go beyond, [10, 10^7]
  double vehicle_event_period_s = 0.2;  ///< track and vehicle events at most this often, [0, 60] s
  int worker_nice = 10;                 ///< niceness added to the cutting thread, [0, 19]
  bool load_existing = true;            ///< queue the GeoTIFFs of tiles_dir at start
  /// The GeoPackage and MBTiles exports written at shutdown(); "" for none.
  std::string gpkg_path;
  std::string mbtiles_path;

  std::string validate() const;
};

/// Counters for /diagnostics.
struct WebMapStats {
  uint64_t geotiffs_cut = 0;       ///< GeoTIFF updates processed successfully
  uint64_t web_tiles_written = 0;  ///< web tile files written (every level)
  uint64_t web_tiles_removed = 0;
  uint64_t errors = 0;  ///< GeoTIFFs that could not be read or cut, files that could not be written
  std::string last_error;
  int queue_length = 0;  ///< GeoTIFFs waiting to be cut
  int sources = 0;       ///< GeoTIFF tiles on the map
  int web_tiles = 0;     ///< web tiles on disk
  int min_zoom = -1, max_zoom = -1;
  double last_latency_ms = std::numeric_limits<double>::quiet_NaN();  ///< queued -> cut and announced
  double max_latency_ms = std::numeric_limits<double>::quiet_NaN();
  double last_cut_ms = std::numeric_limits<double>::quiet_NaN();          ///< cutting alone
  double cut_ms_per_web_tile = std::numeric_limits<double>::quiet_NaN();  ///< mean over every update
  size_t track_points = 0;
  size_t usbl_fixes = 0;
  uint64_t state_writes = 0;
};

class WebMap {
 public:
  enum class Severity { kDebug, kInfo, kWarning, kError };
  /// Messages for the log. `topic` groups them ("geotiff", "files", ...) so that a caller can throttle per topic.
  using Logger = std::function<void(Severity severity, const std::string& topic, const std::string& message)>;

  /// @throws std::invalid_argument naming the bad settings
  WebMap(WebMapConfig config, Logger logger = nullptr);
  /// shutdown(false) if not done.
  ~WebMap();
  WebMap(const WebMap&) = delete;
  WebMap& operator=(const WebMap&) = delete;

  /**
   * @brief Creates the site folder, writes the page and Leaflet into it, adopts what a previous run cut, queues the
   * GeoTIFFs to cut, loads the track, starts the worker thread.
   * @throws std::runtime_error when the site folder cannot be created or the page written
   */
  void start();

  /// Queues a GeoTIFF written or drawn again (a tile message's geotiff_path) for cutting. Returns at once.
  void enqueueGeoTiff(const std::string& path);

  /**
   * @brief Queues the GeoTIFFs of tiles_dir whose version was never queued, adopted nor left out at start
   * (load_existing false): those whose message this node missed (written while it was down, or before its
   * subscription was connected). One listing of the folder; a GeoTIFF that could not be read is not tried again.
   * Nothing before start() or after shutdown().
   * @param min_age a GeoTIFF modified less than this ago is left for the next call (its message is on its way)
   * @return how many were queued
   */
  int queueUnseenGeoTiffs(std::chrono::milliseconds min_age = std::chrono::milliseconds(0));

  /// The vehicle at a time: appended to the track (thinned) and sent to the pages (batched).
  /// @param heading_deg clockwise from true north, NaN: unknown (the page shows the course over ground)
  void addVehiclePose(double stamp_s, double latitude_deg, double longitude_deg, double heading_deg);
  /// A USBL fix. @param sigma_m horizontal 1-sigma (m), NaN: unknown
  void addUsblFix(double stamp_s, double latitude_deg, double longitude_deg, double sigma_m);
  /// The dive's UTM zone (0: UPS), for the page's UTM read-out.
  void setDatum(int utm_zone, bool northern_hemisphere, int epsg);
  /// Sends the events held back by vehicle_event_period_s now (call every so often: the last poses of a pause).
  void flushVehicleEvents();

  /// The whole state as JSON text (/state.json).
  std::string snapshotJson() const;
  WebMapStats stats() const;
  server::EventStream& events() { return events_; }
  const WebMapConfig& config() const { return config_; }

  /**
   * @brief Waits until every queued GeoTIFF is cut (or `timeout` passes). @return true when the queue is empty and
   * the worker idle.
   */
  bool waitIdle(std::chrono::milliseconds timeout);

  /**
   * @brief Cuts what is still queued, stops the worker, writes the state files and, if configured, the GeoPackage
   * and MBTiles files. Idempotent. @return "" or the errors met while writing the files
   */
  std::string shutdown();

 private:
  struct TrackPoint {
    double stamp_s, latitude_deg, longitude_deg;
  };
  struct UsblFix {
    double stamp_s, latitude_deg, longitude_deg, sigma_m;
  };
  struct Vehicle {
    double stamp_s, latitude_deg, longitude_deg, heading_deg;
  };
  struct Job {
    std::string path;
    std::string key;
    int version = 1;
    std::chrono::steady_clock::time_point queued;
  };

  void run();
  void process(const Job& job);
  void adoptPreviousRun(std::vector<std::string>* to_cut);
  void loadTrack();
  void writeStateFiles();
  void log(Severity severity, const std::string& topic, const std::string& message) const;
  void noteError(const std::string& topic, const std::string& message);
  void queueLocked(const std::string& path);
  /// Notes the GeoTIFF's version as seen (queueUnseenGeoTiffs() leaves it); mutex_ held or the worker not started.
  void markSeenLocked(const std::string& key, int version);
  void publishVehicleLocked();
  std::string tileJson(const tiles::SourceTile& source) const;

  WebMapConfig config_;
  Logger logger_;
  server::EventStream events_;
  std::unique_ptr<tiles::WebTileCutter> cutter_;  // the worker's alone once started

  mutable std::mutex mutex_;  // everything below
  std::condition_variable cv_;
  std::deque<Job> queue_;
  bool busy_ = false;
  bool stopping_ = false;
  bool started_ = false;
  bool shut_down_ = false;
  bool dirty_ = true;
  std::vector<tiles::SourceTile> sources_;          // the cutter's, copied after each update
  std::map<std::string, double> cut_unix_s_;        // when each source was last cut
  std::map<std::string, int> versions_seen_;        // key -> newest version queued, adopted or left out at start
  std::set<std::pair<int, int>> finest_tiles_;      // (x, y) of the web tiles at the max zoom
  std::set<std::pair<int, int>> awaiting_parents_;  // of those, the ones whose coarser levels are being built
  int min_zoom_ = -1, max_zoom_ = -1;
  std::vector<TrackPoint> track_;
  std::vector<TrackPoint> unsent_track_;
  std::vector<UsblFix> usbl_;
  std::optional<Vehicle> vehicle_;
  bool vehicle_unsent_ = false;
  std::chrono::steady_clock::time_point last_vehicle_event_;
  struct Datum {
    int utm_zone;
    bool northern;
    int epsg;
  };
  std::optional<Datum> datum_;
  WebMapStats stats_;
  double total_cut_ms_ = 0.0;
  uint64_t total_cut_tiles_ = 0;
  std::thread worker_;
};

}  // namespace site
}  // namespace exocet_web
