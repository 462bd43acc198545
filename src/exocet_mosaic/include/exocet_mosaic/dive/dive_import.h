/**
 * @file dive_import.h
 * @brief Importing a real dive (images + navigation CSV + camera intrinsics) into the records of dive_records.h,
 * so that it can be written into the same bag layout as the simulator's (see tools/dive_import.cpp).
 *
 * No ROS here: the importer reads and validates the inputs (prepareDiveImport), then streams the records in time
 * order into a DiveRecordSink (writeDiveImport); the tool's sink is the bag writer. Every problem with the inputs
 * is a DiveImportError naming the argument, file, line and column concerned and, where there is a choice, the
 * allowed values.
 *
 * Conventions of the navigation CSV (also printed by diveImportUsage()):
 *  - one header row, comma-separated; blank lines and lines starting with '#' are skipped; column names are
 *    matched case-insensitively; other columns (e.g. source, target) are ignored;
 *  - time: the first of the columns t_unix_s, t, time, stamp, ts: seconds since the Unix epoch, non-decreasing;
 *  - position: either local x, y, z (metres; x east, y north, z up) or geodetic lat, lon (degrees WGS 84) with z
 *    (metres, up) or depth (metres, down); with lat, lon the geodetic columns are used and x, y ignored;
 *  - orientation of base_link (x forward, y left, z up) in the world frame: qx, qy, qz, qw (body to world), or
 *    yaw_deg (counter-clockwise from the world's x axis, with optional roll_deg, pitch_deg about the body's x and
 *    y: R = Rz(yaw) Ry(pitch) Rx(roll), as tf), or heading_deg (clockwise from true north, with optional roll_deg,
 *    pitch_deg in the NED/forward-right-down convention: positive pitch is nose up); without any, the identity
 *    with its covariance marked unknown (-1);
 *  - depth (metres, positive down) and altitude (metres above the seabed) give /nav/depth and /nav/altitude; an
 *    empty depth or altitude cell means no measurement on that row; without a depth column, depth = -z.
 * World frame: "utm" when lat, lon columns or an origin are given (positions become UTM easting, northing, up; x, y
 * are offsets from the origin; a heading is turned from true to grid north by the meridian convergence), otherwise
 * "map" (local coordinates as given).
 *
 * Without a navigation CSV (no --nav) the bag holds the images, camera_info, /tf_static and /nav/altitude only (no
 * /nav/odometry): the altitude is a constant (--altitude M, one record at each image) or read from a small CSV
 * (--altitude FILE.csv[:COLUMN], one record at each row within kAltitudeCsvMargin_s of the images and one at each
 * image, interpolated). The start point (--origin-lat/--origin-lon, --heading) is not in the bag: it goes to the
 * fusion's images-only mode through replayArguments(), which the tool prints and writes beside the bag.
 */
#pragma once

#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include <opencv2/videoio.hpp>

#include "exocet_common/camera_model.h"
#include "exocet_mosaic/dive/dive_records.h"

namespace exocet_mosaic {
namespace dive {

/// A problem met while importing a dive. kInput: bad argument or input file (the tool exits 2); kIo: reading or
/// writing failed on a file that should have worked (the tool exits 1).
class DiveImportError : public std::runtime_error {
 public:
  enum class Kind { kInput, kIo };
  DiveImportError(Kind kind, const std::string& message) : std::runtime_error(message), kind_(kind) {}
  Kind kind() const { return kind_; }
  /// Process exit code of the tool for this error: 2 for bad input, 1 for I/O failures.
  int exitCode() const { return kind_ == Kind::kInput ? 2 : 1; }

 private:
  Kind kind_;
};

/// Pixel format of the imported images.
enum class ImageEncoding { kBgr8, kMono8 };

/// Parses "bgr8" or "mono8"; throws DiveImportError (kInput) naming the allowed values.
ImageEncoding parseImageEncoding(const std::string& name);
/// sensor_msgs encoding name: "bgr8" or "mono8".
std::string encodingName(ImageEncoding encoding);

/// Geodetic origin of a geo-referenced world frame.
struct GeoOrigin {
  double latitude_deg = 0.0;
  double longitude_deg = 0.0;
};

/// Largest altitude (m) accepted by --altitude, as a constant or in its CSV: altitudes are in (0, kMaxAltitude_m].
constexpr double kMaxAltitude_m = 1000.0;
/// How far (s) the images may lie outside the time span of an --altitude CSV: within it, an image takes the nearest
/// row's altitude; beyond it, the import fails.
constexpr double kAltitudeCsvMargin_s = 1.0;

/// The altitude of a dive imported without navigation (--altitude): a constant or a CSV column.
struct AltitudeOption {
  std::optional<double> constant_m;  ///< --altitude M: altitude of base_link above the seabed (m), in (0, 1000]
  std::string csv_path;              ///< --altitude FILE.csv[:COLUMN]: CSV with a time and an altitude column
  std::string csv_column;            ///< the column given after ':'; empty: "altitude" (or "altitude_m")
};

/// Everything the tool's command line says (see diveImportUsage()).
struct DiveImportOptions {
  std::string images_path;       ///< folder of images or video file
  std::string nav_path;          ///< navigation CSV; empty: a dive without navigation (then `altitude` is set)
  std::string camera_path;       ///< camera intrinsics YAML
  std::string output_path;       ///< bag to write
  std::string image_times_path;  ///< index CSV of frame times; empty: use start_time_s and fps
  std::optional<double> start_time_s;  ///< time of the first frame (Unix seconds)
  std::optional<double> fps;           ///< frame rate (Hz); for a video, defaults to the container's
  /// With --nav: origin of x, y, makes the world frame "utm". Without: the start point of the dive (the camera at
  /// the first frame), given to the fusion; the bag then carries its UTM zone on /nav/datum.
  std::optional<GeoOrigin> origin;
  std::optional<AltitudeOption> altitude;  ///< --altitude: only without --nav, and then required
  /// --heading: without --nav, heading of base_link's forward axis at the first frame (degrees clockwise from true
  /// north, in [-360, 360]).
  std::optional<double> heading_deg;
  ImageEncoding encoding = ImageEncoding::kBgr8;
  std::string image_storage = "raw";  ///< raw, jpeg or png (checked here, parsed by the bag writer)
  /// base_link -> camera_optical: pose of the camera in base_link. Identity unless --camera-pose is given.
  Eigen::Isometry3d base_from_camera = Eigen::Isometry3d::Identity();
  bool help = false;  ///< --help: print diveImportUsage() and do nothing else
};

/// The tool's help: usage, options, and the CSV and frame conventions.
std::string diveImportUsage();

/**
 * @brief Parses the tool's arguments (without the program name) with CLI11. Accepts "--name value" and
 * "--name=value". Throws DiveImportError (kInput) naming the argument and its allowed values for an unknown option, a
 * missing or malformed value, a missing required option or conflicting options (--altitude or --heading with
 * --nav). A missing --camera is an error that says how to get the intrinsics (self_calibrate, mosaic_video).
 */
DiveImportOptions parseDiveImportArguments(const std::vector<std::string>& args);

/// Parses "x,y,z,roll,pitch,yaw" (metres, degrees; R = Rz(yaw) Ry(pitch) Rx(roll)) into the pose of the camera's
/// optical frame in base_link. Throws DiveImportError (kInput) naming --camera-pose.
Eigen::Isometry3d parseCameraPose(const std::string& text);

/**
 * @brief Parses --altitude's value: a number of metres in (0, kMaxAltitude_m], or "FILE.csv" or "FILE.csv:COLUMN"
 * (the file is not read here). Throws DiveImportError (kInput) naming --altitude, its range and its two forms.
 */
AltitudeOption parseAltitudeOption(const std::string& text);

/// The altitude CSV of --altitude FILE.csv[:COLUMN].
struct AltitudeTable {
  std::string path;
  std::string time_column;      ///< as in the header
  std::string altitude_column;  ///< as in the header
  /// One record per row with a value (empty cells skipped), times increasing; frame and range span as the
  /// navigation's altitude records (min_range_m, max_range_m cover every value).
  std::vector<AltitudeRecord> rows;

  /// Altitude at `stamp_s`: linear between the rows around it, the first or last row's value outside their span.
  double at(double stamp_s) const;
};

/**
 * @brief Reads an altitude CSV: a header with a time column (t_unix_s, t, time, stamp, ts: Unix seconds, increasing)
 * and the altitude column `column` (empty: altitude, else altitude_m; metres, in (0, kMaxAltitude_m]); other columns
 * ignored, empty altitude cells skipped. Throws DiveImportError (kInput) naming --altitude, the file, line and column.
 */
AltitudeTable readAltitudeCsv(const std::string& path, const std::string& column);

/// One row of the navigation CSV.
struct NavigationRow {
  int line = 0;  ///< line number in the CSV, from 1 (the header)
  PoseRecord pose;  ///< base_link in the world frame
  std::optional<DepthRecord> depth;
  std::optional<AltitudeRecord> altitude;
};

/// The navigation of a dive, read from CSV.
struct NavigationTable {
  std::string world_frame = "map";  ///< "utm" (geo-referenced, datum valid) or "map" (local)
  std::optional<exocet_common::GeoReference> datum;  ///< set when world_frame is "utm"
  std::vector<NavigationRow> rows;    ///< in file order, times non-decreasing
  std::string time_column;            ///< the column the times came from
  std::string position_columns;       ///< "x,y,z", "x,y,depth", "lat,lon,z" or "lat,lon,depth"
  std::string orientation_columns;    ///< "qx,qy,qz,qw", "yaw_deg", "heading_deg" (+ roll_deg, pitch_deg) or "none"
  std::vector<std::string> ignored_columns;  ///< header names not used
};

/**
 * @brief Reads a navigation CSV (conventions in the file comment). `origin` makes the world frame "utm" and is the
 * origin of x, y; without it, lat, lon columns take the first row as origin. Throws DiveImportError naming the file,
 * line and column: time going backwards, NaN or infinite values, malformed numbers, missing columns, wrong counts
 * of fields, an empty table.
 */
NavigationTable readNavigationCsv(const std::string& path, const std::optional<GeoOrigin>& origin);

/// Where the images come from.
struct ImageSource {
  enum class Kind { kFolder, kVideo };
  Kind kind = Kind::kFolder;
  std::string path;
  std::vector<std::string> files;  ///< folder: image paths sorted by file name
  int frame_count = 0;             ///< folder: exact; video: as the container says (may be approximate or 0)
  double container_fps = 0.0;      ///< video: frame rate from the container (0 if unknown)
};

/// Image file extensions accepted in a folder (lower case, with the dot).
const std::vector<std::string>& imageFileExtensions();

/**
 * @brief Lists the images of a folder (sorted by file name; extensions of imageFileExtensions(), any case; hidden
 * files skipped) or probes a video file. Throws DiveImportError naming --images: missing path, empty folder,
 * unreadable video.
 */
ImageSource listImages(const std::string& path);

/// Time of each frame.
struct FrameTimes {
  /// Stamp (Unix seconds) of each frame known before decoding: every image of a folder; for a video timed by an
  /// index, by frame number with NaN where the index has no row; empty for a video timed by rate.
  std::vector<double> stamps_s;
  bool from_rate = false;  ///< frame k at start_time_s + k / fps (however many frames a video turns out to have)
  double start_time_s = 0.0;
  double fps = 0.0;
  std::string source;  ///< for messages: the index file or "--start-time/--fps"
  int unused_index_rows = 0;  ///< rows of the index naming no image of the folder

  /// Stamp of frame `index`; throws DiveImportError (kInput) if it has none. `name` names the frame in the error.
  double stampOf(int index, const std::string& name) const;
};

/**
 * @brief Reads frame times from an index CSV: a header with a time column (t_unix_s, t, time, stamp, ts) and a
 * file column (file, filename, image: matched to the folder's images by file name) or a frame column (frame,
 * frame_index: the frame number from 0, in the folder's sorted order or the video's). Every image of a folder must
 * have a row; rows naming no image are counted in unused_index_rows. Stamps must increase with the frame number.
 */
FrameTimes frameTimesFromIndex(const ImageSource& images, const std::string& index_path);

/// Frame times start_time_s + k / fps; fps <= 0 means the container's (a video's). Throws naming the option.
FrameTimes frameTimesFromRate(const ImageSource& images, double start_time_s, double fps);

/// Reads the frames one by one (a dive does not fit in memory), converted to the encoding and checked against
/// the camera's size.
class FrameReader {
 public:
  FrameReader(const ImageSource& images, const FrameTimes& times, const exocet_common::CameraModel& camera,
              ImageEncoding encoding);
  /// Next frame, stamped; false at the end. Throws DiveImportError naming the file (or frame number) for an
  /// undecodable image, a frame of another size than the camera's (both sizes given) or a frame with no time.
  bool next(CameraFrame* frame);

 private:
  const ImageSource& images_;
  const FrameTimes& times_;
  const exocet_common::CameraModel& camera_;
  ImageEncoding encoding_;
  int next_index_ = 0;
  cv::VideoCapture video_;
};

/// Everything read and checked before writing, except the pixels.
struct DiveImport {
  DiveImportOptions options;
  exocet_common::CameraModel camera;
  ImageSource images;
  FrameTimes times;
  /// With --nav: the CSV's. Without: no rows; world frame "utm" and the datum of the start point when one is given,
  /// else "map".
  NavigationTable navigation;
  std::optional<AltitudeTable> altitude_table;  ///< --altitude FILE.csv[:COLUMN]
  /// Without --nav: the start heading for the fusion's ~initial_heading_deg, clockwise from grid north (--heading
  /// turned by the meridian convergence at the start point; as given without a start point).
  std::optional<double> initial_grid_heading_deg;
  /// base_link -> camera_optical, and base_link -> altimeter (identity: the altitude is base_link's) when the bag
  /// has /nav/altitude.
  std::vector<StaticTransform> static_transforms;
  std::vector<std::string> warnings;  ///< worth telling the user, not errors

  bool hasNavigation() const { return !options.nav_path.empty(); }
};

/// Reads and validates the camera, image list, frame times, navigation (or altitude CSV) and output folder of
/// `options`. Without --nav, checks that the images' known times lie within the altitude CSV's span (with
/// kAltitudeCsvMargin_s).
DiveImport prepareDiveImport(const DiveImportOptions& options);

/// One argument of replay.launch (and replay_dive): name and value, as in "name:=value".
struct ReplayArgument {
  std::string name;
  std::string value;
};

/**
 * @brief The replay.launch arguments that replay the imported bag as it should be: ground_truth false (a real dive);
 * without navigation fusion_preset images_only, and with a start point origin_lat, origin_lon (the fusion's
 * ~initial_latitude_deg, ~initial_longitude_deg), heading_deg (~initial_heading_deg, grid north; 0 when --heading
 * is not given). Without a start point the replay maps the dive in the local frame "map".
 */
std::vector<ReplayArgument> replayArguments(const DiveImport& dive);

/// The file beside the bag that replay_dive reads for these arguments: `bag_path` + ".replay.json".
std::string replaySidecarPath(const std::string& bag_path);

/// The shell command that replays `bag_path` into `output_dir` with `arguments`:
/// "rosrun exocet_mosaic replay_dive BAG OUTPUT_DIR name:=value ...", words quoted for a POSIX shell when needed.
std::string replayCommand(const std::string& bag_path, const std::string& output_dir,
                          const std::vector<ReplayArgument>& arguments);

/// Where writeDiveImport puts the records; DiveRecordSinkFor adapts any writer with these methods
/// (e.g. exocet_mosaic::DiveBagWriter).
class DiveRecordSink {
 public:
  virtual ~DiveRecordSink() = default;
  virtual void writeDatum(const exocet_common::GeoReference& datum, double stamp_s) = 0;
  virtual void writeStaticTransforms(const std::vector<StaticTransform>& transforms, double stamp_s) = 0;
  virtual void writeCameraFrame(const CameraFrame& frame, const exocet_common::CameraModel& camera) = 0;
  virtual void writeNavOdometry(const PoseRecord& pose) = 0;
  virtual void writeDepth(const DepthRecord& depth) = 0;
  virtual void writeAltitude(const AltitudeRecord& altitude) = 0;
};

/// DiveRecordSink forwarding to a writer that has the same methods (a template so that this header needs no ROS).
template <typename Writer>
class DiveRecordSinkFor final : public DiveRecordSink {
 public:
  explicit DiveRecordSinkFor(Writer* writer) : writer_(writer) {}
  void writeDatum(const exocet_common::GeoReference& datum, double stamp_s) override { writer_->writeDatum(datum, stamp_s); }
  void writeStaticTransforms(const std::vector<StaticTransform>& transforms, double stamp_s) override {
    writer_->writeStaticTransforms(transforms, stamp_s);
  }
  void writeCameraFrame(const CameraFrame& frame, const exocet_common::CameraModel& camera) override {
    writer_->writeCameraFrame(frame, camera);
  }
  void writeNavOdometry(const PoseRecord& pose) override { writer_->writeNavOdometry(pose); }
  void writeDepth(const DepthRecord& depth) override { writer_->writeDepth(depth); }
  void writeAltitude(const AltitudeRecord& altitude) override { writer_->writeAltitude(altitude); }

 private:
  Writer* writer_;
};

/// What writeDiveImport wrote.
struct DiveImportSummary {
  int frames = 0;
  int nav_rows = 0;
  int depth_records = 0;
  int altitude_records = 0;
  double first_stamp_s = 0.0;
  double last_stamp_s = 0.0;
  std::string world_frame;
  bool navigation = true;  ///< false: imported without --nav
  int frames_before_nav = 0;  ///< frames stamped before the first navigation row
  int frames_after_nav = 0;   ///< frames stamped after the last navigation row

  double duration_s() const { return last_stamp_s - first_stamp_s; }
  /// One line for the user: frames, navigation rows, duration, world frame and output path.
  std::string line(const std::string& output_path) const;
  /// What the user should know but is not an error (frames outside the navigation's time span).
  std::vector<std::string> warnings() const;
};

/**
 * @brief Writes the datum (if geo-referenced) and static transforms, then the frames and navigation rows (without
 * navigation: the altitude records) merged in time order. Throws DiveImportError for bad frames and, without
 * navigation, for a frame outside the altitude CSV's span by more than kAltitudeCsvMargin_s; the sink's own
 * exceptions pass through.
 */
DiveImportSummary writeDiveImport(const DiveImport& dive, DiveRecordSink* sink);

}  // namespace dive
}  // namespace exocet_mosaic
