/**
 * @file video_run.h
 * @brief What `mosaic_video` does, as a function its tests and benchmark call too: checks every input before
 * anything is written, chooses the camera (a file, self-calibration from the clip, or a pinhole from a field of
 * view), reads the video's frames at the speed of the CPU through VideoMosaicker, and writes the tiles, track.csv,
 * overview.png and summary.json in the output folder. No ROS in it.
 */
#pragma once

#include <atomic>
#include <optional>
#include <ostream>
#include <stdexcept>
#include <string>

namespace exocet_mosaic {
namespace video {

/// Exit statuses of a run.
constexpr int kExitDone = 0;
constexpr int kExitFailed = 1;       ///< I/O failure, or no tile could be made (the summary says why)
constexpr int kExitBadInput = 2;     ///< a bad argument or input (one line naming it; nothing written)
constexpr int kExitInterrupted = 130;

/// The camera heights accepted (m): an ROV or AUV mosaics from about 0.3 m to a few tens of metres over the seabed.
constexpr double kMinAltitude_m = 0.1;
constexpr double kMaxAltitude_m = 100.0;
/// The field of view of the pinhole used when there is no calibration and self-calibration refuses: a typical ROV
/// survey camera (PAL, 1/3" sensor, ~4 mm lens behind a flat port).
constexpr double kDefaultHfov_deg = 60.0;
/// Fewest frames a video must have (one registered pair).
constexpr int kMinFrames = 2;

struct VideoRunOptions {
  std::string video_path;
  std::string output_dir;
  double altitude_m = 0.0;  ///< camera height above the seabed (m), [kMinAltitude_m, kMaxAltitude_m]
  std::string camera_path;  ///< intrinsics YAML; empty: self-calibrate, else a pinhole of hfov_deg
  std::optional<double> origin_latitude_deg, origin_longitude_deg;
  std::optional<double> heading_deg;  ///< true heading of the vehicle at the first frame (clockwise from north)
  std::string nav_path;               ///< navigation CSV (dive_import's conventions)
  std::optional<double> start_time_s;  ///< time of frame 0 on the navigation's clock (default: its first row)
  std::optional<double> fps;           ///< frame rate (default: the container's)
  double hfov_deg = kDefaultHfov_deg;
  bool overwrite = false;  ///< a non-empty output folder: replace this tool's files in it
  bool progress = false;   ///< progress bar on `err`
  int max_frames = 0;      ///< 0: every frame; else stop after this many (benchmarks)
  int selfcal_frames = 300;  ///< frames the self-calibration reads, [10, 100000]
  std::string registration_preset = "pal_survey";
  std::string registration_model = "homography";
  std::string tiles_preset = "pal_survey";
  std::string dive_name;
};

/// A bad argument or input: the message names the argument (exit status 2).
class BadInput : public std::invalid_argument {
 public:
  using std::invalid_argument::invalid_argument;
};

/**
 * @brief Runs the whole tool. Messages go to `out` (results) and `err` (warnings, errors, progress).
 * @param stop set (e.g. by a SIGINT handler) to stop reading: the open mosaic is written as a last tile, the summary
 *        says reason "interrupted", and the status is kExitInterrupted.
 * @return the exit status (kExitDone, kExitFailed, kExitBadInput, kExitInterrupted).
 */
int runVideoMosaic(const VideoRunOptions& options, const std::atomic<bool>& stop, std::ostream& out,
                   std::ostream& err);

}  // namespace video
}  // namespace exocet_mosaic
