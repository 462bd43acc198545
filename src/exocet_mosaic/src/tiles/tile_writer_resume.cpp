#include "exocet_mosaic/tiles/tile_writer_resume.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "exocet_common/json_file.h"

namespace exocet_mosaic {
namespace tiles {

namespace fs = std::filesystem;

nlohmann::json tileWriterProgressToJson(const TileWriterProgress& p) {
  nlohmann::json j;
  j["next_frame"] = p.next_frame;
  j["frames_not_on_disk"] = p.frames_not_on_disk;
  j["newest_stamp_s"] = p.newest_stamp_s;
  j["tiles_written"] = p.tiles_written;
  j["images_received"] = p.images_received;
  j["frames_composed"] = p.frames_composed;
  j["frames_lost"] = p.frames_lost;
  j["restarts"] = p.restarts;
  j["finished"] = p.finished;
  return j;
}

namespace {

template <typename T>
T progressField(const nlohmann::json& j, const char* name) {
  const auto it = j.find(name);
  if (it == j.end()) throw std::invalid_argument(std::string("tile writer progress: no '") + name + "'");
  try {
    return it->get<T>();
  } catch (const nlohmann::json::exception& e) {
    throw std::invalid_argument(std::string("tile writer progress: bad '") + name + "': " + e.what());
  }
}

}  // namespace

TileWriterProgress tileWriterProgressFromJson(const nlohmann::json& j) {
  if (!j.is_object()) throw std::invalid_argument("tile writer progress: not a JSON object");
  TileWriterProgress p;
  p.next_frame = progressField<int>(j, "next_frame");
  p.frames_not_on_disk = progressField<int>(j, "frames_not_on_disk");
  p.newest_stamp_s = progressField<double>(j, "newest_stamp_s");
  p.tiles_written = progressField<std::int64_t>(j, "tiles_written");
  p.images_received = progressField<std::int64_t>(j, "images_received");
  p.frames_composed = progressField<std::int64_t>(j, "frames_composed");
  p.frames_lost = progressField<std::int64_t>(j, "frames_lost");
  p.restarts = progressField<int>(j, "restarts");
  p.finished = progressField<bool>(j, "finished");
  if (p.next_frame < 0 || p.frames_not_on_disk < 0 || p.tiles_written < 0 || p.images_received < 0 ||
      p.frames_composed < 0 || p.frames_lost < 0 || p.restarts < 0 || !std::isfinite(p.newest_stamp_s))
    throw std::invalid_argument("tile writer progress: a count is negative or the stamp is not finite");
  return p;
}

std::string tileWriterProgressPath(const std::string& output_dir, const std::string& prefix) {
  return output_dir + "/.exocet_" + prefix + "_progress.json";
}

std::string continuationRefusal(const TileWriterProgress& previous, double first_image_stamp_s, double max_gap_s) {
  std::ostringstream why;
  why.precision(3);
  why << std::fixed;
  const double gap_s = first_image_stamp_s - previous.newest_stamp_s;
  if (!std::isfinite(gap_s))
    why << "the first image's stamp is not finite";
  else if (gap_s < -kContinuationBackToleranceS)
    why << "the first image is stamped " << -gap_s
        << " s before the newest image of the interrupted run (a bag played again from its start)";
  else if (gap_s > max_gap_s)
    why << "the first image is stamped " << gap_s << " s after the newest image of the interrupted run, more than "
        << max_gap_s << " s (another dive)";
  return why.str();
}

namespace {

bool exists(const std::string& path) {
  std::error_code error;
  return fs::exists(path, error);
}

}  // namespace

KeptTiles loadKeptTiles(const std::string& records_dir, const GeoTiffTileWriter& writer) {
  KeptTiles kept;
  const std::string& prefix = writer.config().prefix;
  const std::string& folder = writer.config().output_dir;
  std::vector<fs::path> files;
  std::error_code error;
  for (const auto& entry : fs::directory_iterator(records_dir, error)) {
    const std::string name = entry.path().filename().string();
    if (entry.path().extension() == ".json" && name.rfind(prefix + "_", 0) == 0) files.push_back(entry.path());
  }
  std::sort(files.begin(), files.end());
  for (const fs::path& path : files) {
    TileRecord record;
    try {
      const auto json = exocet_common::readJsonObjectFile<nlohmann::json>(path.string());
      if (!json) throw std::invalid_argument("not a JSON object");
      record = tileRecordFromJson(*json);
    } catch (const std::exception& e) {
      ++kept.unreadable;
      kept.problems.push_back(path.string() + ": " + e.what());
      continue;
    }
    const auto tif = [&](int version) { return folder + "/" + writer.baseName(record.index, version) + ".tif"; };
    // A redraw writes version K + 1 completely, then removes K, then saves the record: a kill between two of these
    // leaves both versions, or the newer one under a record that still names the older.
    int on_disk = 0;
    for (int version = record.version; version <= record.version + 1; ++version)
      if (exists(tif(version))) on_disk = version;
    if (on_disk == 0) {
      ++kept.unreadable;
      kept.problems.push_back(path.string() + ": its tile " + tif(record.version) + " is gone");
      continue;
    }
    for (int version = 1; version < on_disk; ++version)
      if (writer.removeVersion(record.index, version) > 0) ++kept.versions_removed;
    record.version = on_disk;
    kept.records.push_back(std::move(record));
  }
  return kept;
}

int removeTemporariesIn(const std::string& folder) {
  std::vector<fs::path> stale;
  std::error_code error;
  for (const auto& entry : fs::directory_iterator(folder, error)) {
    const std::string name = entry.path().filename().string();
    if (name.size() > 1 && name[0] == '.' && name.find(".partial") != std::string::npos) stale.push_back(entry.path());
  }
  int removed = 0;
  for (const fs::path& path : stale)
    if (fs::remove(path, error)) ++removed;
  return removed;
}

PositionCorrectionTrack readPositionCorrections(const std::string& path, int* left_out) {
  std::ifstream in(path);
  if (!in) throw std::invalid_argument("cannot read the corrections '" + path + "'");
  std::string line;
  std::getline(in, line);
  if (line.rfind("stamp_s,east_m,north_m", 0) != 0)
    throw std::invalid_argument("'" + path + "' does not start with the header stamp_s,east_m,north_m");
  std::vector<double> stamps;
  std::vector<Eigen::Vector2d> values;
  for (int number = 2; std::getline(in, line); ++number) {
    if (line.empty()) continue;
    std::istringstream fields(line);
    double t = 0, e = 0, n = 0;
    char c1 = 0, c2 = 0;
    if (!(fields >> t >> c1 >> e >> c2 >> n) || c1 != ',' || c2 != ',')
      throw std::invalid_argument("'" + path + "' line " + std::to_string(number) +
                                  ": expected stamp_s,east_m,north_m");
    stamps.push_back(t);
    values.emplace_back(e, n);
  }
  PositionCorrectionTrack track;
  const int out = track.set(stamps, values);
  if (left_out != nullptr) *left_out = out;
  return track;
}

}  // namespace tiles
}  // namespace exocet_mosaic
