#include "exocet_mosaic/dive/dive_import.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iomanip>
#include <limits>
#include <map>
#include <memory>
#include <set>
#include <sstream>

#include <dirent.h>
#include <sys/stat.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

// Frame names only (constexpr strings, no ROS dependency), so that the importer and the bag agree on them.
#include "exocet_common/atomic_file.h"
#include "exocet_common/unit_quaternion.h"
#include "exocet_mosaic/ros/dive_topics.h"
#include "exocet_common/geo_reference.h"

namespace exocet_mosaic {
namespace dive {

namespace {

using Kind = DiveImportError::Kind;

[[noreturn]] void fail(Kind kind, const std::string& message) { throw DiveImportError(kind, message); }
[[noreturn]] void failInput(const std::string& message) { fail(Kind::kInput, message); }

constexpr double kPi = 3.14159265358979323846;
constexpr double kDegToRad = kPi / 180.0;
// ros::Time holds unsigned 32-bit seconds: times outside this range cannot be written into a bag.
constexpr double kMaxUnixTime_s = 4294967295.0;

const std::vector<std::string> kTimeColumns = {"t_unix_s", "t", "time", "stamp", "ts"};

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return s;
}

std::string trim(const std::string& s) {
  const auto first = s.find_first_not_of(" \t");
  if (first == std::string::npos) return "";
  const auto last = s.find_last_not_of(" \t");
  return s.substr(first, last - first + 1);
}

std::string join(const std::vector<std::string>& items, const std::string& separator) {
  std::string out;
  for (size_t i = 0; i < items.size(); ++i) out += (i ? separator : "") + items[i];
  return out;
}

std::string baseName(const std::string& path) {
  const auto slash = path.find_last_of('/');
  return slash == std::string::npos ? path : path.substr(slash + 1);
}

std::string extensionOf(const std::string& name) {
  const auto dot = name.find_last_of('.');
  return dot == std::string::npos ? "" : lower(name.substr(dot));
}

std::string formatNumber(double value, int precision = 6) {
  std::ostringstream out;
  out << std::fixed << std::setprecision(precision) << value;
  return out.str();
}

/// Strict number: the whole text, locale-independent; NaN and infinities parse (the caller rejects them by name).
bool parseDouble(const std::string& text_in, double* value) {
  std::string text = trim(text_in);
  if (!text.empty() && text[0] == '+') text.erase(0, 1);
  if (text.empty()) return false;
  const char* end = text.data() + text.size();
  const auto result = std::from_chars(text.data(), end, *value);
  return result.ec == std::errc() && result.ptr == end;
}

enum class PathType { kMissing, kFile, kFolder, kOther };
PathType pathType(const std::string& path) {
  struct stat st;
  if (::stat(path.c_str(), &st) != 0) return PathType::kMissing;
  if (S_ISDIR(st.st_mode)) return PathType::kFolder;
  if (S_ISREG(st.st_mode)) return PathType::kFile;
  return PathType::kOther;
}

/// An input file that must exist and be a regular file; `option` names the argument in messages.
void requireInputFile(const std::string& option, const std::string& path, const std::string& what) {
  switch (pathType(path)) {
    case PathType::kMissing:
      failInput(option + ": " + what + " '" + path + "' does not exist");
    case PathType::kFolder:
      failInput(option + ": '" + path + "' is a folder; expected " + what);
    case PathType::kOther:
      failInput(option + ": '" + path + "' is not a regular file; expected " + what);
    case PathType::kFile:
      break;
  }
  if (::access(path.c_str(), R_OK) != 0)
    fail(Kind::kIo, option + ": cannot read " + what + " '" + path + "': " + std::strerror(errno));
}

// ------------------------------------------------------------------------------------------------------------
// CSV

struct CsvRow {
  int line = 0;
  std::vector<std::string> fields;
};

struct CsvTable {
  std::string path;
  std::string option;              // the command-line option that named the file, for messages
  std::vector<std::string> names;  // header, trimmed and lower-cased
  std::vector<std::string> raw_names;
  std::vector<CsvRow> rows;

  int column(const std::vector<std::string>& candidates) const {
    for (const auto& name : candidates) {
      const auto it = std::find(names.begin(), names.end(), name);
      if (it != names.end()) return static_cast<int>(it - names.begin());
    }
    return -1;
  }
  std::string where(const CsvRow& row, int col) const {
    return option + ": " + path + ": line " + std::to_string(row.line) + ", column '" + raw_names[col] + "'";
  }
  std::string where(const CsvRow& row) const { return option + ": " + path + ": line " + std::to_string(row.line); }
  /// A finite number in `col` of `row`; empty cells are allowed only with `empty` (then *empty is set).
  double number(const CsvRow& row, int col, bool* empty = nullptr) const {
    const std::string text = trim(row.fields[col]);
    if (text.empty()) {
      if (empty) {
        *empty = true;
        return 0.0;
      }
      failInput(where(row, col) + ": empty; a number is required");
    }
    if (empty) *empty = false;
    double value = 0.0;
    if (!parseDouble(text, &value)) failInput(where(row, col) + ": '" + text + "' is not a number");
    if (!std::isfinite(value)) failInput(where(row, col) + ": value '" + text + "' is not finite (NaN or inf)");
    return value;
  }
  /// A time (Unix seconds) in `col` of `row`, in the range a bag can hold.
  double time(const CsvRow& row, int col) const {
    const double t = number(row, col);
    if (t < 0.0 || t > kMaxUnixTime_s)
      failInput(where(row, col) + ": " + trim(row.fields[col]) +
                " is not a time in seconds since the Unix epoch within [0, 4294967295] (milliseconds?)");
    return t;
  }
};

/// Splits one CSV line; fields may be double-quoted (RFC 4180: "" is a quote inside quotes).
std::vector<std::string> splitCsvLine(const std::string& line, bool* unterminated_quote) {
  std::vector<std::string> fields(1);
  bool quoted = false;
  for (size_t i = 0; i < line.size(); ++i) {
    const char c = line[i];
    if (quoted) {
      if (c == '"' && i + 1 < line.size() && line[i + 1] == '"') {
        fields.back() += '"';
        ++i;
      } else if (c == '"') {
        quoted = false;
      } else {
        fields.back() += c;
      }
    } else if (c == '"') {
      quoted = true;
    } else if (c == ',') {
      fields.emplace_back();
    } else {
      fields.back() += c;
    }
  }
  *unterminated_quote = quoted;
  return fields;
}

CsvTable readCsv(const std::string& option, const std::string& path, const std::string& what) {
  requireInputFile(option, path, what);
  std::ifstream in(path);
  if (!in) fail(Kind::kIo, option + ": cannot open " + what + " '" + path + "': " + std::strerror(errno));
  CsvTable table;
  table.path = path;
  table.option = option;
  std::string line;
  int line_number = 0;
  bool have_header = false;
  while (std::getline(in, line)) {
    ++line_number;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line_number == 1 && line.compare(0, 3, "\xEF\xBB\xBF") == 0) line.erase(0, 3);  // UTF-8 byte order mark
    const std::string content = trim(line);
    if (content.empty() || content[0] == '#') continue;
    bool unterminated = false;
    std::vector<std::string> fields = splitCsvLine(line, &unterminated);
    if (unterminated)
      failInput(option + ": " + path + ": line " + std::to_string(line_number) + ": unterminated quote");
    if (!have_header) {
      have_header = true;
      for (const auto& f : fields) {
        table.raw_names.push_back(trim(f));
        table.names.push_back(lower(trim(f)));
      }
      std::set<std::string> seen;
      for (size_t i = 0; i < table.names.size(); ++i) {
        if (table.names[i].empty())
          failInput(option + ": " + path + ": line " + std::to_string(line_number) + ": header column " +
                    std::to_string(i + 1) + " has no name");
        if (!seen.insert(table.names[i]).second)
          failInput(option + ": " + path + ": line " + std::to_string(line_number) + ": column '" + table.raw_names[i] +
                    "' appears twice in the header");
      }
      continue;
    }
    if (fields.size() != table.names.size())
      failInput(option + ": " + path + ": line " + std::to_string(line_number) + " has " +
                std::to_string(fields.size()) + " fields but the header has " + std::to_string(table.names.size()));
    table.rows.push_back({line_number, std::move(fields)});
  }
  if (in.bad()) fail(Kind::kIo, option + ": error reading '" + path + "': " + std::strerror(errno));
  if (!have_header) failInput(option + ": " + path + ": the file is empty; expected a header row and data rows");
  if (table.rows.empty()) failInput(option + ": " + path + ": the file has a header but no data rows");
  return table;
}

int requireTimeColumn(const CsvTable& table) {
  const int col = table.column(kTimeColumns);
  if (col < 0)
    failInput(table.option + ": " + table.path + ": no time column; expected one of " + join(kTimeColumns, ", ") +
              " (the header has: " + join(table.raw_names, ", ") + ")");
  return col;
}

// ------------------------------------------------------------------------------------------------------------
// Orientation conventions

Eigen::Quaterniond rollPitchYaw(double roll_rad, double pitch_rad, double yaw_rad) {
  return Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(pitch_rad, Eigen::Vector3d::UnitY()) *
         Eigen::AngleAxisd(roll_rad, Eigen::Vector3d::UnitX());
}

/// Body (forward, left, up) to world (east, north, up) from a marine attitude: heading clockwise from north, roll
/// and pitch of the forward-right-down body in the north-east-down frame (positive pitch = nose up).
Eigen::Quaterniond fromHeadingNed(double heading_rad, double pitch_rad, double roll_rad) {
  Eigen::Matrix3d enu_from_ned;
  enu_from_ned << 0, 1, 0, 1, 0, 0, 0, 0, -1;
  const Eigen::Matrix3d frd_from_flu = Eigen::Vector3d(1, -1, -1).asDiagonal();
  const Eigen::Matrix3d ned_from_frd = rollPitchYaw(roll_rad, pitch_rad, heading_rad).toRotationMatrix();
  return Eigen::Quaterniond(enu_from_ned * ned_from_frd * frd_from_flu);
}

/// Grid bearing of true north at a point (radians, clockwise from grid north), by a small step north: measured on
/// the projection itself, so it cannot disagree with latLonToGrid's sign conventions.
double gridBearingOfTrueNorth_rad(const exocet_common::GeoReference& datum, double latitude_deg, double longitude_deg) {
  const double step_deg = latitude_deg > 89.0 ? -1e-5 : 1e-5;
  const Eigen::Vector2d a = exocet_common::latLonToGrid(datum, latitude_deg, longitude_deg);
  const Eigen::Vector2d b = exocet_common::latLonToGrid(datum, latitude_deg + step_deg, longitude_deg);
  const Eigen::Vector2d north = (b - a) * (step_deg > 0 ? 1.0 : -1.0);
  return std::atan2(north.x(), north.y());
}

}  // namespace

// ------------------------------------------------------------------------------------------------------------
// Options

ImageEncoding parseImageEncoding(const std::string& name) {
  if (name == "bgr8") return ImageEncoding::kBgr8;
  if (name == "mono8") return ImageEncoding::kMono8;
  failInput("--encoding: '" + name + "' is not one of bgr8, mono8");
}

std::string encodingName(ImageEncoding encoding) { return encoding == ImageEncoding::kBgr8 ? "bgr8" : "mono8"; }

namespace {

const char kDiveImportDescription[] =
    "dive_import: imports a real dive (camera images + navigation CSV + camera intrinsics) into a bag with the\n"
    "layout of the simulator's: /camera/image_raw (or /camera/image_raw/compressed) + /camera/camera_info,\n"
    "/nav/odometry, /nav/depth, /nav/altitude, /nav/datum (geo-referenced dives), /tf_static.\n"
    "Without --nav (video without navigation): images, camera_info, /tf_static and /nav/altitude from --altitude;\n"
    "the start point (--origin-lat/--origin-lon, --heading) goes to the replay, whose command is printed.\n"
    "Frame times: --image-times, or --start-time (with --fps for a folder).";

const char kDiveImportConventions[] = R"(Navigation CSV
  One header row, comma-separated; '#' lines and blank lines skipped; names case-insensitive; other columns
  (e.g. source, target) ignored. One /nav/odometry per row (frame utm or map -> base_link).
  time         first of t_unix_s, t, time, stamp, ts: Unix seconds, never going backwards
  position     x, y, z (metres, x east, y north, z up; x_m, y_m, z_m also accepted), or geodetic lat, lon
               (degrees WGS 84; latitude, longitude, lat_deg, lon_deg also accepted) with z or depth; lat, lon
               take precedence over x, y and make the world frame "utm" (origin: --origin-* or the first row)
  orientation  of base_link (x forward, y left, z up), first found of:
               qx, qy, qz, qw     body-to-world quaternion (normalised; norm must be within 1%)
               yaw_deg            counter-clockwise from the world's x axis; optional roll_deg, pitch_deg about
                                  the body's x, y axes (REP-103)
               heading_deg        clockwise from true north, turned to grid north in a utm frame; optional
                                  roll_deg, pitch_deg in the NED / forward-right-down convention (nose up > 0)
               none               identity, with the orientation covariance set to -1 (unknown)
  depth        depth or depth_m (metres, positive down) -> /nav/depth; without it, depth = -z
  altitude     altitude or altitude_m (metres above the seabed) -> /nav/altitude
  An empty depth or altitude cell means no measurement on that row. Velocities are not imported: the twist
  covariance diagonal is -1 (unknown). NaN or infinite values are errors.

Without --nav
  --altitude M           one /nav/altitude (sensor_msgs/Range, frame altimeter, at base_link) at each image
  --altitude FILE.csv[:COLUMN]
                         time column as above (increasing) and the altitude column (default altitude or
                         altitude_m; metres in (0, 1000]); one /nav/altitude per row within 1 s of the
                         images, and one at each image, interpolated. The images must lie within the rows'
                         time span give or take 1 s (there they take the nearest row's value).
  No /nav/odometry, /nav/depth. The bag replays in the fusion's images-only mode: the tool prints the
  command and writes OUT.bag.replay.json, which replay_dive reads (rosrun exocet_mosaic replay_dive OUT.bag
  OUTDIR). With --origin-lat/--origin-lon the tiles are in that point's UTM zone, the start heading being
  --heading (0 if not given); without them, in the local frame "map" (metres; y along the first heading).

Exit status: 0 done, 2 bad arguments or input (the message names the argument, file, line and column),
1 I/O failure, 128+N killed by signal N (SIGINT, SIGTERM). On any error no file is left under OUT.bag.)";

/// The tool's options as given; parseDiveImportArguments converts and checks them with messages naming each.
struct DiveImportArgumentText {
  std::string images, nav, camera, output, image_times, start_time, fps, origin_lat, origin_lon, heading, altitude,
      encoding, image_storage, camera_pose;
};

/// The command line of dive_import, filling `text`.
std::unique_ptr<CLI::App> diveImportCommandLine(DiveImportArgumentText* text) {
  auto app = std::make_unique<CLI::App>(kDiveImportDescription, "dive_import");
  const auto option = [&](const std::string& name, std::string* value, const std::string& value_name,
                          const std::string& group, const std::string& what) {
    CLI::Option* added = app->add_option(name, *value, what)->group(group);
    if (!value_name.empty()) added->type_name(value_name);
    return added;
  };
  option("--images", &text->images, "DIR|VIDEO", "Inputs",
         "folder of images (.png .jpg .jpeg .tif .tiff .bmp, sorted by file name: zero-pad\n"
         "the numbers) or a video file (any format OpenCV/FFmpeg reads)")
      ->required();
  option("--nav", &text->nav, "NAV.csv", "Inputs",
         "navigation CSV (conventions below); without it, --altitude is required");
  option("--altitude", &text->altitude, "M|FILE.csv[:COLUMN]", "Inputs",
         "without --nav only: the altitude of base_link above the seabed, a constant in\n"
         "metres within (0, 1000] or a CSV of times and altitudes (below)");
  option("--camera", &text->camera, "K.yaml", "Inputs",
         "intrinsics: camera_calibration_parsers YAML (image_width, image_height,\n"
         "camera_matrix, distortion_coefficients) or the short form (image_width,\n"
         "image_height, K: [9], D: [4..5]). Every image must have this size. Required;\n"
         "unknown intrinsics: self_calibrate --images DIR --output K.yaml estimates them,\n"
         "or mosaic_video VIDEO --altitude M --output DIR does it all from a video");
  option("--output", &text->output, "OUT.bag", "Inputs",
         "bag to write; written under a temporary name and renamed when complete")
      ->required();
  option("--image-times", &text->image_times, "INDEX.csv", "Frame times (one of)",
         "header with a time column (t_unix_s, t, time, stamp, ts: Unix seconds) and a file\n"
         "column (file, filename, image: matched by file name) or a frame column (frame,\n"
         "frame_index: frame number from 0 in sorted or video order)");
  option("--start-time", &text->start_time, "UNIX_S", "Frame times (one of)",
         "time of the first frame, in [0, 4294967295] s; frame k at UNIX_S + k / F");
  option("--fps", &text->fps, "F", "Frame times (one of)",
         "frame rate (Hz), in (0, 100000]; required for a folder, defaults to the container's\n"
         "for a video");
  option("--origin-lat", &text->origin_lat, "DEG", "Geo-reference",
         "WGS 84 origin of the CSV's x, y (latitude in [-90, 90], longitude in [-180, 360)):\n"
         "the world frame becomes \"utm\", positions UTM easting = origin easting + x,\n"
         "northing = origin northing + y; a /nav/datum gives the zone and EPSG code. Without\n"
         "an origin or lat, lon columns, the world frame is \"map\" and positions are written\n"
         "as given. Without --nav: the camera's position at the first frame (the start\n"
         "point of the replay), its zone on /nav/datum.");
  option("--origin-lon", &text->origin_lon, "DEG", "Geo-reference", "given with --origin-lat");
  option("--heading", &text->heading, "DEG", "Geo-reference",
         "without --nav only: heading of the vehicle's forward axis (base_link x) at the\n"
         "first frame, degrees clockwise from true north, in [-360, 360]; default 0");
  option("--encoding", &text->encoding, "", "Output",
         "pixel format of the images (default bgr8; mono8 converts to gray)")
      ->check(CLI::IsMember({encodingName(ImageEncoding::kBgr8), encodingName(ImageEncoding::kMono8)}));
  option("--image-storage", &text->image_storage, "", "Output", "sensor_msgs/Image (default raw) or CompressedImage")
      ->check(CLI::IsMember({"raw", "jpeg", "png"}));
  option("--camera-pose", &text->camera_pose, "X,Y,Z,ROLL,PITCH,YAW", "Output",
         "camera optical frame (x right, y down, z along the view) in base_link: metres\n"
         "and degrees, R = Rz(yaw) Ry(pitch) Rx(roll). Default identity (the nav pose is\n"
         "the camera's). A downward camera whose image top points forward on a base_link\n"
         "(x forward, y left, z up) is 0,0,0,180,0,-90.");
  app->footer(kDiveImportConventions);
  return app;
}

}  // namespace

std::string diveImportUsage() {
  DiveImportArgumentText ignored;
  return diveImportCommandLine(&ignored)->help();
}

namespace {

double parseOptionNumber(const std::string& option, const std::string& text) {
  double value = 0.0;
  if (!parseDouble(text, &value)) failInput(option + ": '" + text + "' is not a number");
  if (!std::isfinite(value)) failInput(option + ": '" + text + "' is not finite");
  return value;
}

}  // namespace

Eigen::Isometry3d parseCameraPose(const std::string& text) {
  std::vector<double> v;
  std::stringstream in(text);
  std::string item;
  while (std::getline(in, item, ',')) v.push_back(parseOptionNumber("--camera-pose", item));
  if (v.size() != 6 || (!text.empty() && text.back() == ','))
    failInput("--camera-pose: '" + text + "' must be 6 comma-separated numbers x,y,z,roll,pitch,yaw (m, deg)");
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = rollPitchYaw(v[3] * kDegToRad, v[4] * kDegToRad, v[5] * kDegToRad).toRotationMatrix();
  pose.translation() = Eigen::Vector3d(v[0], v[1], v[2]);
  return pose;
}

AltitudeOption parseAltitudeOption(const std::string& text) {
  AltitudeOption altitude;
  const std::string range = "(0, " + formatNumber(kMaxAltitude_m, 0) + "] m";
  double value = 0.0;
  if (parseDouble(text, &value)) {
    if (!(value > 0.0 && value <= kMaxAltitude_m)) failInput("--altitude: " + trim(text) + " m is not within " + range);
    altitude.constant_m = value;
    return altitude;
  }
  std::string path = text, column;
  const auto colon = text.find_last_of(':');
  if (colon != std::string::npos && lower(text.substr(0, colon)).size() >= 4 &&
      extensionOf(text.substr(0, colon)) == ".csv" && text.find('/', colon) == std::string::npos) {
    path = text.substr(0, colon);
    column = trim(text.substr(colon + 1));
    if (column.empty()) failInput("--altitude: '" + text + "' names no column after ':' (FILE.csv:COLUMN)");
  }
  if (extensionOf(path) != ".csv")
    failInput("--altitude: '" + text + "' is neither an altitude in metres within " + range +
              " nor FILE.csv or FILE.csv:COLUMN");
  altitude.csv_path = path;
  altitude.csv_column = column;
  return altitude;
}

DiveImportOptions parseDiveImportArguments(const std::vector<std::string>& args) {
  DiveImportArgumentText text;
  const std::unique_ptr<CLI::App> app = diveImportCommandLine(&text);
  try {
    std::vector<std::string> reversed(args.rbegin(), args.rend());  // CLI11 takes them last first
    app->parse(reversed);
  } catch (const CLI::CallForHelp&) {
    DiveImportOptions help;
    help.help = true;
    return help;
  } catch (const CLI::ParseError& e) {
    failInput(std::string(e.what()) + " (see --help)");
  }

  DiveImportOptions o;
  const auto take = [&](const std::string& name, const std::string& given, std::string* out) {
    if (app->count(name) == 0) return false;
    if (given.empty()) failInput(name + " has an empty value");
    *out = given;
    return true;
  };
  take("--images", text.images, &o.images_path);
  take("--nav", text.nav, &o.nav_path);
  take("--output", text.output, &o.output_path);
  if (!take("--camera", text.camera, &o.camera_path))
    failInput(
        "--camera is required: the bag's /camera/camera_info needs the camera's intrinsics. Unknown intrinsics: "
        "estimate them from the dive's images first with `rosrun exocet_mosaic self_calibrate --images DIR --output "
        "camera.yaml` (a folder of images; or --bag BAG --image-topic TOPIC) and give --camera camera.yaml; or, for a "
        "video, run `rosrun exocet_mosaic mosaic_video VIDEO --altitude M --output DIR`, which self-calibrates and "
        "mosaics it in one go");
  std::string altitude_text, heading_text;
  const bool has_altitude = take("--altitude", text.altitude, &altitude_text);
  const bool has_heading = take("--heading", text.heading, &heading_text);
  if (!o.nav_path.empty()) {
    if (has_altitude)
      failInput("--altitude cannot be combined with --nav: the navigation CSV's altitude column gives /nav/altitude");
    if (has_heading)
      failInput(
          "--heading cannot be combined with --nav: the navigation CSV gives the orientation (qx..qw, yaw_deg or "
          "heading_deg columns)");
  } else {
    if (!has_altitude)
      failInput("--altitude is required without --nav: the camera's scale needs the altitude above the seabed, a " +
                std::string("constant in metres within (0, ") + formatNumber(kMaxAltitude_m, 0) +
                "] or FILE.csv[:COLUMN]");
    o.altitude = parseAltitudeOption(altitude_text);
    if (has_heading) {
      const double heading_deg = parseOptionNumber("--heading", heading_text);
      if (heading_deg < -360.0 || heading_deg > 360.0)
        failInput("--heading: " + heading_text + " is not within [-360, 360] degrees (clockwise from true north)");
      o.heading_deg = heading_deg;
    }
  }
  take("--image-times", text.image_times, &o.image_times_path);
  std::string start_text;
  if (take("--start-time", text.start_time, &start_text))
    o.start_time_s = parseOptionNumber("--start-time", start_text);
  std::string fps_text;
  if (take("--fps", text.fps, &fps_text)) o.fps = parseOptionNumber("--fps", fps_text);
  if (!o.image_times_path.empty() && (o.start_time_s || o.fps))
    failInput("--image-times cannot be combined with --start-time/--fps: give one way of timing the frames");
  if (o.image_times_path.empty() && !o.start_time_s)
    failInput("frame times needed: give --image-times INDEX.csv or --start-time UNIX_S (and --fps for a folder)");
  if (o.start_time_s && (*o.start_time_s < 0.0 || *o.start_time_s > kMaxUnixTime_s))
    failInput("--start-time: " + start_text + " is not within [0, 4294967295] seconds since the Unix epoch");
  if (o.fps && !(*o.fps > 0.0 && *o.fps <= 100000.0)) failInput("--fps: must be within (0, 100000] Hz");
  std::string lat_text, lon_text;
  const bool has_lat = take("--origin-lat", text.origin_lat, &lat_text);
  const bool has_lon = take("--origin-lon", text.origin_lon, &lon_text);
  if (has_lat != has_lon) failInput("--origin-lat and --origin-lon must be given together");
  if (has_lat) {
    GeoOrigin origin;
    origin.latitude_deg = parseOptionNumber("--origin-lat", lat_text);
    origin.longitude_deg = parseOptionNumber("--origin-lon", lon_text);
    if (origin.latitude_deg < -90.0 || origin.latitude_deg > 90.0)
      failInput("--origin-lat: " + lat_text + " is not within [-90, 90] degrees");
    if (origin.longitude_deg < -180.0 || origin.longitude_deg >= 360.0)
      failInput("--origin-lon: " + lon_text + " is not within [-180, 360) degrees");
    o.origin = origin;
  }
  std::string value;
  if (take("--encoding", text.encoding, &value)) o.encoding = parseImageEncoding(value);
  if (take("--image-storage", text.image_storage, &value)) o.image_storage = value;
  if (take("--camera-pose", text.camera_pose, &value)) o.base_from_camera = parseCameraPose(value);
  return o;
}

// ------------------------------------------------------------------------------------------------------------
// Navigation

NavigationTable readNavigationCsv(const std::string& path, const std::optional<GeoOrigin>& origin) {
  const CsvTable table = readCsv("--nav", path, "navigation CSV");
  const std::string where_file = "--nav: " + path;
  NavigationTable nav;
  std::set<int> used;
  const auto find = [&](const std::vector<std::string>& names) {
    const int col = table.column(names);
    if (col >= 0) used.insert(col);
    return col;
  };
  const int c_time = requireTimeColumn(table);
  used.insert(c_time);
  nav.time_column = table.raw_names[c_time];

  const int c_lat = find({"lat", "latitude", "lat_deg", "latitude_deg"});
  const int c_lon = find({"lon", "longitude", "lon_deg", "longitude_deg"});
  if ((c_lat < 0) != (c_lon < 0))
    failInput(where_file + ": has a " + (c_lat >= 0 ? "latitude" : "longitude") + " column but no " +
              (c_lat >= 0 ? "longitude (lon)" : "latitude (lat)") + " column");
  const bool geodetic = c_lat >= 0;
  int c_x = -1, c_y = -1;
  if (!geodetic) {
    c_x = find({"x", "x_m"});
    c_y = find({"y", "y_m"});
    if (c_x < 0 || c_y < 0)
      failInput(where_file + ": no position columns; expected x, y (local metres) or lat, lon (degrees WGS 84)" +
                " (the header has: " + join(table.raw_names, ", ") + ")");
  }
  const int c_z = find({"z", "z_m"});
  const int c_depth = find({"depth", "depth_m"});
  const int c_altitude = find({"altitude", "altitude_m"});
  if (c_z < 0 && c_depth < 0)
    failInput(where_file + ": no vertical position; expected a z column (metres, up) or a depth column (metres, down)");
  nav.position_columns = std::string(geodetic ? "lat,lon," : "x,y,") + (c_z >= 0 ? "z" : "depth");

  // Orientation: a quaternion, else a yaw, else a heading; rows keep what the first found convention says.
  const std::vector<std::string> q_names = {"qx", "qy", "qz", "qw"};
  std::vector<int> c_q;
  std::vector<std::string> q_missing;
  for (const auto& n : q_names) {
    c_q.push_back(table.column({n}));
    if (c_q.back() < 0) q_missing.push_back(n);
  }
  const bool has_quaternion = q_missing.empty();
  if (!has_quaternion && q_missing.size() < 4)
    failInput(where_file + ": quaternion columns incomplete: missing " + join(q_missing, ", "));
  int c_yaw = -1, c_heading = -1, c_roll = -1, c_pitch = -1;
  if (has_quaternion) {
    for (int c : c_q) used.insert(c);
    nav.orientation_columns = "qx,qy,qz,qw";
  } else {
    c_yaw = table.column({"yaw_deg"});
    if (c_yaw < 0) c_heading = table.column({"heading_deg"});
    c_roll = table.column({"roll_deg"});
    c_pitch = table.column({"pitch_deg"});
    if (c_yaw < 0 && c_heading < 0 && (c_roll >= 0 || c_pitch >= 0))
      failInput(where_file + ": roll_deg/pitch_deg need a yaw_deg or heading_deg column (or give qx, qy, qz, qw)");
    for (int c : {c_yaw, c_heading, c_roll, c_pitch})
      if (c >= 0) used.insert(c);
    nav.orientation_columns = c_yaw >= 0 ? "yaw_deg" : c_heading >= 0 ? "heading_deg" : "none";
    if (c_roll >= 0) nav.orientation_columns += ",roll_deg";
    if (c_pitch >= 0) nav.orientation_columns += ",pitch_deg";
  }
  for (size_t i = 0; i < table.raw_names.size(); ++i)
    if (!used.count(static_cast<int>(i))) nav.ignored_columns.push_back(table.raw_names[i]);

  // World frame and datum.
  if (origin || geodetic) {
    nav.world_frame = "utm";
    try {
      if (origin) {
        nav.datum = exocet_common::makeGeoReference(origin->latitude_deg, origin->longitude_deg);
      } else {
        const CsvRow& first = table.rows.front();
        nav.datum = exocet_common::makeGeoReference(table.number(first, c_lat), table.number(first, c_lon));
      }
    } catch (const std::invalid_argument& e) {
      failInput((origin ? std::string("--origin-lat/--origin-lon") : table.where(table.rows.front())) + ": " +
                e.what());
    }
  }

  double min_altitude_m = std::numeric_limits<double>::infinity();
  double max_altitude_m = 0.0;
  const CsvRow* previous = nullptr;
  for (const CsvRow& row : table.rows) {
    NavigationRow out;
    out.line = row.line;
    const double t = table.time(row, c_time);
    if (previous && t < nav.rows.back().pose.stamp_s)
      failInput(table.where(row, c_time) + ": time " + formatNumber(t) + " s goes backwards from " +
                formatNumber(nav.rows.back().pose.stamp_s) + " s on line " + std::to_string(previous->line));
    out.pose.stamp_s = t;

    double lat_deg = 0.0, lon_deg = 0.0;
    Eigen::Vector2d horizontal;
    if (geodetic) {
      lat_deg = table.number(row, c_lat);
      lon_deg = table.number(row, c_lon);
      if (lat_deg < -90.0 || lat_deg > 90.0)
        failInput(table.where(row, c_lat) + ": latitude " + trim(row.fields[c_lat]) + " not within [-90, 90] deg");
      if (lon_deg < -180.0 || lon_deg >= 360.0)
        failInput(table.where(row, c_lon) + ": longitude " + trim(row.fields[c_lon]) + " not within [-180, 360) deg");
      horizontal = exocet_common::latLonToGrid(*nav.datum, lat_deg, lon_deg);
    } else {
      horizontal = Eigen::Vector2d(table.number(row, c_x), table.number(row, c_y));
      if (nav.datum) horizontal += Eigen::Vector2d(nav.datum->origin_easting_m, nav.datum->origin_northing_m);
    }
    bool depth_empty = true;
    const double depth_m = c_depth >= 0 ? table.number(row, c_depth, &depth_empty) : 0.0;
    double z_m = 0.0;
    if (c_z >= 0) {
      z_m = table.number(row, c_z);
    } else if (depth_empty) {
      failInput(table.where(row, c_depth) + ": empty, and there is no z column to give the vertical position");
    } else {
      z_m = -depth_m;
    }
    out.pose.position_m = Eigen::Vector3d(horizontal.x(), horizontal.y(), z_m);
    if (c_depth >= 0 && !depth_empty) {
      out.depth = DepthRecord{t, depth_m, 0.0};
    } else if (c_depth < 0) {
      out.depth = DepthRecord{t, -z_m, 0.0};
    }
    if (c_altitude >= 0) {
      bool empty = false;
      const double altitude_m = table.number(row, c_altitude, &empty);
      if (!empty) {
        if (altitude_m < 0.0)
          failInput(table.where(row, c_altitude) + ": altitude " + trim(row.fields[c_altitude]) + " m is negative");
        AltitudeRecord a;
        a.stamp_s = t;
        a.range_m = altitude_m;
        out.altitude = a;
        min_altitude_m = std::min(min_altitude_m, altitude_m);
        max_altitude_m = std::max(max_altitude_m, altitude_m);
      }
    }

    if (has_quaternion) {
      const Eigen::Quaterniond q(table.number(row, c_q[3]), table.number(row, c_q[0]), table.number(row, c_q[1]),
                                 table.number(row, c_q[2]));
      if (!exocet_common::isUnitQuaternion(q.w(), q.x(), q.y(), q.z()))
        failInput(table.where(row) + ": quaternion (qx, qy, qz, qw) has norm " + formatNumber(q.norm()) +
                  "; expected 1 (within 1%)");
      out.pose.orientation = q.normalized();
    } else if (c_yaw >= 0 || c_heading >= 0) {
      const double roll_rad = c_roll >= 0 ? table.number(row, c_roll) * kDegToRad : 0.0;
      const double pitch_rad = c_pitch >= 0 ? table.number(row, c_pitch) * kDegToRad : 0.0;
      if (c_yaw >= 0) {
        out.pose.orientation = rollPitchYaw(roll_rad, pitch_rad, table.number(row, c_yaw) * kDegToRad);
      } else {
        double heading_rad = table.number(row, c_heading) * kDegToRad;
        if (nav.datum) {
          // A compass heading is from true north; the utm frame's y axis is grid north.
          if (!geodetic) {
            const Eigen::Vector2d ll = exocet_common::gridToLatLon(*nav.datum, horizontal.x(), horizontal.y());
            lat_deg = ll.x();
            lon_deg = ll.y();
          }
          heading_rad += gridBearingOfTrueNorth_rad(*nav.datum, lat_deg, lon_deg);
        }
        out.pose.orientation = fromHeadingNed(heading_rad, pitch_rad, roll_rad);
      }
    } else {
      // Unknown orientation: -1 on the diagonal, as for the DVL's unmeasured angular part.
      for (int i = 3; i < 6; ++i) out.pose.pose_covariance(i, i) = -1.0;
    }
    // Velocities are not in the CSV: mark them unknown rather than claim a perfectly known zero.
    for (int i = 0; i < 6; ++i) out.pose.twist_covariance(i, i) = -1.0;
    nav.rows.push_back(out);
    previous = &row;
  }
  // One range span for the whole dive, so that every altitude lies inside [min_range, max_range].
  for (auto& row : nav.rows)
    if (row.altitude) {
      row.altitude->min_range_m = std::min(row.altitude->min_range_m, min_altitude_m);
      row.altitude->max_range_m = std::max(row.altitude->max_range_m, max_altitude_m);
    }
  return nav;
}

// ------------------------------------------------------------------------------------------------------------
// Altitude without navigation

namespace {

/// Altitude record with the conventions of the navigation's (frame altimeter, written by the bag writer).
AltitudeRecord altitudeRecord(double stamp_s, double altitude_m) {
  AltitudeRecord a;
  a.stamp_s = stamp_s;
  a.range_m = altitude_m;
  return a;
}

/// Widens the records' [min_range_m, max_range_m] to hold every value, as the navigation's altitude does.
void coverRangeSpan(std::vector<AltitudeRecord>* records) {
  double lo = std::numeric_limits<double>::infinity(), hi = 0.0;
  for (const auto& a : *records) {
    lo = std::min(lo, a.range_m);
    hi = std::max(hi, a.range_m);
  }
  for (auto& a : *records) {
    a.min_range_m = std::min(a.min_range_m, lo);
    a.max_range_m = std::max(a.max_range_m, hi);
  }
}

}  // namespace

AltitudeTable readAltitudeCsv(const std::string& path, const std::string& column) {
  const CsvTable table = readCsv("--altitude", path, "altitude CSV");
  const int c_time = requireTimeColumn(table);
  const std::vector<std::string> names =
      column.empty() ? std::vector<std::string>{"altitude", "altitude_m"} : std::vector<std::string>{lower(column)};
  const int c_altitude = table.column(names);
  if (c_altitude < 0)
    failInput("--altitude: " + path + ": no altitude column; expected " + join(names, " or ") +
              (column.empty() ? " (or name it: --altitude FILE.csv:COLUMN)" : "") +
              " (the header has: " + join(table.raw_names, ", ") + ")");
  AltitudeTable out;
  out.path = path;
  out.time_column = table.raw_names[c_time];
  out.altitude_column = table.raw_names[c_altitude];
  const std::string range = "(0, " + formatNumber(kMaxAltitude_m, 0) + "] m";
  int previous_line = 0;
  for (const CsvRow& row : table.rows) {
    const double t = table.time(row, c_time);
    bool empty = false;
    const double altitude_m = table.number(row, c_altitude, &empty);
    if (empty) continue;  // no measurement on that row
    if (!(altitude_m > 0.0 && altitude_m <= kMaxAltitude_m))
      failInput(table.where(row, c_altitude) + ": altitude " + trim(row.fields[c_altitude]) + " m is not within " +
                range);
    if (!out.rows.empty() && !(t > out.rows.back().stamp_s))
      failInput(table.where(row, c_time) + ": time " + formatNumber(t) + " s is not after " +
                formatNumber(out.rows.back().stamp_s) + " s on line " + std::to_string(previous_line) +
                "; times must increase");
    out.rows.push_back(altitudeRecord(t, altitude_m));
    previous_line = row.line;
  }
  if (out.rows.empty()) failInput("--altitude: " + path + ": no row has an altitude");
  coverRangeSpan(&out.rows);
  return out;
}

double AltitudeTable::at(double stamp_s) const {
  if (stamp_s <= rows.front().stamp_s) return rows.front().range_m;
  if (stamp_s >= rows.back().stamp_s) return rows.back().range_m;
  const auto after = std::lower_bound(rows.begin(), rows.end(), stamp_s,
                                      [](const AltitudeRecord& a, double t) { return a.stamp_s < t; });
  const auto before = after - 1;
  const double w = (stamp_s - before->stamp_s) / (after->stamp_s - before->stamp_s);
  return (1.0 - w) * before->range_m + w * after->range_m;
}

namespace {

/// Throws naming --altitude when a frame at `stamp_s` is outside the table's span by more than the margin.
void requireAltitudeCovers(const AltitudeTable& table, double stamp_s, const std::string& frame_name) {
  const double first_s = table.rows.front().stamp_s, last_s = table.rows.back().stamp_s;
  if (stamp_s >= first_s - kAltitudeCsvMargin_s && stamp_s <= last_s + kAltitudeCsvMargin_s) return;
  const double off_s = stamp_s < first_s ? first_s - stamp_s : stamp_s - last_s;
  failInput("--altitude: " + frame_name + " at " + formatNumber(stamp_s) + " s is " + formatNumber(off_s, 3) + " s " +
            (stamp_s < first_s ? "before the first" : "after the last") + " row of '" + table.path + "' (rows from " +
            formatNumber(first_s) + " to " + formatNumber(last_s) + " s); the images must lie " +
            "within the altitude's time span give or take " + formatNumber(kAltitudeCsvMargin_s, 1) + " s");
}

}  // namespace

// ------------------------------------------------------------------------------------------------------------
// Images and their times

const std::vector<std::string>& imageFileExtensions() {
  static const std::vector<std::string> kExtensions = {".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp"};
  return kExtensions;
}

ImageSource listImages(const std::string& path) {
  ImageSource source;
  source.path = path;
  const PathType type = pathType(path);
  if (type == PathType::kMissing) failInput("--images: '" + path + "' does not exist (expected a folder or a video)");
  if (type == PathType::kOther) failInput("--images: '" + path + "' is neither a folder nor a video file");
  const auto& extensions = imageFileExtensions();
  if (type == PathType::kFolder) {
    source.kind = ImageSource::Kind::kFolder;
    DIR* dir = ::opendir(path.c_str());
    if (!dir) fail(Kind::kIo, "--images: cannot list folder '" + path + "': " + std::strerror(errno));
    std::vector<std::string> names;
    while (const dirent* entry = ::readdir(dir)) {
      const std::string name = entry->d_name;
      if (name.empty() || name[0] == '.') continue;
      if (std::find(extensions.begin(), extensions.end(), extensionOf(name)) == extensions.end()) continue;
      if (pathType(path + "/" + name) != PathType::kFile) continue;
      names.push_back(name);
    }
    ::closedir(dir);
    if (names.empty()) failInput("--images: folder '" + path + "' has no images (" + join(extensions, " ") + ")");
    std::sort(names.begin(), names.end());
    const std::string prefix = path.back() == '/' ? path : path + "/";
    for (const auto& name : names) source.files.push_back(prefix + name);
    source.frame_count = static_cast<int>(source.files.size());
    return source;
  }
  if (std::find(extensions.begin(), extensions.end(), extensionOf(path)) != extensions.end())
    failInput("--images: '" + path + "' is a single image; give the folder that holds the images, or a video");
  if (::access(path.c_str(), R_OK) != 0)
    fail(Kind::kIo, "--images: cannot read video '" + path + "': " + std::strerror(errno));
  source.kind = ImageSource::Kind::kVideo;
  cv::VideoCapture video(path);
  cv::Mat first;
  if (!video.isOpened() || !video.read(first) || first.empty())
    failInput("--images: cannot decode '" + path + "' as a video (OpenCV/FFmpeg), and it is not a folder");
  source.container_fps = video.get(cv::CAP_PROP_FPS);
  if (!std::isfinite(source.container_fps) || source.container_fps < 0.0) source.container_fps = 0.0;
  const double count = video.get(cv::CAP_PROP_FRAME_COUNT);
  source.frame_count = std::isfinite(count) && count > 0 ? static_cast<int>(std::lround(count)) : 0;
  return source;
}

double FrameTimes::stampOf(int index, const std::string& name) const {
  if (from_rate) return start_time_s + index / fps;
  if (index >= 0 && index < static_cast<int>(stamps_s.size()) && !std::isnan(stamps_s[index])) return stamps_s[index];
  failInput("--image-times: " + name + " has no row in '" + source + "'");
}

FrameTimes frameTimesFromIndex(const ImageSource& images, const std::string& index_path) {
  const CsvTable table = readCsv("--image-times", index_path, "frame time index CSV");
  const int c_time = requireTimeColumn(table);
  const int c_file = table.column({"file", "filename", "image"});
  const int c_frame = table.column({"frame", "frame_index"});
  const bool folder = images.kind == ImageSource::Kind::kFolder;
  if (!folder && c_frame < 0)
    failInput("--image-times: " + index_path + ": a video needs a frame column (frame, frame_index)");
  if (c_file < 0 && c_frame < 0)
    failInput("--image-times: " + index_path +
              ": no file column (file, filename, image) or frame column (frame, frame_index)");
  FrameTimes times;
  times.source = index_path;
  const bool by_file = folder && c_file >= 0;
  std::vector<int> lines;  // index line of each frame's time, for messages

  std::map<std::string, int> folder_index;  // file name -> frame number
  if (by_file)
    for (size_t k = 0; k < images.files.size(); ++k) folder_index[baseName(images.files[k])] = static_cast<int>(k);
  if (folder) {
    times.stamps_s.assign(images.files.size(), std::numeric_limits<double>::quiet_NaN());
    lines.assign(images.files.size(), 0);
  }
  std::map<std::string, int> seen_names;
  for (const CsvRow& row : table.rows) {
    const double t = table.time(row, c_time);
    int k = -1;
    if (by_file) {
      const std::string name = baseName(trim(row.fields[c_file]));
      if (name.empty()) failInput(table.where(row, c_file) + ": empty file name");
      const auto [it, inserted] = seen_names.emplace(name, row.line);
      if (!inserted)
        failInput(table.where(row, c_file) + ": file name '" + name + "' already on line " +
                  std::to_string(it->second) + " (rows are matched to images by file name)");
      const auto found = folder_index.find(name);
      if (found == folder_index.end()) {
        ++times.unused_index_rows;
        continue;
      }
      k = found->second;
    } else {
      const double frame = table.number(row, c_frame);
      if (frame < 0.0 || frame > 1e8 || frame != std::floor(frame))
        failInput(table.where(row, c_frame) + ": '" + trim(row.fields[c_frame]) +
                  "' is not a frame number (an integer from 0)");
      k = static_cast<int>(frame);
      if (folder && k >= static_cast<int>(images.files.size())) {
        ++times.unused_index_rows;
        continue;
      }
      if (k >= static_cast<int>(times.stamps_s.size())) {
        times.stamps_s.resize(k + 1, std::numeric_limits<double>::quiet_NaN());
        lines.resize(k + 1, 0);
      }
      if (!std::isnan(times.stamps_s[k]))
        failInput(table.where(row, c_frame) + ": frame " + std::to_string(k) + " already on line " +
                  std::to_string(lines[k]));
    }
    times.stamps_s[k] = t;
    lines[k] = row.line;
  }
  const auto frameName = [&](int k) {
    return folder ? "image '" + baseName(images.files[k]) + "'" : "video frame " + std::to_string(k);
  };
  for (size_t k = 0; k < times.stamps_s.size() && folder; ++k)
    if (std::isnan(times.stamps_s[k]))
      failInput("--image-times: " + frameName(static_cast<int>(k)) + " has no row in '" + index_path + "'" +
                (by_file ? " (rows are matched by file name)" : " (rows are matched by frame number)"));
  int previous = -1;
  for (size_t k = 0; k < times.stamps_s.size(); ++k) {
    if (std::isnan(times.stamps_s[k])) continue;
    if (previous >= 0 && !(times.stamps_s[k] > times.stamps_s[previous]))
      failInput("--image-times: " + index_path + ": line " + std::to_string(lines[k]) + ": time of " +
                frameName(static_cast<int>(k)) + " (" + formatNumber(times.stamps_s[k]) + " s) is not after that of " +
                frameName(previous) + " (" + formatNumber(times.stamps_s[previous]) + " s, line " +
                std::to_string(lines[previous]) + "); frame times must increase");
    previous = static_cast<int>(k);
  }
  if (previous < 0) failInput("--image-times: " + index_path + ": no row names a frame of '" + images.path + "'");
  return times;
}

FrameTimes frameTimesFromRate(const ImageSource& images, double start_time_s, double fps) {
  FrameTimes times;
  times.from_rate = true;
  times.source = "--start-time/--fps";
  times.start_time_s = start_time_s;
  times.fps = fps;
  if (!(fps > 0.0)) {
    if (images.kind == ImageSource::Kind::kFolder)
      failInput("--fps is required with --start-time for a folder of images (or give --image-times)");
    if (!(images.container_fps > 0.0))
      failInput("--images: video '" + images.path + "' does not give its frame rate; give --fps");
    times.fps = images.container_fps;
  }
  if (images.kind == ImageSource::Kind::kFolder) {
    const double last_s = start_time_s + (images.frame_count - 1) / times.fps;
    if (last_s > kMaxUnixTime_s) failInput("--start-time/--fps: the last frame's time is beyond 4294967295 s");
    for (int k = 0; k < images.frame_count; ++k) times.stamps_s.push_back(start_time_s + k / times.fps);
  }
  return times;
}

FrameReader::FrameReader(const ImageSource& images, const FrameTimes& times, const exocet_common::CameraModel& camera,
                         ImageEncoding encoding)
    : images_(images), times_(times), camera_(camera), encoding_(encoding) {
  if (images_.kind == ImageSource::Kind::kVideo && !video_.open(images_.path))
    fail(Kind::kIo, "--images: cannot open video '" + images_.path + "'");
}

bool FrameReader::next(CameraFrame* frame) {
  const int k = next_index_;
  cv::Mat image;
  std::string name;
  if (images_.kind == ImageSource::Kind::kFolder) {
    if (k >= static_cast<int>(images_.files.size())) return false;
    const std::string& file = images_.files[k];
    name = "image '" + file + "'";
    image = cv::imread(file, cv::IMREAD_COLOR);
    if (image.empty()) {
      if (::access(file.c_str(), R_OK) != 0)
        fail(Kind::kIo, "--images: cannot read " + name + ": " + std::strerror(errno));
      failInput("--images: cannot decode " + name + " (" + join(imageFileExtensions(), " ") + " via OpenCV)");
    }
  } else {
    // The container's frame count can be approximate: the end of the stream is the end of the dive.
    if (!video_.read(image) || image.empty()) {
      if (k == 0) failInput("--images: video '" + images_.path + "' has no frames");
      return false;
    }
    name = "frame " + std::to_string(k) + " of video '" + images_.path + "'";
  }
  if (image.cols != camera_.width || image.rows != camera_.height)
    failInput("--images: " + name + " is " + std::to_string(image.cols) + "x" + std::to_string(image.rows) +
              " pixels but the camera (--camera) is " + std::to_string(camera_.width) + "x" +
              std::to_string(camera_.height));
  if (image.channels() != 3 || image.depth() != CV_8U)
    failInput("--images: " + name + " did not decode to 8-bit colour");
  if (encoding_ == ImageEncoding::kMono8) cv::cvtColor(image, image, cv::COLOR_BGR2GRAY);
  frame->stamp_s = times_.stampOf(k, name);
  frame->index = k;
  frame->image = image;
  frame->encoding = encodingName(encoding_);
  ++next_index_;
  return true;
}

// ------------------------------------------------------------------------------------------------------------
// The whole import

DiveImport prepareDiveImport(const DiveImportOptions& options) {
  DiveImport dive;
  dive.options = options;
  requireInputFile("--camera", options.camera_path, "camera intrinsics YAML");
  try {
    dive.camera = exocet_common::loadCameraModelYaml(options.camera_path);
  } catch (const std::runtime_error& e) {
    failInput(std::string("--camera: ") + e.what());
  }
  dive.images = listImages(options.images_path);
  if (!options.image_times_path.empty()) {
    dive.times = frameTimesFromIndex(dive.images, options.image_times_path);
    if (dive.times.unused_index_rows > 0)
      dive.warnings.push_back(std::to_string(dive.times.unused_index_rows) + " row(s) of '" + options.image_times_path +
                              "' name no image of '" + options.images_path + "'");
  } else {
    dive.times = frameTimesFromRate(dive.images, options.start_time_s.value_or(0.0), options.fps.value_or(0.0));
  }
  if (dive.hasNavigation()) {
    dive.navigation = readNavigationCsv(options.nav_path, options.origin);
  } else {
    if (!options.altitude) failInput("--altitude is required without --nav");
    if (options.origin) {
      dive.navigation.world_frame = "utm";
      try {
        dive.navigation.datum =
            exocet_common::makeGeoReference(options.origin->latitude_deg, options.origin->longitude_deg);
      } catch (const std::invalid_argument& e) {
        failInput(std::string("--origin-lat/--origin-lon: ") + e.what());
      }
    }
    // The fusion's start heading is from grid north: turned by the meridian convergence at the start point.
    double heading_deg = options.heading_deg.value_or(0.0);
    if (dive.navigation.datum) {
      const GeoOrigin& start = *options.origin;
      heading_deg +=
          gridBearingOfTrueNorth_rad(*dive.navigation.datum, start.latitude_deg, start.longitude_deg) / kDegToRad;
    }
    dive.initial_grid_heading_deg = heading_deg;
    if (!options.heading_deg)
      dive.warnings.push_back("no --heading: the replay takes the vehicle as heading north at the first frame");
    if (!options.altitude->csv_path.empty()) {
      dive.altitude_table = readAltitudeCsv(options.altitude->csv_path, options.altitude->csv_column);
      // The frames whose times are known now (a folder, an indexed video); the others are checked as they come.
      for (size_t k = 0; k < dive.times.stamps_s.size(); ++k)
        if (!std::isnan(dive.times.stamps_s[k]))
          requireAltitudeCovers(*dive.altitude_table, dive.times.stamps_s[k],
                                dive.images.kind == ImageSource::Kind::kFolder
                                    ? "image '" + baseName(dive.images.files[k]) + "'"
                                    : "video frame " + std::to_string(k));
    }
  }
  if (pathType(options.output_path) == PathType::kFolder)
    failInput("--output: '" + options.output_path + "' is a folder; give the bag's file name");
  const std::string problem = exocet_common::checkWritableDestination(options.output_path);
  if (!problem.empty()) failInput("--output: cannot write '" + options.output_path + "': " + problem);
  StaticTransform camera_mount;
  camera_mount.parent_frame = frames::kBaseLink;
  camera_mount.child_frame = frames::kCameraOptical;
  camera_mount.parent_from_child = options.base_from_camera;
  dive.static_transforms.push_back(camera_mount);
  bool altitude = !dive.hasNavigation();
  for (const auto& row : dive.navigation.rows) altitude = altitude || row.altitude.has_value();
  if (altitude) {
    // The fusion places the altimeter by tf: the altitude is base_link's (the CSV's convention), so at its origin.
    StaticTransform altimeter_mount;
    altimeter_mount.parent_frame = frames::kBaseLink;
    altimeter_mount.child_frame = frames::kAltimeter;
    dive.static_transforms.push_back(altimeter_mount);
  }
  return dive;
}

std::vector<ReplayArgument> replayArguments(const DiveImport& dive) {
  std::vector<ReplayArgument> arguments = {{"ground_truth", "false"}};
  if (dive.hasNavigation()) return arguments;
  arguments.push_back({"fusion_preset", "images_only"});
  if (dive.options.origin) {
    arguments.push_back({"origin_lat", formatNumber(dive.options.origin->latitude_deg, 8)});
    arguments.push_back({"origin_lon", formatNumber(dive.options.origin->longitude_deg, 8)});
  }
  arguments.push_back({"heading_deg", formatNumber(dive.initial_grid_heading_deg.value_or(0.0), 4)});
  return arguments;
}

std::string replaySidecarPath(const std::string& bag_path) { return bag_path + ".replay.json"; }

std::string replayCommand(const std::string& bag_path, const std::string& output_dir,
                          const std::vector<ReplayArgument>& arguments) {
  const auto quoted = [](const std::string& word) {
    const bool plain = !word.empty() && std::all_of(word.begin(), word.end(), [](unsigned char c) {
      return std::isalnum(c) || std::strchr("_-+=:,./@%", c) != nullptr;
    });
    if (plain) return word;
    std::string out = "'";
    for (char c : word) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
    return out + "'";
  };
  std::string command = "rosrun exocet_mosaic replay_dive " + quoted(bag_path) + " " + quoted(output_dir);
  for (const auto& a : arguments) command += " " + quoted(a.name + ":=" + a.value);
  return command;
}

std::string DiveImportSummary::line(const std::string& output_path) const {
  std::ostringstream out;
  out << "dive_import: " << frames << " frames, ";
  if (navigation)
    out << nav_rows << " nav rows (" << depth_records << " depth, " << altitude_records << " altitude), ";
  else
    out << "no navigation (" << altitude_records << " altitude), ";
  out << std::fixed << std::setprecision(3) << duration_s() << " s from " << first_stamp_s << " (Unix s), world frame "
      << world_frame << " -> " << output_path;
  return out.str();
}

std::vector<std::string> DiveImportSummary::warnings() const {
  std::vector<std::string> out;
  // Downstream nodes interpolate the navigation at each frame: outside its span they can only extrapolate.
  if (frames_before_nav > 0)
    out.push_back(std::to_string(frames_before_nav) + " frame(s) before the first navigation row");
  if (frames_after_nav > 0) out.push_back(std::to_string(frames_after_nav) + " frame(s) after the last navigation row");
  return out;
}

DiveImportSummary writeDiveImport(const DiveImport& dive, DiveRecordSink* sink) {
  DiveImportSummary summary;
  summary.world_frame = dive.navigation.world_frame;
  summary.navigation = dive.hasNavigation();
  const auto& rows = dive.navigation.rows;
  FrameReader reader(dive.images, dive.times, dive.camera, dive.options.encoding);
  CameraFrame frame;
  bool have_frame = reader.next(&frame);
  if (!have_frame) failInput("--images: '" + dive.images.path + "' gave no frames");

  // Without navigation: the altitude CSV's rows near the images (a long log must not delay the replay's start),
  // and an altitude at each image, so that every image has one however sparse the rows.
  const AltitudeTable* table = dive.altitude_table ? &*dive.altitude_table : nullptr;
  std::vector<AltitudeRecord> altitude_rows;
  if (table)
    for (const auto& a : table->rows)
      if (a.stamp_s >= frame.stamp_s - kAltitudeCsvMargin_s) altitude_rows.push_back(a);
  const auto frameAltitude = [&](double stamp_s) {
    AltitudeRecord a = table ? altitudeRecord(stamp_s, table->at(stamp_s))
                             : altitudeRecord(stamp_s, *dive.options.altitude->constant_m);
    if (table) {
      a.min_range_m = table->rows.front().min_range_m;
      a.max_range_m = table->rows.front().max_range_m;
    } else {
      std::vector<AltitudeRecord> one = {a};
      coverRangeSpan(&one);
      a = one.front();
    }
    return a;
  };
  const auto frameName = [&](const CameraFrame& f) {
    return dive.images.kind == ImageSource::Kind::kFolder ? "image '" + baseName(dive.images.files[f.index]) + "'"
                                                          : "video frame " + std::to_string(f.index);
  };

  // Latched messages first, stamped at the start of the dive so that they precede everything on playback.
  double start_s = frame.stamp_s;
  if (!rows.empty()) start_s = std::min(start_s, rows.front().pose.stamp_s);
  if (!altitude_rows.empty()) start_s = std::min(start_s, altitude_rows.front().stamp_s);
  if (dive.navigation.datum) sink->writeDatum(*dive.navigation.datum, start_s);
  sink->writeStaticTransforms(dive.static_transforms, start_s);
  summary.first_stamp_s = summary.last_stamp_s = start_s;

  // Frames and navigation (or altitude rows) merged in time order (navigation first on ties), so that the bag plays
  // back in order.
  const double nav_first_s = rows.empty() ? 0.0 : rows.front().pose.stamp_s;
  const double nav_last_s = rows.empty() ? 0.0 : rows.back().pose.stamp_s;
  double last_frame_s = frame.stamp_s;
  double last_altitude_s = -std::numeric_limits<double>::infinity();
  size_t r = 0, a = 0;
  while (have_frame || r < rows.size() || a < altitude_rows.size()) {
    if (r < rows.size() && (!have_frame || rows[r].pose.stamp_s <= frame.stamp_s)) {
      const NavigationRow& row = rows[r++];
      sink->writeNavOdometry(row.pose);
      if (row.depth) {
        sink->writeDepth(*row.depth);
        ++summary.depth_records;
      }
      if (row.altitude) {
        sink->writeAltitude(*row.altitude);
        ++summary.altitude_records;
      }
      ++summary.nav_rows;
      summary.last_stamp_s = std::max(summary.last_stamp_s, row.pose.stamp_s);
    } else if (a < altitude_rows.size() && (!have_frame || altitude_rows[a].stamp_s <= frame.stamp_s)) {
      const AltitudeRecord& row = altitude_rows[a++];
      if (!have_frame && row.stamp_s > last_frame_s + kAltitudeCsvMargin_s) {
        a = altitude_rows.size();  // the rest of the log is beyond the images
        continue;
      }
      sink->writeAltitude(row);
      ++summary.altitude_records;
      last_altitude_s = row.stamp_s;
      summary.last_stamp_s = std::max(summary.last_stamp_s, row.stamp_s);
    } else {
      if (!summary.navigation) {
        if (table) requireAltitudeCovers(*table, frame.stamp_s, frameName(frame));
        if (frame.stamp_s != last_altitude_s) {  // a row at the image's stamp already gives its altitude
          sink->writeAltitude(frameAltitude(frame.stamp_s));
          ++summary.altitude_records;
          last_altitude_s = frame.stamp_s;
        }
      }
      sink->writeCameraFrame(frame, dive.camera);
      ++summary.frames;
      if (summary.navigation && frame.stamp_s < nav_first_s) ++summary.frames_before_nav;
      if (summary.navigation && frame.stamp_s > nav_last_s) ++summary.frames_after_nav;
      summary.last_stamp_s = std::max(summary.last_stamp_s, frame.stamp_s);
      last_frame_s = frame.stamp_s;
      have_frame = reader.next(&frame);
    }
  }
  return summary;
}

}  // namespace dive
}  // namespace exocet_mosaic
