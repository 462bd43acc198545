#include "exocet_web/site/web_map.h"

#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include <nlohmann/json.hpp>

#include "exocet_common/atomic_file.h"
#include "exocet_common/background_priority.h"
#include "exocet_common/json_file.h"
#include "exocet_common/utm_grid.h"
#include "exocet_web/site/site_assets.h"
#include "exocet_web/tiles/tile_packages.h"

namespace exocet_web {
namespace site {

namespace {

namespace fs = std::filesystem;
using Json = nlohmann::ordered_json;
using Clock = std::chrono::steady_clock;

constexpr int kStateFormat = 1;

double unixNow_s() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

/// Rounded for the JSON files: 1e-8 degree is about 1 mm.
/// Rounded to 1e-8 degree (about 1 mm), printed short: the division gives the double nearest the decimal.
Json degrees(double v) { return std::isfinite(v) ? Json(std::round(v * 1e8) / 1e8) : Json(nullptr); }
Json finiteOrNull(double v) { return std::isfinite(v) ? Json(v) : Json(nullptr); }

/// Metadata values that are numbers become JSON numbers.
Json metadataValue(const std::string& text) {
  if (text.empty()) return text;
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (end && *end == '\0' && std::isfinite(v)) return v;
  return text;
}

/// Approximate ground distance (m) between two close points: enough to thin a track.
double groundDistance_m(double lat1, double lon1, double lat2, double lon2) {
  constexpr double kMetresPerDegree = 111195.0;
  const double dx = (lon2 - lon1) * std::cos((lat1 + lat2) * M_PI / 360.0) * kMetresPerDegree;
  const double dy = (lat2 - lat1) * kMetresPerDegree;
  return std::hypot(dx, dy);
}

double bearing_deg(double lat1, double lon1, double lat2, double lon2) {
  const double dx = (lon2 - lon1) * std::cos((lat1 + lat2) * M_PI / 360.0);
  const double dy = lat2 - lat1;
  double b = std::atan2(dx, dy) * 180.0 / M_PI;
  return b < 0 ? b + 360.0 : b;
}

std::string jsonLine(const Json& j) { return exocet_common::jsonText(j, -1); }

}  // namespace

std::string WebMapConfig::validate() const {
  std::vector<std::string> errors;
  if (site_dir.empty()) errors.push_back("site_dir is empty");
  tiles::CutterConfig cut = cutter;
  if (cut.output_dir.empty()) cut.output_dir = site_dir + "/tiles";
  const std::string cut_error = cut.validate();
  if (!cut_error.empty()) errors.push_back(cut_error);
  if (!(state_period_s >= 0.1 && state_period_s <= 3600.0))
    errors.push_back("state_period_s " + std::to_string(state_period_s) + " outside [0.1, 3600]");
  if (!(track_min_spacing_m >= 0.0 && track_min_spacing_m <= 100.0))
    errors.push_back("track_min_spacing_m " + std::to_string(track_min_spacing_m) + " outside [0, 100]");
  if (max_track_points < 100 || max_track_points > 10000000)
    errors.push_back("max_track_points " + std::to_string(max_track_points) + " outside [100, 10000000]");
  if (max_usbl_fixes < 10 || max_usbl_fixes > 10000000)
    errors.push_back("max_usbl_fixes " + std::to_string(max_usbl_fixes) + " outside [10, 10000000]");
  if (!(vehicle_event_period_s >= 0.0 && vehicle_event_period_s <= 60.0))
    errors.push_back("vehicle_event_period_s " + std::to_string(vehicle_event_period_s) + " outside [0, 60]");
  if (worker_nice < 0 || worker_nice > 19)
    errors.push_back("worker_nice " + std::to_string(worker_nice) + " outside [0, 19]");
  std::string joined;
  for (const auto& e : errors) joined += (joined.empty() ? "" : "; ") + e;
  return joined;
}

WebMap::WebMap(WebMapConfig config, Logger logger) : config_(std::move(config)), logger_(std::move(logger)) {
  const std::string error = config_.validate();
  if (!error.empty()) throw std::invalid_argument("web map: " + error);
  config_.cutter.output_dir = config_.site_dir + "/tiles";
  cutter_ = std::make_unique<tiles::WebTileCutter>(config_.cutter);
}

WebMap::~WebMap() { shutdown(); }

void WebMap::log(Severity severity, const std::string& topic, const std::string& message) const {
  if (logger_) logger_(severity, topic, message);
}

void WebMap::noteError(const std::string& topic, const std::string& message) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    ++stats_.errors;
    stats_.last_error = message;
  }
  log(Severity::kWarning, topic, message);
}

void WebMap::start() {
  std::error_code ec;
  fs::create_directories(config_.cutter.output_dir, ec);
  if (ec) throw std::runtime_error("web map: cannot create '" + config_.cutter.output_dir + "': " + ec.message());
  const std::string assets_error = writeSiteAssets(config_.site_dir, config_.leaflet_dir);
  if (!assets_error.empty()) throw std::runtime_error("web map: " + assets_error);
  std::vector<std::string> to_cut;
  if (config_.load_existing && !config_.tiles_dir.empty()) {
    adoptPreviousRun(&to_cut);
  } else if (!config_.tiles_dir.empty()) {
    // Left out on purpose: queueUnseenGeoTiffs() must not cut them either.
    for (const auto& path : tiles::listSourceTiles(config_.tiles_dir)) {
      std::string key;
      int index = 0, version = 0;
      if (tiles::parseTileFileName(fs::path(path).filename().string(), &key, &index, &version))
        markSeenLocked(key, version);
    }
  }
  loadTrack();
  {
    std::lock_guard<std::mutex> lock(mutex_);
    for (const auto& path : to_cut) queueLocked(path);
    started_ = true;
    dirty_ = true;
  }
  writeStateFiles();  // the page finds its state at once, even before the first cut
  if (!to_cut.empty())
    log(Severity::kInfo, "start",
        std::to_string(to_cut.size()) + " GeoTIFF tiles of " + config_.tiles_dir + " to cut into web tiles");
  worker_ = std::thread([this] { run(); });
}

void WebMap::adoptPreviousRun(std::vector<std::string>* to_cut) {
  std::string list_error;
  const std::vector<std::string> paths = tiles::listSourceTiles(config_.tiles_dir, &list_error);
  if (!list_error.empty()) log(Severity::kWarning, "geotiff", list_error);
  const auto manifest = exocet_common::readJsonObjectFile<Json>(config_.site_dir + "/tiles.json");
  bool compatible = false;
  std::map<std::string, Json> previous;
  int min_zoom = -1, max_zoom = -1;
  if (manifest && manifest->value("format", 0) == kStateFormat && manifest->contains("zoom") &&
      manifest->contains("cutter") && manifest->contains("tiles")) {
    try {
      min_zoom = (*manifest)["zoom"].value("min", -1);
      max_zoom = (*manifest)["zoom"].value("max", -1);
      const Json& cut = (*manifest)["cutter"];
      compatible = max_zoom >= 1 && min_zoom >= 0 && min_zoom <= max_zoom &&
                   (config_.cutter.max_zoom < 0 || config_.cutter.max_zoom == max_zoom) &&
                   (config_.cutter.min_zoom < 0 || config_.cutter.min_zoom == min_zoom) &&
                   cut.value("resampling", "") == config_.cutter.resampling;
      for (const Json& t : (*manifest)["tiles"]) previous[t.at("key").get<std::string>()] = t;
    } catch (const std::exception& e) {
      log(Severity::kWarning, "files",
          "tiles.json of a previous run unreadable (" + std::string(e.what()) + "): every web tile is cut again");
      compatible = false;
    }
  }
  std::vector<tiles::SourceTile> adopted;
  std::vector<std::string> changed, readable;
  std::set<std::string> present;
  for (const std::string& path : paths) {
    tiles::SourceTile source;
    const std::string error = tiles::readSourceTile(path, &source);
    if (!error.empty()) {
      std::string key;
      int index = 0, version = 0;
      if (tiles::parseTileFileName(fs::path(path).filename().string(), &key, &index, &version))
        markSeenLocked(key, version);  // counted once, not at every look at the folder
      noteError("geotiff", error);
      continue;
    }
    markSeenLocked(source.key, source.version);
    present.insert(source.key);
    readable.push_back(path);
    const auto it = previous.find(source.key);
    if (compatible && it != previous.end() && it->second.value("version", 0) == source.version &&
        it->second.value("file", "") == fs::path(source.path).filename().string() &&
        it->second.value("size_bytes", int64_t(-1)) == source.file_size_bytes &&
        it->second.value("mtime_ns", int64_t(-1)) == source.mtime_ns) {
      adopted.push_back(source);
      cut_unix_s_[source.key] = it->second.value("cut_unix_s", 0.0);
    } else {
      changed.push_back(path);
    }
  }
  // A tile cut before but gone from the folder: its web tiles cannot be told apart from the others'.
  for (const auto& item : previous)
    if (!present.count(item.first)) compatible = false;
  if (!compatible) {
    std::error_code ec;
    fs::remove_all(config_.cutter.output_dir, ec);
    fs::create_directories(config_.cutter.output_dir, ec);
    cut_unix_s_.clear();
    *to_cut = readable;  // the others were counted as errors above
    return;
  }
  cutter_->adopt(adopted, min_zoom, max_zoom);
  sources_ = cutter_->sources();
  min_zoom_ = cutter_->minZoom();
  max_zoom_ = cutter_->maxZoom();
  for (const auto& t : cutter_->tiles())
    if (t.z == max_zoom_) finest_tiles_.insert({t.x, t.y});
  *to_cut = changed;
  stats_.sources = static_cast<int>(sources_.size());
  stats_.web_tiles = static_cast<int>(cutter_->tiles().size());
  stats_.min_zoom = min_zoom_;
  stats_.max_zoom = max_zoom_;
  if (!adopted.empty())
    log(Severity::kInfo, "start",
        std::to_string(adopted.size()) + " GeoTIFF tiles already cut by a previous run (" +
            std::to_string(cutter_->tiles().size()) + " web tiles, levels " + std::to_string(min_zoom) + " to " +
            std::to_string(max_zoom) + ")");
}

void WebMap::loadTrack() {
  if (const auto saved = exocet_common::readJsonObjectFile<Json>(config_.site_dir + "/track.json")) {
    try {
      std::lock_guard<std::mutex> lock(mutex_);
      for (const Json& p : saved->at("track"))
        track_.push_back({p.at(2).get<double>(), p.at(0).get<double>(), p.at(1).get<double>()});
      for (const Json& f : saved->at("usbl"))
        usbl_.push_back({f.at(2).get<double>(), f.at(0).get<double>(), f.at(1).get<double>(),
                         f.at(3).is_number() ? f.at(3).get<double>() : std::nan("")});
      return;
    } catch (const std::exception& e) {
      track_.clear();
      usbl_.clear();
      log(Severity::kWarning, "files", "track.json of a previous run unreadable: " + std::string(e.what()));
    }
  }
  // A finished dive: the fusion's track, in the tiles' UTM zone.
  const std::string csv = !config_.track_csv.empty()  ? config_.track_csv
                          : config_.tiles_dir.empty() ? ""
                                                      : config_.tiles_dir + "/fused_track.csv";
  std::ifstream in(csv);
  if (csv.empty() || !in) return;
  int epsg = 0;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!sources_.empty()) epsg = sources_.front().epsg;
  }
  if (epsg == 0) {
    for (const auto& path : tiles::listSourceTiles(config_.tiles_dir)) {
      tiles::SourceTile source;
      if (tiles::readSourceTile(path, &source).empty() && source.epsg != 0) {
        epsg = source.epsg;
        break;
      }
    }
  }
  const bool utm = (epsg > 32600 && epsg <= 32660) || (epsg > 32700 && epsg <= 32760);
  if (!utm) return;
  const auto grid = exocet_common::UtmGrid::fromZone(epsg % 100, epsg < 32700);
  std::string line;
  std::getline(in, line);  // header: stamp_s,easting_m,northing_m,...
  int loaded = 0;
  while (std::getline(in, line)) {
    std::stringstream fields(line);
    std::string t, e, n;
    if (!std::getline(fields, t, ',') || !std::getline(fields, e, ',') || !std::getline(fields, n, ',')) continue;
    try {
      const auto ll = grid.toLatLon(std::stod(e), std::stod(n));
      addVehiclePose(std::stod(t), ll.x(), ll.y(), std::nan(""));
      ++loaded;
    } catch (const std::exception&) {
    }
  }
  std::lock_guard<std::mutex> lock(mutex_);
  unsent_track_.clear();
  vehicle_unsent_ = false;
  if (loaded) log(Severity::kInfo, "start", "track of the finished dive from " + csv);
}

void WebMap::queueLocked(const std::string& path) {
  Job job;
  job.path = path;
  job.queued = Clock::now();
  int index = 0;
  if (tiles::parseTileFileName(fs::path(path).filename().string(), &job.key, &index, &job.version))
    markSeenLocked(job.key, job.version);
  else
    job.key = path;  // cut anyway: readSourceTile says what is wrong
  // A newer version of a tile still queued replaces it; the older message's time is kept for the latency.
  for (Job& queued : queue_) {
    if (queued.key == job.key) {
      if (job.version >= queued.version) {
        queued.path = job.path;
        queued.version = job.version;
      }
      return;
    }
  }
  queue_.push_back(job);
  stats_.queue_length = static_cast<int>(queue_.size());
}

void WebMap::markSeenLocked(const std::string& key, int version) {
  int& seen = versions_seen_[key];
  seen = std::max(seen, version);
}

int WebMap::queueUnseenGeoTiffs(std::chrono::milliseconds min_age) {
  if (config_.tiles_dir.empty()) return 0;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!started_ || stopping_) return 0;
  }
  std::string list_error;
  const std::vector<std::string> paths = tiles::listSourceTiles(config_.tiles_dir, &list_error);
  if (!list_error.empty()) log(Severity::kWarning, "geotiff", list_error);
  const double now_unix_s = unixNow_s();
  int queued = 0;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (stopping_) return 0;
    for (const std::string& path : paths) {
      std::string key;
      int index = 0, version = 0;
      if (!tiles::parseTileFileName(fs::path(path).filename().string(), &key, &index, &version)) continue;
      const auto seen = versions_seen_.find(key);
      if (seen != versions_seen_.end() && seen->second >= version) continue;
      struct stat st {};
      if (min_age.count() > 0 && ::stat(path.c_str(), &st) == 0 &&
          now_unix_s - (st.st_mtim.tv_sec + st.st_mtim.tv_nsec * 1e-9) < min_age.count() * 1e-3)
        continue;
      queueLocked(path);
      ++queued;
    }
  }
  if (queued > 0) cv_.notify_all();
  return queued;
}

void WebMap::enqueueGeoTiff(const std::string& path) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (stopping_) return;
    queueLocked(path);
  }
  cv_.notify_all();
}

void WebMap::run() {
  if (config_.worker_nice > 0) exocet_common::lowerThisThreadPriority(config_.worker_nice);
  const auto period =
      std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(config_.state_period_s));
  auto last_write = Clock::now() - period;
  std::unique_lock<std::mutex> lock(mutex_);
  while (true) {
    if (!queue_.empty()) {
      const Job job = queue_.front();
      queue_.pop_front();
      stats_.queue_length = static_cast<int>(queue_.size());
      busy_ = true;
      lock.unlock();
      process(job);
      lock.lock();
      busy_ = false;
      cv_.notify_all();
    }
    const bool due = Clock::now() - last_write >= period;
    if (dirty_ && due) {
      lock.unlock();
      writeStateFiles();
      lock.lock();
      last_write = Clock::now();
      continue;
    }
    if (!queue_.empty()) continue;
    if (stopping_) break;
    if (dirty_)
      cv_.wait_until(lock, last_write + period, [&] { return stopping_ || !queue_.empty(); });
    else
      cv_.wait(lock, [&] { return stopping_ || !queue_.empty() || dirty_; });
  }
}

bool WebMap::waitIdle(std::chrono::milliseconds timeout) {
  std::unique_lock<std::mutex> lock(mutex_);
  return cv_.wait_for(lock, timeout, [&] { return queue_.empty() && !busy_; });
}

void WebMap::process(const Job& job) {
  tiles::SourceTile source;
  const std::string error = tiles::readSourceTile(job.path, &source);
  if (!error.empty()) {
    std::error_code ec;
    if (!fs::exists(job.path, ec)) {
      // Replaced by a newer version before it was cut: that version's message follows (or is queued already).
      log(Severity::kInfo, "geotiff", "'" + job.path + "' is gone (a newer version replaced it): skipped");
      return;
    }
    noteError("geotiff", error);
    return;
  }
  // The finest level is announced as soon as it is on disk (a page following the vehicle shows that level), the
  // coarser levels once they are built.
  size_t finest_written = 0, finest_removed = 0;
  double first_announce_ms = std::numeric_limits<double>::quiet_NaN();
  const auto announce = [&](const tiles::CutReport& part, size_t written_from, size_t removed_from, bool finest_only) {
    const double latency_ms = std::chrono::duration<double, std::milli>(Clock::now() - job.queued).count();
    std::lock_guard<std::mutex> lock(mutex_);
    if (std::isnan(first_announce_ms)) {
      // The footprint first: a page takes the mosaic's bounds from the footprints.
      first_announce_ms = latency_ms;
      sources_ = cutter_->sources();
      if (cutter_->source(source.key)) events_.publish("tile", tileJson(source));
    }
    const int previous_min = min_zoom_, previous_max = max_zoom_;
    min_zoom_ = cutter_->minZoom();
    max_zoom_ = cutter_->maxZoom();
    if (previous_max != max_zoom_) finest_tiles_.clear();
    awaiting_parents_.clear();
    Json written = Json::array(), removed = Json::array();
    for (size_t i = written_from; i < part.written.size(); ++i) {
      const auto& t = part.written[i];
      if (t.z == max_zoom_) {
        finest_tiles_.insert({t.x, t.y});
        if (finest_only) awaiting_parents_.insert({t.x, t.y});
      }
      written.push_back({t.z, t.x, t.y});
    }
    for (size_t i = removed_from; i < part.removed.size(); ++i) {
      const auto& t = part.removed[i];
      if (t.z == max_zoom_) finest_tiles_.erase({t.x, t.y});
      removed.push_back({t.z, t.x, t.y});
    }
    if (finest_only && written.empty() && removed.empty()) return;  // announced with the coarser levels
    dirty_ = true;
    Json cut;
    cut["key"] = source.key;
    cut["index"] = source.index;
    cut["version"] = source.version;
    cut["levels"] = finest_only ? "finest" : "coarser";
    cut["zoom"] = {{"min", min_zoom_}, {"max", max_zoom_}};
    cut["zoom_changed"] = previous_min != min_zoom_ || previous_max != max_zoom_;
    cut["written"] = written;
    cut["removed"] = removed;
    cut["cut_ms"] = std::round(part.total_ms);
    cut["warp_ms"] = std::round(part.warp_ms);
    cut["latency_ms"] = std::round(latency_ms);
    events_.publish("webtiles", jsonLine(cut));
  };
  const tiles::CutReport report = cutter_->update(source, [&](const tiles::CutReport& finest) {
    announce(finest, 0, 0, true);
    finest_written = finest.written.size();
    finest_removed = finest.removed.size();
  });
  if (!report.ok) noteError("cut", "cutting '" + job.path + "': " + report.error);
  for (const std::string& key : report.unreadable) {
    if (key == source.key) continue;
    // Another tile's file went (a newer version is on disk, its message on the way): cut that version too.
    const tiles::SourceTile* other = cutter_->source(key);
    if (!other) continue;
    bool queued = false;
    for (const auto& path : tiles::listSourceTiles(fs::path(other->path).parent_path().string())) {
      std::string k;
      int i = 0, v = 0;
      if (tiles::parseTileFileName(fs::path(path).filename().string(), &k, &i, &v) && k == key && path != other->path) {
        enqueueGeoTiff(path);
        queued = true;
      }
    }
    if (!queued) log(Severity::kWarning, "geotiff", "'" + other->path + "' cannot be opened any more");
  }
  const double done_unix_s = unixNow_s();
  {
    std::lock_guard<std::mutex> lock(mutex_);
    sources_ = cutter_->sources();
    cut_unix_s_[source.key] = done_unix_s;
    stats_.web_tiles_written += report.written.size();
    stats_.web_tiles_removed += report.removed.size();
    if (report.ok) ++stats_.geotiffs_cut;
    stats_.sources = static_cast<int>(sources_.size());
    stats_.web_tiles = static_cast<int>(cutter_->tiles().size());
    stats_.last_cut_ms = report.total_ms;
    total_cut_ms_ += report.total_ms;
    total_cut_tiles_ += report.written.size();
    if (total_cut_tiles_ > 0) stats_.cut_ms_per_web_tile = total_cut_ms_ / double(total_cut_tiles_);
  }
  announce(report, finest_written, finest_removed, false);
  const double latency_ms = std::isnan(first_announce_ms)
                                ? std::chrono::duration<double, std::milli>(Clock::now() - job.queued).count()
                                : first_announce_ms;
  std::lock_guard<std::mutex> lock(mutex_);
  stats_.min_zoom = min_zoom_;
  stats_.max_zoom = max_zoom_;
  log(Severity::kDebug, "cut",
      source.key + " v" + std::to_string(source.version) + ": " + std::to_string(report.written.size()) +
          " web tiles written, " + std::to_string(report.removed.size()) + " removed in " +
          std::to_string(std::lround(report.total_ms)) + " ms (GDAL warp " +
          std::to_string(std::lround(report.warp_ms)) + " ms, " + std::to_string(report.sources_warped) +
          " warps), finest level announced " + std::to_string(std::lround(latency_ms)) + " ms after it was queued");
  stats_.last_latency_ms = latency_ms;
  stats_.max_latency_ms = std::isnan(stats_.max_latency_ms) ? latency_ms : std::max(stats_.max_latency_ms, latency_ms);
}

std::string WebMap::tileJson(const tiles::SourceTile& s) const {
  Json j;
  j["key"] = s.key;
  j["index"] = s.index;
  j["version"] = s.version;
  j["file"] = fs::path(s.path).filename().string();
  j["epsg"] = s.epsg;
  j["gsd_m"] = s.gsd_m;
  j["width_px"] = s.width_px;
  j["height_px"] = s.height_px;
  Json corners = Json::array();
  for (const auto& c : s.corners_deg) corners.push_back({degrees(c[0]), degrees(c[1])});
  j["corners"] = corners;
  j["bounds"] = {degrees(s.latlon_box.south_deg), degrees(s.latlon_box.west_deg), degrees(s.latlon_box.north_deg),
                 degrees(s.latlon_box.east_deg)};
  Json metadata = Json::object();
  for (const auto& [key, value] : s.metadata) metadata[key] = metadataValue(value);
  j["metadata"] = metadata;
  const auto cut = cut_unix_s_.find(s.key);
  j["cut_unix_s"] = cut == cut_unix_s_.end() ? Json(nullptr) : Json(std::round(cut->second * 1000.0) / 1000.0);
  j["size_bytes"] = s.file_size_bytes;
  j["mtime_ns"] = s.mtime_ns;
  return jsonLine(j);
}

void WebMap::addVehiclePose(double stamp_s, double latitude_deg, double longitude_deg, double heading_deg) {
  if (!std::isfinite(latitude_deg) || !std::isfinite(longitude_deg) || std::abs(latitude_deg) > 90.0) return;
  std::lock_guard<std::mutex> lock(mutex_);
  const bool keep = track_.empty() || groundDistance_m(track_.back().latitude_deg, track_.back().longitude_deg,
                                                       latitude_deg, longitude_deg) >= config_.track_min_spacing_m;
  if (keep) {
    track_.push_back({stamp_s, latitude_deg, longitude_deg});
    unsent_track_.push_back(track_.back());
    if (static_cast<int>(track_.size()) > config_.max_track_points) {
      // Bounded on a dive of any length: every other point of the older half goes.
      std::vector<TrackPoint> thinned;
      const size_t half = track_.size() / 2;
      for (size_t i = 0; i < track_.size(); ++i)
        if (i >= half || i % 2 == 0) thinned.push_back(track_[i]);
      track_.swap(thinned);
    }
  }
  vehicle_ = Vehicle{stamp_s, latitude_deg, longitude_deg, heading_deg};
  vehicle_unsent_ = true;
  dirty_ = true;
  if (started_ && Clock::now() - last_vehicle_event_ >= std::chrono::duration<double>(config_.vehicle_event_period_s))
    publishVehicleLocked();
}

void WebMap::flushVehicleEvents() {
  std::lock_guard<std::mutex> lock(mutex_);
  if (vehicle_unsent_ || !unsent_track_.empty()) publishVehicleLocked();
}

void WebMap::publishVehicleLocked() {
  Json j;
  Json points = Json::array();
  for (const auto& p : unsent_track_) points.push_back({degrees(p.latitude_deg), degrees(p.longitude_deg), p.stamp_s});
  j["points"] = points;
  if (vehicle_) {
    Json v;
    v["lat"] = degrees(vehicle_->latitude_deg);
    v["lon"] = degrees(vehicle_->longitude_deg);
    v["t"] = vehicle_->stamp_s;
    v["heading_deg"] = finiteOrNull(vehicle_->heading_deg);
    // The course over ground from the last track points, for a vehicle without a heading.
    double course = std::nan("");
    for (size_t i = track_.size(); i-- > 0;) {
      if (groundDistance_m(track_[i].latitude_deg, track_[i].longitude_deg, vehicle_->latitude_deg,
                           vehicle_->longitude_deg) >= 0.2) {
        course = bearing_deg(track_[i].latitude_deg, track_[i].longitude_deg, vehicle_->latitude_deg,
                             vehicle_->longitude_deg);
        break;
      }
      if (track_.size() - i > 50) break;
    }
    v["course_deg"] = finiteOrNull(course);
    j["vehicle"] = v;
  }
  events_.publish("track", jsonLine(j));
  unsent_track_.clear();
  vehicle_unsent_ = false;
  last_vehicle_event_ = Clock::now();
}

void WebMap::addUsblFix(double stamp_s, double latitude_deg, double longitude_deg, double sigma_m) {
  if (!std::isfinite(latitude_deg) || !std::isfinite(longitude_deg) || std::abs(latitude_deg) > 90.0) return;
  std::lock_guard<std::mutex> lock(mutex_);
  usbl_.push_back({stamp_s, latitude_deg, longitude_deg, sigma_m});
  if (static_cast<int>(usbl_.size()) > config_.max_usbl_fixes) usbl_.erase(usbl_.begin());
  dirty_ = true;
  if (!started_) return;
  Json j;
  j["fixes"] =
      Json::array({Json::array({degrees(latitude_deg), degrees(longitude_deg), stamp_s, finiteOrNull(sigma_m)})});
  events_.publish("usbl", jsonLine(j));
}

void WebMap::setDatum(int utm_zone, bool northern_hemisphere, int epsg) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (datum_ && datum_->utm_zone == utm_zone && datum_->northern == northern_hemisphere) return;
  datum_ = Datum{utm_zone, northern_hemisphere, epsg};
  dirty_ = true;
  if (!started_) return;
  events_.publish("datum", jsonLine(Json{{"utm_zone", utm_zone}, {"northern", northern_hemisphere}, {"epsg", epsg}}));
}

std::string WebMap::snapshotJson() const {
  std::lock_guard<std::mutex> lock(mutex_);
  Json j;
  j["format"] = kStateFormat;
  j["dive_name"] = config_.dive_name;
  j["generated_unix_s"] = std::round(unixNow_s() * 1000.0) / 1000.0;
  j["event_id"] = events_.idText(events_.lastId());
  if (datum_) {
    j["datum"] = {{"utm_zone", datum_->utm_zone}, {"northern", datum_->northern}, {"epsg", datum_->epsg}};
  } else {
    j["datum"] = nullptr;
  }
  j["zoom"] = {{"min", min_zoom_}, {"max", max_zoom_}};
  tiles::LatLonBox box{180.0, 90.0, -180.0, -90.0};
  Json tiles = Json::array();
  for (const auto& s : sources_) {
    tiles.push_back(Json::parse(tileJson(s)));
    box = {std::min(box.west_deg, s.latlon_box.west_deg), std::min(box.south_deg, s.latlon_box.south_deg),
           std::max(box.east_deg, s.latlon_box.east_deg), std::max(box.north_deg, s.latlon_box.north_deg)};
  }
  j["bounds"] =
      sources_.empty()
          ? Json(nullptr)
          : Json({degrees(box.south_deg), degrees(box.west_deg), degrees(box.north_deg), degrees(box.east_deg)});
  j["tiles"] = tiles;
  Json xy = Json::array();
  for (const auto& [x, y] : finest_tiles_) xy.push_back({x, y});
  Json awaiting = Json::array();
  for (const auto& [x, y] : awaiting_parents_) awaiting.push_back({x, y});
  // awaiting_parents: finest web tiles announced whose coarser levels are still being cut (not there yet).
  j["web_tiles"] = {{"z", max_zoom_}, {"xy", xy}, {"awaiting_parents", awaiting}};
  Json track = Json::array();
  for (const auto& p : track_) track.push_back({degrees(p.latitude_deg), degrees(p.longitude_deg), p.stamp_s});
  j["track"] = track;
  Json usbl = Json::array();
  for (const auto& f : usbl_)
    usbl.push_back({degrees(f.latitude_deg), degrees(f.longitude_deg), f.stamp_s, finiteOrNull(f.sigma_m)});
  j["usbl"] = usbl;
  if (vehicle_) {
    j["vehicle"] = {{"lat", degrees(vehicle_->latitude_deg)},
                    {"lon", degrees(vehicle_->longitude_deg)},
                    {"t", vehicle_->stamp_s},
                    {"heading_deg", finiteOrNull(vehicle_->heading_deg)}};
  } else {
    j["vehicle"] = nullptr;
  }
  return jsonLine(j);
}

WebMapStats WebMap::stats() const {
  std::lock_guard<std::mutex> lock(mutex_);
  WebMapStats s = stats_;
  s.queue_length = static_cast<int>(queue_.size());
  s.track_points = track_.size();
  s.usbl_fixes = usbl_.size();
  return s;
}

void WebMap::writeStateFiles() {
  std::string state, manifest, track;
  {
    // One consistent picture of the state for the four files.
    const std::string snapshot = snapshotJson();
    std::lock_guard<std::mutex> lock(mutex_);
    dirty_ = false;
    state = snapshot;
    Json m;
    m["format"] = kStateFormat;
    m["zoom"] = {{"min", min_zoom_}, {"max", max_zoom_}};
    m["cutter"] = {{"resampling", config_.cutter.resampling}, {"png_compression", config_.cutter.png_compression}};
    Json list = Json::array();
    for (const auto& s : sources_) list.push_back(Json::parse(tileJson(s)));
    m["tiles"] = list;
    manifest = exocet_common::jsonText(m, 1);
    Json t;
    Json points = Json::array();
    for (const auto& p : track_) points.push_back({degrees(p.latitude_deg), degrees(p.longitude_deg), p.stamp_s});
    t["track"] = points;
    Json usbl = Json::array();
    for (const auto& f : usbl_)
      usbl.push_back({degrees(f.latitude_deg), degrees(f.longitude_deg), f.stamp_s, finiteOrNull(f.sigma_m)});
    t["usbl"] = usbl;
    track = jsonLine(t);
  }
  try {
    exocet_common::writeFileAtomically(config_.site_dir + "/state.json", state + "\n");
    exocet_common::writeFileAtomically(config_.site_dir + "/state.js",
                                       "// The web map's state for a page opened from disk (file://).\n"
                                       "window.EXOCET_STATE = " +
                                           state + ";\n");
    exocet_common::writeFileAtomically(config_.site_dir + "/tiles.json", manifest + "\n");
    exocet_common::writeFileAtomically(config_.site_dir + "/track.json", track + "\n");
    std::lock_guard<std::mutex> lock(mutex_);
    ++stats_.state_writes;
  } catch (const std::exception& e) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      dirty_ = true;  // try again at the next period
    }
    noteError("files", e.what());
  }
}

std::string WebMap::shutdown() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (shut_down_ || !started_) {
      shut_down_ = true;
      return "";
    }
    shut_down_ = true;
    stopping_ = true;
  }
  cv_.notify_all();
  if (worker_.joinable()) worker_.join();
  flushVehicleEvents();
  const uint64_t errors_before = stats().errors;
  writeStateFiles();
  std::string errors = stats().errors > errors_before ? stats().last_error : "";
  if (cutter_->tiles().empty()) return errors;
  tiles::TilePackageInfo info;
  info.name = config_.dive_name.empty() ? "Exocet mosaic" : config_.dive_name;
  info.description = "Seabed mosaic (Exocet web map), " + std::to_string(sources_.size()) + " GeoTIFF tiles";
  for (const auto& [path, format] : {std::make_pair(config_.gpkg_path, std::string("GeoPackage")),
                                     std::make_pair(config_.mbtiles_path, std::string("MBTiles"))}) {
    if (path.empty()) continue;
    const tiles::TilePackageResult result = format == "GeoPackage"
                                                ? tiles::exportGeoPackage(config_.cutter.output_dir, path, info)
                                                : tiles::exportMbtiles(config_.cutter.output_dir, path, info);
    if (!result.ok) {
      noteError("files", format + " export: " + result.error);
      errors += (errors.empty() ? "" : "; ") + result.error;
    } else {
      log(Severity::kInfo, "files",
          format + " " + path + ": " + std::to_string(result.tiles) + " web tiles, levels " +
              std::to_string(result.min_zoom) + " to " + std::to_string(result.max_zoom));
    }
  }
  return errors;
}

}  // namespace site
}  // namespace exocet_web
