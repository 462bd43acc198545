#include "exocet_mosaic/video/video_run.h"

#include <fcntl.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <iomanip>
#include <regex>
#include <sstream>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "exocet_common/atomic_file.h"
#include "exocet_common/json_file.h"
#include "exocet_common/utm_grid.h"
#include "exocet_mosaic/video/overview_picture.h"
#include "exocet_mosaic/video/video_camera.h"
#include "exocet_mosaic/video/video_mosaicker.h"

namespace exocet_mosaic {
namespace video {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
using Json = nlohmann::ordered_json;

/// Files this tool writes in its output folder (what --overwrite replaces).
bool isOurFile(const std::string& name) {
  static const std::regex ours(
      R"((tile_\d{4,}\.(tif|tfw|cog\.tif|kmz|json))|overview\.png|track\.csv|summary\.json|camera\.yaml|SCALE_APPROXIMATE\.txt|\.(tile_|overview|track|summary|camera|SCALE).*partial.*)");
  return std::regex_match(name, ours);
}

void checkOptions(const VideoRunOptions& o) {
  if (o.video_path.empty()) throw BadInput("VIDEO: no video given");
  if (o.output_dir.empty()) throw BadInput("--output: no folder given");
  if (!(o.altitude_m >= kMinAltitude_m && o.altitude_m <= kMaxAltitude_m)) {
    std::ostringstream s;
    s << "--altitude " << o.altitude_m << " is outside [" << kMinAltitude_m << ", " << kMaxAltitude_m
      << "] m (the camera's height above the seabed)";
    throw BadInput(s.str());
  }
  if (o.origin_latitude_deg.has_value() != o.origin_longitude_deg.has_value())
    throw BadInput("--origin-lat and --origin-lon go together: give both or neither");
  if (o.origin_latitude_deg && !(std::abs(*o.origin_latitude_deg) <= 84.0))
    throw BadInput("--origin-lat " + std::to_string(*o.origin_latitude_deg) + " is outside [-84, 84] deg (UTM)");
  if (o.origin_longitude_deg && !(*o.origin_longitude_deg >= -180.0 && *o.origin_longitude_deg < 360.0))
    throw BadInput("--origin-lon " + std::to_string(*o.origin_longitude_deg) + " is outside [-180, 360) deg");
  if (o.heading_deg && !(*o.heading_deg >= -360.0 && *o.heading_deg <= 360.0))
    throw BadInput("--heading " + std::to_string(*o.heading_deg) + " is outside [-360, 360] deg");
  if (!(o.hfov_deg > 1.0 && o.hfov_deg < 179.0))
    throw BadInput("--hfov " + std::to_string(o.hfov_deg) + " is outside (1, 179) deg");
  if (o.fps && !(*o.fps > 0.0 && *o.fps <= 1000.0))
    throw BadInput("--fps " + std::to_string(*o.fps) + " is outside (0, 1000] frames/s");
  if (o.start_time_s && !(std::isfinite(*o.start_time_s) && *o.start_time_s > 0.0))
    throw BadInput("--start-time must be a positive time (s)");
  if (o.selfcal_frames < 10 || o.selfcal_frames > 100000) throw BadInput("--selfcal-frames outside [10, 100000]");
  if (o.max_frames < 0) throw BadInput("--max-frames must be >= 0");
}

/// The video opened, with its first frames decoded to check it (kept to be used, not read twice).
struct OpenedVideo {
  cv::VideoCapture capture;
  std::vector<cv::Mat> first_frames;
  cv::Size size;
  double container_fps = 0.0;
  int container_frames = 0;
};

/// Keeps the decoders' own messages (FFmpeg's, GStreamer's) off stderr while it lives: a file that is no video is
/// reported in one line of ours.
class QuietStderr {
 public:
  QuietStderr() : saved_(::dup(STDERR_FILENO)) {
    const int null = ::open("/dev/null", O_WRONLY);
    if (saved_ >= 0 && null >= 0) ::dup2(null, STDERR_FILENO);
    if (null >= 0) ::close(null);
  }
  ~QuietStderr() {
    if (saved_ >= 0) {
      ::dup2(saved_, STDERR_FILENO);
      ::close(saved_);
    }
  }
  QuietStderr(const QuietStderr&) = delete;
  QuietStderr& operator=(const QuietStderr&) = delete;

 private:
  int saved_;
};

OpenedVideo openVideo(const VideoRunOptions& o) {
  if (!fs::exists(o.video_path)) throw BadInput("VIDEO '" + o.video_path + "' does not exist");
  if (!fs::is_regular_file(o.video_path)) throw BadInput("VIDEO '" + o.video_path + "' is not a file");
  OpenedVideo v;
  bool opened = false;
  {
    const QuietStderr quiet;
    opened = v.capture.open(o.video_path, cv::CAP_FFMPEG) && v.capture.isOpened();
    if (!opened) opened = v.capture.open(o.video_path) && v.capture.isOpened();
  }
  if (!opened)
    throw BadInput("VIDEO '" + o.video_path + "' cannot be read as a video (no decoder opens it)");
  v.container_fps = v.capture.get(cv::CAP_PROP_FPS);
  v.container_frames = static_cast<int>(v.capture.get(cv::CAP_PROP_FRAME_COUNT));
  cv::Mat frame;
  while (static_cast<int>(v.first_frames.size()) < kMinFrames && v.capture.read(frame) && !frame.empty())
    v.first_frames.push_back(frame.clone());
  if (v.first_frames.empty()) throw BadInput("VIDEO '" + o.video_path + "' is empty: no frame can be decoded");
  if (static_cast<int>(v.first_frames.size()) < kMinFrames)
    throw BadInput("VIDEO '" + o.video_path + "' is too short: " + std::to_string(v.first_frames.size()) +
                   " frame, at least " + std::to_string(kMinFrames) + " needed");
  v.size = v.first_frames.front().size();
  if (v.first_frames.front().depth() != CV_8U)
    throw BadInput("VIDEO '" + o.video_path + "': frames are not 8-bit images");
  return v;
}

void prepareOutputDir(const VideoRunOptions& o) {
  std::error_code ec;
  if (fs::exists(o.output_dir, ec)) {
    if (!fs::is_directory(o.output_dir, ec)) throw BadInput("--output '" + o.output_dir + "' exists and is not a folder");
    std::vector<fs::path> ours, others;
    for (const fs::directory_entry& e : fs::directory_iterator(o.output_dir, ec))
      (isOurFile(e.path().filename().string()) && e.is_regular_file() ? ours : others).push_back(e.path());
    if (!ours.empty() || !others.empty()) {
      if (!o.overwrite)
        throw BadInput("--output '" + o.output_dir + "' exists and is not empty (give --overwrite to replace its " +
                       "tiles and results)");
      if (!others.empty())
        throw BadInput("--output '" + o.output_dir + "' holds files this tool did not write (e.g. '" +
                       others.front().filename().string() + "'): --overwrite replaces only its own; choose a folder");
    }
  }
  const std::string writable = exocet_common::checkWritableDestination(o.output_dir + "/x");
  if (fs::exists(o.output_dir) && !writable.empty()) throw BadInput("--output: " + writable);
}

void clearOurFiles(const std::string& dir) {
  std::error_code ec;
  for (const fs::directory_entry& e : fs::directory_iterator(dir, ec))
    if (e.is_regular_file() && isOurFile(e.path().filename().string())) fs::remove(e.path(), ec);
}

std::string formatDuration(double s) {
  if (!std::isfinite(s) || s < 0) return "--:--";
  const int t = static_cast<int>(s + 0.5);
  std::ostringstream out;
  if (t >= 3600) out << t / 3600 << ":" << std::setw(2) << std::setfill('0') << (t / 60) % 60;
  else out << t / 60;
  out << ":" << std::setw(2) << std::setfill('0') << t % 60;
  return out.str();
}

/// One line redrawn in place: bar, frames, frames/s, time left.
class ProgressBar {
 public:
  ProgressBar(std::ostream& err, bool enabled, int total) : err_(err), enabled_(enabled), total_(total) {}
  void update(int done, double elapsed_s, bool force = false) {
    if (!enabled_) return;
    const auto now = Clock::now();
    if (!force && now - last_ < std::chrono::milliseconds(200)) return;
    last_ = now;
    const double rate = elapsed_s > 0 ? done / elapsed_s : 0.0;
    std::ostringstream line;
    line << "\r";
    if (total_ > 0) {
      const int width = 30, filled = std::min(width, width * done / std::max(1, total_));
      line << "[" << std::string(filled, '#') << std::string(width - filled, ' ') << "] " << done << "/" << total_;
    } else {
      line << done;
    }
    line << " frames  " << std::fixed << std::setprecision(1) << rate << " frames/s";
    if (total_ > 0 && rate > 0) line << "  " << formatDuration((total_ - done) / rate) << " left";
    line << "   ";
    err_ << line.str() << std::flush;
  }
  void end() {
    if (enabled_) err_ << "\n";
  }

 private:
  std::ostream& err_;
  bool enabled_;
  int total_;
  Clock::time_point last_{};
};

std::string trackCsv(const std::vector<FramePlacement>& track, double t0_s) {
  std::ostringstream out;
  out << "frame,t_s,easting_m,northing_m,sigma_m,placed\n" << std::fixed;
  for (const FramePlacement& f : track) {
    out << f.frame << ',' << std::setprecision(4) << f.stamp_s - t0_s << ',';
    if (f.camera_en_m)
      out << std::setprecision(4) << f.camera_en_m->x() << ',' << f.camera_en_m->y() << ',' << f.sigma_m;
    else
      out << ",,";
    out << ',' << (f.placed ? 1 : 0) << '\n';
  }
  return out.str();
}

void writeCameraYaml(const std::string& path, const exocet_common::CameraModel& camera) {
  const std::string temporary = exocet_common::temporaryPathFor(path) + ".yaml";
  exocet_common::saveCameraModelYaml(temporary, camera, "mosaic_video");
  exocet_common::commitTemporaryFile(temporary, path);
}

}  // namespace

int runVideoMosaic(const VideoRunOptions& o, const std::atomic<bool>& stop, std::ostream& out, std::ostream& err) {
  const auto started = Clock::now();
  const auto elapsed_s = [&]() { return std::chrono::duration<double>(Clock::now() - started).count(); };
  const std::string tool = "mosaic_video: ";
  VideoMosaickerConfig config;
  OpenedVideo video;
  CameraChoice camera;
  std::optional<dive::NavigationTable> navigation;
  double fps = 0.0;
  // ---- Every input checked before anything is written. ----
  try {
    checkOptions(o);
    video = openVideo(o);
    fps = o.fps.value_or(video.container_fps);
    if (!(fps > 0.0 && fps <= 1000.0))
      throw BadInput("VIDEO '" + o.video_path + "': the container gives no usable frame rate (" +
                     std::to_string(video.container_fps) + "): give --fps");
    if (!o.camera_path.empty()) {
      if (!fs::is_regular_file(o.camera_path)) throw BadInput("--camera '" + o.camera_path + "' does not exist");
      try {
        camera.camera = exocet_common::loadCameraModelYaml(o.camera_path);
      } catch (const std::exception& e) {
        throw BadInput(std::string("--camera: ") + e.what());
      }
      if (camera.camera.width != video.size.width || camera.camera.height != video.size.height)
        throw BadInput("--camera '" + o.camera_path + "' is for " + std::to_string(camera.camera.width) + "x" +
                       std::to_string(camera.camera.height) + " images, the video's are " +
                       std::to_string(video.size.width) + "x" + std::to_string(video.size.height));
      camera.source = "file";
    }
    std::optional<dive::GeoOrigin> origin;
    if (o.origin_latitude_deg) origin = dive::GeoOrigin{*o.origin_latitude_deg, *o.origin_longitude_deg};
    if (!o.nav_path.empty()) {
      if (!fs::is_regular_file(o.nav_path)) throw BadInput("--nav '" + o.nav_path + "' does not exist");
      try {
        navigation = dive::readNavigationCsv(o.nav_path, origin);
      } catch (const dive::DiveImportError& e) {
        throw BadInput(std::string("--nav: ") + e.what());
      }
    }
    try {
      config.registration = loadRegistrationPreset(presetPath("registration", o.registration_preset));
      config.registration.registration.model = registration::motionModelFromString(o.registration_model);
      config.tiles = loadTilesPreset(presetPath("tiles", o.tiles_preset));
    } catch (const std::invalid_argument& e) {
      throw BadInput(e.what());
    }
    prepareOutputDir(o);
  } catch (const BadInput& e) {
    err << tool << e.what() << "\n";
    return kExitBadInput;
  }

  // ---- The run. ----
  Json summary;
  std::string reason;
  int status = kExitDone;
  try {
    fs::create_directories(o.output_dir);
    clearOurFiles(o.output_dir);
    if (camera.source.empty()) {
      err << tool << "no --camera: self-calibrating from the first " << o.selfcal_frames << " frames...\n";
      camera = selfCalibrateVideo(o.video_path, o.selfcal_frames, o.hfov_deg, stop);
      if (!stop) err << tool << camera.summary << "\n";
    } else {
      camera.summary = "intrinsics from " + o.camera_path;
    }
    config.camera = camera.camera;
    config.camera_height_m = o.altitude_m;
    config.scale_approximate = camera.scale_approximate;
    config.dive_name = fs::path(o.video_path).stem().string();
    config.tiles.files.output_dir = o.output_dir;

    // Frame of the tiles and the first point.
    std::string frame = "utm";
    int epsg = 0;
    std::optional<exocet_common::UtmGrid> grid;
    if (navigation && navigation->world_frame == "utm" && navigation->datum) {
      grid = navigation->datum->grid();
    } else if (o.origin_latitude_deg && !navigation) {
      grid = exocet_common::UtmGrid::forLatLon(*o.origin_latitude_deg, *o.origin_longitude_deg);
      config.start_en_m = grid->toGrid(*o.origin_latitude_deg, *o.origin_longitude_deg);
    }
    if (grid) {
      config.utm_zone = grid->zone();
      config.northern_hemisphere = grid->northern();
      epsg = grid->epsg();
    } else {
      frame = navigation ? navigation->world_frame : "local";
      config.local_frame = frame;
    }
    if (o.heading_deg) {
      double grid_heading_rad = *o.heading_deg * M_PI / 180.0;
      // A compass heading is true; the grid's north differs by the meridian convergence (as dive_import turns it).
      if (grid && config.start_en_m)
        grid_heading_rad -= grid->convergence_rad(config.start_en_m->x(), config.start_en_m->y());
      config.start_enu_yaw_rad = M_PI / 2.0 - grid_heading_rad;
    }

    VideoMosaicker mosaicker(config);
    double t0_s = o.start_time_s.value_or(1.0);
    if (navigation) {
      mosaicker.setNavigation(navigation->rows, navigation->orientation_columns != "none");
      if (!o.start_time_s) t0_s = navigation->rows.front().pose.stamp_s;
    }
    writeCameraYaml(o.output_dir + "/camera.yaml", config.camera);

    // Self-calibration read the video on its own; the frames kept from the check are the first ones.
    if (camera.source != "file") {
      video.capture.release();
      video.capture.open(o.video_path);
      video.first_frames.clear();
    }
    const int total = o.max_frames > 0 ? (video.container_frames > 0 ? std::min(o.max_frames, video.container_frames)
                                                                      : o.max_frames)
                                       : video.container_frames;
    ProgressBar bar(err, o.progress, total);
    const auto run_started = Clock::now();
    std::size_t next_kept = 0;
    cv::Mat image;
    int index = 0;
    while (!stop) {
      if (o.max_frames > 0 && index >= o.max_frames) break;
      if (next_kept < video.first_frames.size()) {
        image = video.first_frames[next_kept++];
      } else if (!video.capture.read(image) || image.empty()) {
        break;
      }
      if (image.size() != video.size) {
        err << tool << "frame " << index << " is " << image.cols << "x" << image.rows << ", not "
            << video.size.width << "x" << video.size.height << ": the video ends there\n";
        break;
      }
      if (image.type() != CV_8UC3 && image.type() != CV_8UC1) cv::cvtColor(image, image, cv::COLOR_BGRA2BGR);
      mosaicker.addFrame(image, t0_s + index / fps);
      ++index;
      bar.update(index, std::chrono::duration<double>(Clock::now() - run_started).count());
    }
    const bool interrupted = stop.load();
    mosaicker.finish(interrupted ? "interrupted" : "flush");
    const double run_s = std::chrono::duration<double>(Clock::now() - run_started).count();
    bar.update(index, run_s, true);
    bar.end();

    // ---- Outputs. ----
    exocet_common::writeFileAtomically(o.output_dir + "/track.csv", trackCsv(mosaicker.track(), t0_s));
    const cv::Mat overview = drawOverview(mosaicker.thumbnails(), mosaicker.track(), 1600);
    std::string overview_path;
    if (!overview.empty()) {
      std::vector<uchar> png;
      cv::imencode(".png", overview, png);
      overview_path = o.output_dir + "/overview.png";
      exocet_common::writeFileAtomically(overview_path, std::string(png.begin(), png.end()));
    }
    if (camera.scale_approximate)
      exocet_common::writeFileAtomically(
          o.output_dir + "/SCALE_APPROXIMATE.txt",
          "The tiles' scale is approximate: no camera calibration was given and self-calibration refused\n(" +
              camera.summary + ").\nGive --camera K.yaml for a measured scale.\n");

    const int read = mosaicker.framesRead();
    const int tiles = static_cast<int>(mosaicker.tilesWritten().size());
    if (interrupted) {
      reason = "interrupted";
      status = kExitInterrupted;
    } else if (tiles == 0) {
      const compose::ComposerStats stats = mosaicker.composerStats();
      reason = mosaicker.writeErrors().empty()
                   ? std::to_string(read) + " frames read, " + std::to_string(mosaicker.framesPlaced()) +
                         " placed, no mosaic closed" + (stats.last_problem.empty() ? "" : ": " + stats.last_problem)
                   : "tiles could not be written: " + mosaicker.writeErrors().back();
      status = kExitFailed;
    }
    summary["video"] = o.video_path;
    summary["frames_read"] = read;
    summary["frames_registered"] = mosaicker.framesRegistered();
    summary["frames_placed"] = mosaicker.framesPlaced();
    summary["frames_placed_fraction"] = read > 0 ? double(mosaicker.framesPlaced()) / read : 0.0;
    summary["tiles_written"] = tiles;
    summary["tiles_not_written"] = static_cast<int>(mosaicker.writeErrors().size());
    summary["frame"] = frame;
    summary["epsg"] = epsg;
    summary["camera"] = camera.source;
    summary["camera_fx_px"] = config.camera.fx;
    summary["camera_fy_px"] = config.camera.fy;
    summary["camera_cx_px"] = config.camera.cx;
    summary["camera_cy_px"] = config.camera.cy;
    summary["camera_detail"] = camera.summary;
    if (!camera.details.empty()) summary["selfcal"] = camera.details;
    summary["scale_approximate"] = camera.scale_approximate;
    summary["altitude_m"] = o.altitude_m;
    summary["navigation"] = navigation ? Json(o.nav_path) : Json(nullptr);
    summary["seconds"] = elapsed_s();
    summary["mosaic_seconds"] = run_s;
    summary["fps"] = run_s > 0 ? read / run_s : 0.0;
    summary["video_fps"] = fps;
    summary["overview"] = overview_path.empty() ? Json(nullptr) : Json(overview_path);
    Json tile_list = Json::array();
    for (const tiles::WrittenTile& t : mosaicker.tilesWritten()) tile_list.push_back(t.geotiff_path);
    summary["tiles"] = tile_list;
    summary["reason"] = reason.empty() ? Json(nullptr) : Json(reason);
    exocet_common::writeJsonFileAtomically(o.output_dir + "/summary.json", summary);

    std::ostringstream line;
    line << std::fixed << std::setprecision(1);
    if (status == kExitFailed)
      line << tool << "no tile written: " << reason;
    else
      line << (interrupted ? "interrupted: " : "") << tiles << " tile" << (tiles == 1 ? "" : "s") << " in "
           << o.output_dir << " (" << (frame == "utm" ? "EPSG " + std::to_string(epsg) : "local frame '" + frame + "'")
           << "), " << mosaicker.framesPlaced() << "/" << read << " frames placed, " << summary["fps"].get<double>()
           << " frames/s" << (camera.scale_approximate ? ", scale approximate" : "");
    (status == kExitFailed ? err : out) << line.str() << "\n";
    return status;
  } catch (const std::exception& e) {
    err << tool << e.what() << "\n";
    return kExitFailed;
  }
}

}  // namespace video
}  // namespace exocet_mosaic
