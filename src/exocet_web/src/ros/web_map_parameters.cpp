#include "exocet_web/ros/web_map_parameters.h"

#include <stdexcept>

#include "exocet_common/ros/parameter_reader.h"

namespace exocet_web {

WebMapNodeConfig readWebMapNodeConfig(const ros::NodeHandle& private_nh) {
  WebMapNodeConfig c;
  const exocet_common::ParameterReader p(private_nh);
  site::WebMapConfig& s = c.site;
  p.readRequiredString(
      "tiles_dir", &s.tiles_dir,
      "the folder of the GeoTIFF tiles (the tile writer's ~output_dir): its tiles are loaded at start");
  s.site_dir = s.tiles_dir + "/web";
  p.readString("site_dir", &s.site_dir, {}, "the folder of the web site (created; default <tiles_dir>/web)");
  p.readOptionalString("dive_name", &s.dive_name, "the dive's name, in the page's title and the MBTiles file");
  p.readString("leaflet_dir", &s.leaflet_dir, {}, "Leaflet's folder (Debian package libjs-leaflet)");
  s.gpkg_path = s.site_dir + "/mosaic.gpkg";
  p.readOptionalString(
      "gpkg_path", &s.gpkg_path,
      "the GeoPackage of the web tiles written at shutdown, for QGIS (default <site_dir>/mosaic.gpkg), "
      "\"\" for none");
  p.readOptionalString("mbtiles_path", &s.mbtiles_path,
                       "an MBTiles file of the web tiles written at shutdown, \"\" (default) for none");
  p.readBool("load_existing", &s.load_existing, "cut the GeoTIFF tiles already in ~tiles_dir at start");
  p.readInt("max_zoom", &s.cutter.max_zoom, -1, 30,
            "the finest web tile level, -1: the native level of the first GeoTIFF tile (nearest its gsd)");
  p.readInt("min_zoom", &s.cutter.min_zoom, -1, 30,
            "the coarsest web tile level, -1: the level at which the survey fits in one tile");
  if (s.cutter.max_zoom == 0) throw std::invalid_argument(p.describe("max_zoom") + " is 0: allowed -1 or [1, 30]");
  if (s.cutter.max_zoom > 0 && s.cutter.min_zoom > s.cutter.max_zoom)
    throw std::invalid_argument(p.describe("min_zoom") + " is " + std::to_string(s.cutter.min_zoom) +
                                ", above ~max_zoom " + std::to_string(s.cutter.max_zoom) + ": allowed [0, max_zoom]");
  p.readInt("png_compression", &s.cutter.png_compression, 0, 9, "zlib level of the web tiles' PNG");
  p.readString("resampling", &s.cutter.resampling, {"near", "bilinear", "cubic", "lanczos", "average"},
               "GDAL's resampling of the finest level");
  p.readDouble("state_period_s", &s.state_period_s, 0.1, 3600.0, "state files rewritten at most this often (s)");
  p.readDouble("track_min_spacing_m", &s.track_min_spacing_m, 0.0, 100.0,
               "a track point closer than this to the previous one kept is dropped (m)");
  p.readInt("max_track_points", &s.max_track_points, 100, 10000000, "track points kept (the older half thinned)");
  p.readDouble("vehicle_event_period_s", &s.vehicle_event_period_s, 0.0, 60.0,
               "track and vehicle updates sent to the pages at most this often (s)");
  p.readInt("worker_nice", &s.worker_nice, 0, 19, "niceness added to the cutting thread");

  server::ServerConfig& w = c.server;
  p.readString("bind_address", &w.bind_address, {},
               "the address the server listens on: 127.0.0.1 (this computer only), the station network's address, "
               "or 0.0.0.0 (every interface)");
  p.readInt("port", &w.port, 0, 65535, "the server's TCP port, 0: any free port (logged)");
  p.readInt("max_clients", &w.max_clients, 1, 1024, "connections served at once (a browser opens up to 6)");
  p.readInt("keep_alive_s", &w.keep_alive_s, 1, 60, "an idle connection is closed after this (s)");
  p.readDouble("heartbeat_s", &w.heartbeat_s, 0.05, 60.0, "period of the live stream's keep-alive comments (s)");
  p.readInt("server_nice", &w.thread_nice, 0, 19, "niceness added to the server's threads");

  p.readTopic("tile_topic", &c.tile_topic);
  p.readTopic("odometry_topic", &c.odometry_topic);
  p.readTopic("datum_topic", &c.datum_topic);
  p.readOptionalTopic("usbl_topic", &c.usbl_topic);
  p.readOptionalTopic("imu_topic", &c.imu_topic);
  p.readPositiveDouble("imu_max_age_s", &c.imu_max_age_s, 3600.0,
                       "an IMU attitude older than this (s) no longer gives the vehicle's heading");

  const std::string site_error = s.validate();
  if (!site_error.empty()) throw std::invalid_argument("web_map_node: " + site_error);
  const std::string server_error = w.validate();
  if (!server_error.empty()) throw std::invalid_argument("web_map_node: " + server_error);
  return c;
}

}  // namespace exocet_web
