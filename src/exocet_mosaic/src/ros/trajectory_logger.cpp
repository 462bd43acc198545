#include "exocet_mosaic/ros/trajectory_logger.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <charconv>
#include <cinttypes>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <sstream>
#include <stdexcept>
#include <system_error>
#include <utility>
#include <vector>

#include <ros/callback_queue.h>
#include <ros/names.h>
#include <xmlrpcpp/XmlRpcValue.h>
#include <nlohmann/json.hpp>

#include "exocet_common/ros/parameter_reader.h"
#include "exocet_common/geo_reference.h"
#include "exocet_common/json_file.h"

namespace exocet_mosaic {

namespace {

namespace fs = std::filesystem;
using diagnostic_msgs::DiagnosticStatus;

// A replay at -r 20 delivers the 50 Hz ground truth at 1 kHz: two seconds of slack before roscpp drops any.
constexpr uint32_t kOdometryQueueSize = 2000;
constexpr uint32_t kUsblQueueSize = 200;
constexpr uint32_t kDatumQueueSize = 10;
// A stamp that goes back by more than this is a new timeline (a replay restarted), not jitter.
constexpr double kStampJumpThreshold_s = 1.0;
// About three hours of 1 Hz fixes waiting for a datum; beyond, the oldest are written without easting/northing.
constexpr size_t kMaxPendingFixes = 10000;
// While the disk refuses writes, rows wait in memory up to this size per file; later rows are dropped (counted).
constexpr size_t kMaxBufferedBytes = 64u << 20;
constexpr double kWarningPeriod_s = 5.0;
constexpr double kDrainQuiet_s = 0.3;
constexpr double kDrainMax_s = 2.0;

static_assert(std::atomic<int>::is_always_lock_free, "the stop flag is written from a signal handler");
std::atomic<int> g_stop_signals{0};

void onStopSignal(int /*signal*/) { g_stop_signals.fetch_add(1); }

std::string suffixFor(int index) { return index <= 1 ? std::string() : "_" + std::to_string(index); }

// Shortest text that reads back as the same double (C++17 to_chars): exact, and short for round values.
void appendNumber(std::string* line, double value) {
  char buffer[64];
  const auto result = std::to_chars(buffer, buffer + sizeof(buffer), value);
  line->append(buffer, result.ptr);
}

// Stamps printed from their integer seconds and nanoseconds: a double cannot hold epoch nanoseconds exactly.
void appendStamp(std::string* line, const ros::Time& t) {
  char buffer[32];
  const int n = std::snprintf(buffer, sizeof(buffer), "%" PRIu32 ".%09" PRIu32, t.sec, t.nsec);
  line->append(buffer, static_cast<size_t>(n));
}

std::string formatNumber(double value) {
  std::string s;
  appendNumber(&s, value);
  return s;
}

std::string formatStamp(const ros::Time& t) {
  std::string s;
  appendStamp(&s, t);
  return s;
}

struct RollPitchYaw_deg {
  double roll = 0.0;
  double pitch = 0.0;
  double yaw = 0.0;
};

// Rotation about x (roll), y (pitch), z (yaw) applied as R = Rz(yaw) Ry(pitch) Rx(roll): tf2's getRPY convention.
RollPitchYaw_deg toRollPitchYaw(double x, double y, double z, double w) {
  const double norm = std::sqrt(x * x + y * y + z * z + w * w);
  x /= norm;
  y /= norm;
  z /= norm;
  w /= norm;
  constexpr double kDegPerRad = 180.0 / M_PI;
  RollPitchYaw_deg rpy;
  rpy.roll = std::atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y)) * kDegPerRad;
  rpy.pitch = std::asin(std::clamp(2.0 * (w * y - z * x), -1.0, 1.0)) * kDegPerRad;
  rpy.yaw = std::atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z)) * kDegPerRad;
  return rpy;
}

// Per-axis 1-sigma of a horizontal position from its two variances; NaN when either is negative (REP convention
// for "unknown").
double horizontalSigma_m(double var_e_m2, double var_n_m2) {
  if (var_e_m2 < 0.0 || var_n_m2 < 0.0) return std::nan("");
  return std::sqrt(0.5 * (var_e_m2 + var_n_m2));
}

// ---- Parameters -------------------------------------------------------------------------------------------------

}  // namespace

TrajectoryLoggerConfig readTrajectoryLoggerConfig(const ros::NodeHandle& private_nh) {
  TrajectoryLoggerConfig config;
  const exocet_common::ParameterReader params(private_nh);
  params.readRequiredString("output_dir", &config.output_dir, "the folder where the trajectory CSV files are written");
  params.readPositiveDouble("flush_period_s", &config.flush_period_s, 60.0,
                            "the wall-clock period between writes to disk (s)");
  params.readTopic("ground_truth_topic", &config.ground_truth_topic);
  params.readTopic("navigation_topic", &config.navigation_topic);
  params.readTopic("usbl_topic", &config.usbl_topic);
  params.readTopic("datum_topic", &config.datum_topic);
  params.readString("utm_frame", &config.utm_frame, {}, "the UTM frame of the odometry, normally 'utm'");
  params.readPositiveDouble("resume_max_gap_s", &config.resume_max_gap_s, 1e6,
                            "the newest files are appended to when the first message comes at most this long after "
                            "their last row (s)");
  return config;
}

void installStopSignalHandlers() {
  struct sigaction action {};
  action.sa_handler = onStopSignal;
  sigemptyset(&action.sa_mask);
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);
}

// ---- One CSV file -------------------------------------------------------------------------------------------------

/// An append-only CSV file holding whole lines: rows wait in memory and go to disk at flush(); a failed or partial
/// write is cut back to the last whole line and retried at the next flush.
class TrajectoryLogger::CsvFile {
 public:
  /// Creates `path` (never overwriting an existing file) and writes `header_line` at once.
  CsvFile(std::string path, const std::string& header_line) : path_(std::move(path)) {
    fd_ = ::open(path_.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_APPEND | O_CLOEXEC, 0644);
    if (fd_ < 0) throw std::system_error(errno, std::generic_category(), "cannot create '" + path_ + "'");
    buffer_ = header_line;
    if (!flush()) {
      ::close(fd_);
      std::remove(path_.c_str());
      throw std::runtime_error("cannot write '" + path_ + "': " + last_error_);
    }
  }

  struct Append {};
  /// Opens an existing `path` for appending (a restart): a partial last line is cut off; `*last_row` receives the
  /// last whole row (empty if the file holds only its header).
  CsvFile(std::string path, Append, std::string* last_row) : path_(std::move(path)) {
    fd_ = ::open(path_.c_str(), O_RDWR | O_APPEND | O_CLOEXEC);
    if (fd_ < 0) throw std::system_error(errno, std::generic_category(), "cannot open '" + path_ + "'");
    std::string text;
    char chunk[65536];
    ssize_t n = 0;
    while ((n = ::pread(fd_, chunk, sizeof(chunk), static_cast<off_t>(text.size()))) > 0)
      text.append(chunk, static_cast<size_t>(n));
    const size_t whole = text.rfind('\n') == std::string::npos ? 0 : text.rfind('\n') + 1;
    if (whole < text.size() && ::ftruncate(fd_, static_cast<off_t>(whole)) != 0) {
      const int error = errno;
      ::close(fd_);
      throw std::system_error(error, std::generic_category(), "cannot cut the partial last row of '" + path_ + "'");
    }
    text.resize(whole);
    if (text.empty()) {
      ::close(fd_);
      throw std::runtime_error("'" + path_ + "' has no header line");
    }
    const size_t header_end = text.find('\n');
    const size_t last_start = text.rfind('\n', text.size() - 2);
    *last_row = last_start == std::string::npos || last_start < header_end
                    ? std::string()
                    : text.substr(last_start + 1, text.size() - last_start - 2);
    bytes_on_disk_ = whole;
    lines_on_disk_ = 1;  // this run's rows are counted from here, as after the header of a new file
  }

  ~CsvFile() { close(); }

  CsvFile(const CsvFile&) = delete;
  CsvFile& operator=(const CsvFile&) = delete;

  /// Queues one whole line (ending in '\n'); false (and counted) if too much is already waiting for the disk.
  bool append(const std::string& line) {
    if (buffer_.size() + line.size() > kMaxBufferedBytes) {
      ++dropped_rows_;
      return false;
    }
    buffer_ += line;
    ++rows_;
    return true;
  }

  /// Writes the queued lines. On error keeps whatever was not written and returns false (see lastError()).
  bool flush() {
    if (buffer_.empty()) return true;
    if (fd_ < 0) {
      last_error_ = "file already closed";
      return false;
    }
    size_t done = 0;
    while (done < buffer_.size()) {
      const ssize_t n = ::write(fd_, buffer_.data() + done, buffer_.size() - done);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) {
        last_error_ = n < 0 ? std::strerror(errno) : "write() wrote nothing";
        break;
      }
      done += static_cast<size_t>(n);
    }
    if (done == buffer_.size()) {
      lines_on_disk_ += static_cast<uint64_t>(std::count(buffer_.begin(), buffer_.end(), '\n'));
      bytes_on_disk_ += done;
      buffer_.clear();
      failing_ = false;
      return true;
    }
    // Keep the file made of whole lines: cut a partial line back off (O_APPEND makes the next write land at the
    // new end). If even that fails, count the fragment as written: the next flush completes the line.
    size_t written = done;
    const size_t last_newline = done == 0 ? std::string::npos : buffer_.rfind('\n', done - 1);
    const size_t whole = last_newline == std::string::npos ? 0 : last_newline + 1;
    if (whole < done && ::ftruncate(fd_, static_cast<off_t>(bytes_on_disk_ + whole)) == 0) written = whole;
    lines_on_disk_ += static_cast<uint64_t>(std::count(buffer_.begin(), buffer_.begin() + written, '\n'));
    bytes_on_disk_ += written;
    buffer_.erase(0, written);
    failing_ = true;
    return false;
  }

  /// Flushes, fsyncs and closes; false (see lastError()) if something could not be written.
  bool close() {
    if (fd_ < 0) return buffer_.empty();
    bool ok = flush();
    // The periodic flushes skip fsync (it can block the callbacks for long on a busy disk); closing is the moment
    // to make the rows survive a power cut.
    if (::fsync(fd_) != 0 && errno != EINVAL) {
      last_error_ = std::string("fsync: ") + std::strerror(errno);
      ok = false;
    }
    if (::close(fd_) != 0) {
      last_error_ = std::string("close: ") + std::strerror(errno);
      ok = false;
    }
    fd_ = -1;
    return ok;
  }

  const std::string& path() const { return path_; }
  /// Rows accepted by append(), whether on disk yet or not.
  uint64_t rows() const { return rows_; }
  /// Rows wholly on disk (the header line excluded).
  uint64_t rowsOnDisk() const { return lines_on_disk_ > 0 ? lines_on_disk_ - 1 : 0; }
  uint64_t bytesOnDisk() const { return bytes_on_disk_; }
  size_t bytesWaiting() const { return buffer_.size(); }
  uint64_t droppedRows() const { return dropped_rows_; }
  bool failing() const { return failing_; }
  const std::string& lastError() const { return last_error_; }

 private:
  std::string path_;
  int fd_ = -1;
  std::string buffer_;
  uint64_t rows_ = 0;
  uint64_t bytes_on_disk_ = 0;
  uint64_t lines_on_disk_ = 0;
  uint64_t dropped_rows_ = 0;
  bool failing_ = false;
  std::string last_error_;
};

/// The files of one timeline (one replay of a bag): the three CSV files and the datum, with a common suffix.
struct TrajectoryLogger::FileSet {
  int index = 1;  ///< 1 for the plain names, n for the suffix "_n"
  uint64_t generation = 0;
  std::string datum_path;
  bool datum_written = false;
  std::unique_ptr<CsvFile> ground_truth;
  std::unique_ptr<CsvFile> navigation;
  std::unique_ptr<CsvFile> usbl;

  std::vector<CsvFile*> files() const { return {ground_truth.get(), navigation.get(), usbl.get()}; }
};

// ---- The node -----------------------------------------------------------------------------------------------------

TrajectoryLogger::TrajectoryLogger(ros::NodeHandle nh, ros::NodeHandle private_nh)
    : config_(readTrajectoryLoggerConfig(private_nh)), nh_(nh), private_nh_(private_nh), updater_(nh, private_nh) {
  std::error_code error;
  fs::create_directories(config_.output_dir, error);
  if (error)
    throw std::runtime_error(exocet_common::ParameterReader(private_nh_).describe("output_dir") +
                             ": cannot create folder '" + config_.output_dir + "': " + error.message());
  output_dir_abs_ = fs::absolute(config_.output_dir, error).lexically_normal().string();
  if (error) output_dir_abs_ = config_.output_dir;
  try {
    current_set_ = reopenNewestFileSet();
    if (!current_set_) current_set_ = openFileSet(1);
  } catch (const std::exception& e) {
    throw std::runtime_error(exocet_common::ParameterReader(private_nh_).describe("output_dir") + " '" +
                             output_dir_abs_ + "' is not writable: " + e.what());
  }
  if (current_set_->index > 1 && !reopened_pending_)
    ROS_WARN(
        "%s already holds trajectory files of an earlier run: writing this run's with the suffix '%s' "
        "(nothing is overwritten)",
        output_dir_abs_.c_str(), suffixFor(current_set_->index).c_str());

  ground_truth_.label = "ground truth";
  ground_truth_.topic = nh_.resolveName(config_.ground_truth_topic);
  navigation_.label = "navigation";
  navigation_.topic = nh_.resolveName(config_.navigation_topic);
  usbl_.label = "USBL fixes";
  usbl_.topic = nh_.resolveName(config_.usbl_topic);
  datum_stream_.label = "datum";
  datum_stream_.topic = nh_.resolveName(config_.datum_topic);

  updater_.setHardwareID("none");
  updater_.add(ground_truth_.label,
               [this](diagnostic_updater::DiagnosticStatusWrapper& s) { diagnoseStream(&ground_truth_, s); });
  updater_.add(navigation_.label,
               [this](diagnostic_updater::DiagnosticStatusWrapper& s) { diagnoseStream(&navigation_, s); });
  updater_.add(usbl_.label, [this](diagnostic_updater::DiagnosticStatusWrapper& s) { diagnoseUsbl(s); });
  updater_.add(datum_stream_.label, [this](diagnostic_updater::DiagnosticStatusWrapper& s) { diagnoseDatum(s); });
  updater_.add("output files", [this](diagnostic_updater::DiagnosticStatusWrapper& s) { diagnoseFiles(s); });

  const ros::TransportHints hints = ros::TransportHints().tcpNoDelay();
  ground_truth_sub_ =
      nh_.subscribe(ground_truth_.topic, kOdometryQueueSize, &TrajectoryLogger::onGroundTruth, this, hints);
  navigation_sub_ = nh_.subscribe(navigation_.topic, kOdometryQueueSize, &TrajectoryLogger::onNavigation, this, hints);
  usbl_sub_ = nh_.subscribe(usbl_.topic, kUsblQueueSize, &TrajectoryLogger::onUsbl, this, hints);
  datum_sub_ = nh_.subscribe(datum_stream_.topic, kDatumQueueSize, &TrajectoryLogger::onDatum, this, hints);

  // Wall-clock timers: the flushes and the diagnostics must go on when a replay pauses or its clock jumps back.
  flush_timer_ =
      nh_.createSteadyTimer(ros::WallDuration(config_.flush_period_s), &TrajectoryLogger::onFlushTimer, this);
  const double diagnostics_period_s = updater_.getPeriod() > 0.0 ? updater_.getPeriod() : 1.0;
  diagnostics_timer_ =
      nh_.createSteadyTimer(ros::WallDuration(diagnostics_period_s), &TrajectoryLogger::onDiagnosticsTimer, this);

  ROS_INFO("logging %s, %s and %s (datum on %s) into %s, flushed every %g s", ground_truth_.topic.c_str(),
           navigation_.topic.c_str(), usbl_.topic.c_str(), datum_stream_.topic.c_str(), output_dir_abs_.c_str(),
           config_.flush_period_s);
}

TrajectoryLogger::~TrajectoryLogger() {
  if (!pending_fixes_.empty()) {
    ROS_WARN(
        "no datum ever arrived on %s: writing %zu USBL fixes with latitude/longitude only (easting_m and "
        "northing_m are nan)",
        datum_stream_.topic.c_str(), pending_fixes_.size());
    for (const PendingFix& fix : pending_fixes_) writeFix(&usbl_, current_set_.get(), fix);
    pending_fixes_.clear();
  }
  if (previous_set_) closeFileSet(previous_set_.get());
  if (current_set_) closeFileSet(current_set_.get());
}

void TrajectoryLogger::spinUntilStopped() {
  ros::CallbackQueue* queue = ros::getGlobalCallbackQueue();
  while (ros::ok() && g_stop_signals.load() == 0) queue->callAvailable(ros::WallDuration(0.1));
  // Stopped by a signal (roslaunch stops the nodes as soon as a required `rosbag play` ends): the last messages
  // of the bag may still be in the sockets or the queue. Process them until the topics fall quiet.
  const auto messages = [this] { return ground_truth_.received + navigation_.received + usbl_.received; };
  const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(kDrainMax_s);
  ros::WallTime last_message = ros::WallTime::now();
  uint64_t seen = messages();
  while (ros::ok() && g_stop_signals.load() == 1 && ros::WallTime::now() < deadline &&
         (ros::WallTime::now() - last_message).toSec() < kDrainQuiet_s) {
    queue->callAvailable(ros::WallDuration(0.02));
    if (messages() != seen) {
      seen = messages();
      last_message = ros::WallTime::now();
    }
  }
  flush();
}

void TrajectoryLogger::flush() {
  for (FileSet* set : {previous_set_.get(), current_set_.get()}) {
    if (set == nullptr) continue;
    for (CsvFile* file : set->files())
      if (!file->flush()) noteWriteError(file->path(), file->lastError());
  }
}

void TrajectoryLogger::onFlushTimer(const ros::SteadyTimerEvent& /*event*/) { flush(); }

void TrajectoryLogger::onDiagnosticsTimer(const ros::SteadyTimerEvent& /*event*/) { updater_.force_update(); }

void TrajectoryLogger::noteWriteError(const std::string& path, const std::string& error) {
  ++write_errors_;
  ++window_write_errors_;
  last_write_error_ = path + ": " + error;
  uint64_t held_back = 0;
  if (!write_error_messages_.allow(kWarningPeriod_s, &held_back)) return;
  const std::string more = held_back == 0 ? std::string()
                                          : " (and " + std::to_string(held_back) + " more write errors in the last " +
                                                formatNumber(kWarningPeriod_s) + " s)";
  ROS_ERROR("cannot write %s: %s; the rows wait in memory and are retried every %g s%s", path.c_str(), error.c_str(),
            config_.flush_period_s, more.c_str());
}

bool TrajectoryLogger::Throttle::allow(double period_s, uint64_t* held_back) {
  const ros::WallTime now = ros::WallTime::now();
  if (!last.isZero() && (now - last).toSec() < period_s) {
    ++suppressed;
    return false;
  }
  *held_back = suppressed;
  suppressed = 0;
  last = now;
  return true;
}

void TrajectoryLogger::reject(Stream* stream, const std::string& field, const std::string& problem) {
  ++stream->rejected;
  ++stream->window_rejected;
  stream->last_rejection = field + " " + problem;
  // Throttled per topic rather than per call site (as ROS_WARN_THROTTLE would), so one bad topic cannot hide another.
  uint64_t held_back = 0;
  if (!stream->warnings.allow(kWarningPeriod_s, &held_back)) return;
  if (held_back > 0)
    ROS_WARN("rejected a message on %s: %s %s (and %" PRIu64 " other rejections on this topic in the last %g s)",
             stream->topic.c_str(), field.c_str(), problem.c_str(), held_back, kWarningPeriod_s);
  else
    ROS_WARN("rejected a message on %s: %s %s", stream->topic.c_str(), field.c_str(), problem.c_str());
}

// ---- Time order and file sets -------------------------------------------------------------------------------------

void TrajectoryLogger::checkClock() {
  const ros::Time now = ros::Time::now();
  if (now.isZero()) return;  // sim time before the first /clock
  if (!last_clock_.isZero() && now < last_clock_) {
    ++clock_jumps_;
    // A topic may have seen the jump first (its stamps went back) and started the new set already.
    if (clock_generation_ == generation_)
      startNewFileSet("the ROS clock went back from " + formatStamp(last_clock_) + " to " + formatStamp(now) +
                      " (a bag replayed again?)");
    clock_generation_ = generation_;
  }
  last_clock_ = now;
}

TrajectoryLogger::FileSet* TrajectoryLogger::placeInTime(Stream* stream, const ros::Time& stamp, bool reorder_ok) {
  if (reopened_pending_) decideOnReopenedSet(stamp);
  if (stream->last_stamp.isZero()) {
    stream->generation = generation_;
    stream->last_stamp = stamp;
    return current_set_.get();
  }
  if (stamp < stream->last_stamp) {
    const double back_s = (stream->last_stamp - stamp).toSec();
    if (stream->generation < generation_) {
      // This topic's first message since a jump that the clock or another topic revealed: same new timeline.
    } else if (back_s > kStampJumpThreshold_s) {
      startNewFileSet(stream->topic + " header.stamp went back by " + formatNumber(back_s) + " s, from " +
                      formatStamp(stream->last_stamp) + " to " + formatStamp(stamp) + " (a bag replayed again?)");
    } else if (!reorder_ok) {
      reject(stream, "header.stamp",
             formatStamp(stamp) + " is " + formatNumber(back_s) + " s older than the previous message's " +
                 formatStamp(stream->last_stamp) + " (out of order)");
      return nullptr;
    } else {
      return current_set_.get();  // a fix overtaken by a later one: kept, the latest stamp stays the reference
    }
    stream->generation = generation_;
    stream->last_stamp = stamp;
    return current_set_.get();
  }
  stream->last_stamp = stamp;
  if (stream->generation < generation_) {
    // Stamps still going forward after a jump: a message sent before the jump, still in flight. It belongs with
    // the timeline it came from.
    if (previous_set_ && previous_set_->generation == stream->generation) return previous_set_.get();
    stream->generation = generation_;
  }
  return current_set_.get();
}

std::unique_ptr<TrajectoryLogger::FileSet> TrajectoryLogger::openFileSet(int first_index) {
  constexpr int kMaxSets = 10000;
  for (int index = first_index; index < first_index + kMaxSets; ++index) {
    const std::string suffix = suffixFor(index);
    const std::string base = output_dir_abs_ + "/";
    const std::vector<std::string> paths = {base + "ground_truth" + suffix + ".csv",
                                            base + "navigation" + suffix + ".csv",
                                            base + "usbl_fixes" + suffix + ".csv", base + "datum" + suffix + ".json"};
    bool taken = false;
    for (const std::string& path : paths) {
      std::error_code error;
      taken = taken || fs::exists(path, error) || error;
    }
    if (taken) continue;
    auto set = std::make_unique<FileSet>();
    set->index = index;
    set->datum_path = paths[3];
    try {
      set->ground_truth =
          std::make_unique<CsvFile>(paths[0], "stamp_s,easting_m,northing_m,up_m,roll_deg,pitch_deg,yaw_deg\n");
      set->navigation = std::make_unique<CsvFile>(
          paths[1], "stamp_s,easting_m,northing_m,up_m,roll_deg,pitch_deg,yaw_deg,horizontal_sigma_m,up_sigma_m\n");
      set->usbl = std::make_unique<CsvFile>(
          paths[2], "stamp_s,arrival_s,latitude_deg,longitude_deg,easting_m,northing_m,horizontal_sigma_m\n");
    } catch (const std::exception& e) {
      for (CsvFile* file : set->files())
        if (file != nullptr) std::remove(file->path().c_str());
      // Another process took this name between the check and the creation: try the next suffix.
      const auto* system_error = dynamic_cast<const std::system_error*>(&e);
      if (system_error != nullptr && system_error->code() == std::errc::file_exists) continue;
      throw;
    }
    return set;
  }
  throw std::runtime_error("more than " + std::to_string(kMaxSets) + " sets of trajectory files in " + output_dir_abs_);
}

std::unique_ptr<TrajectoryLogger::FileSet> TrajectoryLogger::reopenNewestFileSet() {
  int newest = 0;
  for (int index = 1; index < 10000; ++index) {
    std::error_code error;
    if (!fs::exists(output_dir_abs_ + "/ground_truth" + suffixFor(index) + ".csv", error)) break;
    newest = index;
  }
  if (newest == 0) return nullptr;
  const std::string suffix = suffixFor(newest);
  const std::string base = output_dir_abs_ + "/";
  auto set = std::make_unique<FileSet>();
  set->index = newest;
  set->datum_path = base + "datum" + suffix + ".json";
  std::string last_rows[3];
  try {
    set->ground_truth =
        std::make_unique<CsvFile>(base + "ground_truth" + suffix + ".csv", CsvFile::Append(), &last_rows[0]);
    set->navigation =
        std::make_unique<CsvFile>(base + "navigation" + suffix + ".csv", CsvFile::Append(), &last_rows[1]);
    set->usbl = std::make_unique<CsvFile>(base + "usbl_fixes" + suffix + ".csv", CsvFile::Append(), &last_rows[2]);
  } catch (const std::exception& e) {
    ROS_WARN("the newest trajectory files in %s cannot be appended to (%s): a new set is started",
             output_dir_abs_.c_str(), e.what());
    return nullptr;
  }
  for (const std::string& row : last_rows) {
    // stamp_s, first on each row, printed as sec.nanosec
    const std::string text = row.substr(0, row.find(','));
    const size_t dot = text.find('.');
    if (text.empty() || dot == std::string::npos) continue;
    try {
      const ros::Time stamp(static_cast<uint32_t>(std::stoul(text.substr(0, dot))),
                            static_cast<uint32_t>(std::stoul(text.substr(dot + 1))));
      if (stamp > reopened_last_stamp_) reopened_last_stamp_ = stamp;
    } catch (const std::exception&) {
      // A row that does not start with a stamp: no timeline to continue from it.
    }
  }
  reopened_pending_ = true;
  return set;
}

void TrajectoryLogger::decideOnReopenedSet(const ros::Time& stamp) {
  reopened_pending_ = false;
  std::string why;
  if (!reopened_last_stamp_.isZero()) {
    const double gap_s = stamp.toSec() - reopened_last_stamp_.toSec();
    if (gap_s < -kStampJumpThreshold_s)
      why = "the first message is stamped " + formatNumber(-gap_s) + " s before their last row (a bag played again)";
    else if (gap_s > config_.resume_max_gap_s)
      why = "the first message is stamped " + formatNumber(gap_s) +
            " s after their last row, more than "
            "~resume_max_gap_s = " +
            formatNumber(config_.resume_max_gap_s) + " s (another dive)";
  }
  if (why.empty()) {
    if (have_datum_) writeDatumFile(current_set_.get());
    resume_note_ = "appending to the set '" + suffixFor(current_set_->index) + "' left by a run interrupted at " +
                   formatStamp(reopened_last_stamp_);
    ROS_WARN(
        "%s: continuing the trajectory files of a run interrupted at %s (a restart): the rows are appended to "
        "%s/*%s.csv",
        formatStamp(stamp).c_str(), formatStamp(reopened_last_stamp_).c_str(), output_dir_abs_.c_str(),
        suffixFor(current_set_->index).c_str());
    return;
  }
  std::unique_ptr<FileSet> next;
  try {
    next = openFileSet(current_set_->index + 1);
  } catch (const std::exception& e) {
    noteWriteError(output_dir_abs_, std::string("cannot start a new set of files: ") + e.what());
    return;  // appending beats losing the run
  }
  next->generation = generation_;
  closeFileSet(current_set_.get());
  current_set_ = std::move(next);
  if (have_datum_) writeDatumFile(current_set_.get());
  resume_note_ = "a new set: " + why;
  ROS_WARN(
      "%s already holds trajectory files of an earlier run (%s): writing this run's with the suffix '%s' "
      "(nothing is overwritten)",
      output_dir_abs_.c_str(), why.c_str(), suffixFor(current_set_->index).c_str());
}

void TrajectoryLogger::startNewFileSet(const std::string& reason) {
  std::unique_ptr<FileSet> next;
  try {
    next = openFileSet(current_set_->index + 1);
  } catch (const std::exception& e) {
    // Interleaving two timelines is bad, losing them is worse: keep writing where we are, loudly.
    ++generation_;
    noteWriteError(output_dir_abs_, std::string("cannot start a new set of files after a time jump: ") + e.what());
    return;
  }
  ++generation_;
  next->generation = generation_;
  ROS_WARN("%s: starting a new set of files with the suffix '%s' rather than mixing two timelines in one file",
           reason.c_str(), suffixFor(next->index).c_str());
  if (previous_set_) closeFileSet(previous_set_.get());
  previous_set_.reset();
  flush();
  previous_set_ = std::move(current_set_);
  current_set_ = std::move(next);
  if (have_datum_) writeDatumFile(current_set_.get());
}

void TrajectoryLogger::closeFileSet(FileSet* set) {
  for (CsvFile* file : set->files()) {
    const bool closed = file->close();
    const uint64_t lost = file->rows() + file->droppedRows() - file->rowsOnDisk();
    if (closed && lost == 0) {
      ROS_INFO("%s: %" PRIu64 " rows", file->path().c_str(), file->rowsOnDisk());
      continue;
    }
    ++write_errors_;
    ++window_write_errors_;
    last_write_error_ = file->path() + ": " + file->lastError();
    // Not throttled: this is the last word on the file.
    ROS_ERROR("%s: only %" PRIu64 " of %" PRIu64 " rows written, %" PRIu64 " lost: %s", file->path().c_str(),
              file->rowsOnDisk(), file->rows() + file->droppedRows(), lost, file->lastError().c_str());
  }
}

void TrajectoryLogger::writeDatumFile(FileSet* set) {
  const exocet_msgs::GeoDatum& d = datum_msg_;
  nlohmann::ordered_json json;
  json["topic"] = datum_stream_.topic;
  json["frame_id"] = d.frame_id;
  json["utm_zone"] = static_cast<int>(d.utm_zone);
  json["northern_hemisphere"] = static_cast<bool>(d.northern_hemisphere);
  json["epsg"] = static_cast<int>(d.epsg);
  json["origin_latitude_deg"] = d.origin_latitude_deg;
  json["origin_longitude_deg"] = d.origin_longitude_deg;
  json["origin_easting_m"] = d.origin_easting_m;
  json["origin_northing_m"] = d.origin_northing_m;
  try {
    exocet_common::writeJsonFileAtomically(set->datum_path, json);
    set->datum_written = true;
  } catch (const std::exception& e) {
    noteWriteError(set->datum_path, e.what());
  }
}

// ---- Messages -----------------------------------------------------------------------------------------------------

void TrajectoryLogger::onGroundTruth(const nav_msgs::Odometry::ConstPtr& msg) {
  logOdometry(&ground_truth_, *msg, false);
}

void TrajectoryLogger::onNavigation(const nav_msgs::Odometry::ConstPtr& msg) { logOdometry(&navigation_, *msg, true); }

void TrajectoryLogger::logOdometry(Stream* stream, const nav_msgs::Odometry& msg, bool with_sigma) {
  ++stream->received;
  checkClock();
  if (msg.header.frame_id != config_.utm_frame) {
    reject(stream, "header.frame_id",
           "is '" + msg.header.frame_id + "', not the UTM frame '" + config_.utm_frame + "' (parameter ~utm_frame)");
    return;
  }
  if (msg.header.stamp.isZero()) {
    reject(stream, "header.stamp", "is 0 (unset)");
    return;
  }
  const geometry_msgs::Point& p = msg.pose.pose.position;
  const geometry_msgs::Quaternion& q = msg.pose.pose.orientation;
  const std::pair<const char*, double> fields[] = {{"pose.pose.position.x", p.x},    {"pose.pose.position.y", p.y},
                                                   {"pose.pose.position.z", p.z},    {"pose.pose.orientation.x", q.x},
                                                   {"pose.pose.orientation.y", q.y}, {"pose.pose.orientation.z", q.z},
                                                   {"pose.pose.orientation.w", q.w}};
  for (const auto& field : fields) {
    if (!std::isfinite(field.second)) {
      reject(stream, field.first, "is " + formatNumber(field.second));
      return;
    }
  }
  const double q_norm = std::sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w);
  if (!(q_norm > 1e-6)) {
    reject(stream, "pose.pose.orientation", "is a zero quaternion (no rotation defined)");
    return;
  }
  if (with_sigma) {
    for (const int i : {0, 7, 14}) {
      if (!std::isfinite(msg.pose.covariance[i])) {
        reject(stream, "pose.covariance[" + std::to_string(i) + "]", "is " + formatNumber(msg.pose.covariance[i]));
        return;
      }
    }
  }
  FileSet* set = placeInTime(stream, msg.header.stamp, false);
  if (set == nullptr) return;

  const RollPitchYaw_deg rpy = toRollPitchYaw(q.x, q.y, q.z, q.w);
  std::string row;
  row.reserve(192);
  appendStamp(&row, msg.header.stamp);
  for (const double value : {p.x, p.y, p.z, rpy.roll, rpy.pitch, rpy.yaw}) {
    row += ',';
    appendNumber(&row, value);
  }
  if (with_sigma) {
    row += ',';
    appendNumber(&row, horizontalSigma_m(msg.pose.covariance[0], msg.pose.covariance[7]));
    row += ',';
    const double var_up_m2 = msg.pose.covariance[14];
    appendNumber(&row, var_up_m2 < 0.0 ? std::nan("") : std::sqrt(var_up_m2));
  }
  row += '\n';
  CsvFile* file = with_sigma ? set->navigation.get() : set->ground_truth.get();
  if (!file->append(row)) {
    noteWriteError(file->path(),
                   "rows dropped: " + std::to_string(kMaxBufferedBytes) + " bytes already wait for the disk");
    return;
  }
  ++stream->logged;
  ++stream->window_logged;
  if (stream->window_first_stamp.isZero()) stream->window_first_stamp = msg.header.stamp;
  stream->window_last_stamp = msg.header.stamp;
}

void TrajectoryLogger::onUsbl(const sensor_msgs::NavSatFix::ConstPtr& msg) {
  ++usbl_.received;
  checkClock();
  PendingFix fix;
  fix.arrival = ros::Time::now();
  fix.stamp = msg->header.stamp;
  fix.latitude_deg = msg->latitude;
  fix.longitude_deg = msg->longitude;
  if (fix.stamp.isZero()) {
    reject(&usbl_, "header.stamp", "is 0 (unset)");
    return;
  }
  if (msg->status.status < sensor_msgs::NavSatStatus::STATUS_FIX) {
    reject(&usbl_, "status.status", "is " + std::to_string(msg->status.status) + " (no fix)");
    return;
  }
  if (!(fix.latitude_deg >= -90.0 && fix.latitude_deg <= 90.0)) {
    reject(&usbl_, "latitude", "is " + formatNumber(fix.latitude_deg) + " deg, outside [-90, 90]");
    return;
  }
  if (!(fix.longitude_deg >= -180.0 && fix.longitude_deg < 360.0)) {
    reject(&usbl_, "longitude", "is " + formatNumber(fix.longitude_deg) + " deg, outside [-180, 360)");
    return;
  }
  if (msg->position_covariance_type == sensor_msgs::NavSatFix::COVARIANCE_TYPE_UNKNOWN) {
    fix.horizontal_sigma_m = std::nan("");
  } else {
    for (const int i : {0, 4}) {
      const double variance = msg->position_covariance[i];
      if (!(std::isfinite(variance) && variance >= 0.0)) {
        reject(&usbl_, "position_covariance[" + std::to_string(i) + "]",
               "is " + formatNumber(variance) + " with position_covariance_type " +
                   std::to_string(msg->position_covariance_type) + " (a variance must be finite and >= 0)");
        return;
      }
    }
    fix.horizontal_sigma_m = horizontalSigma_m(msg->position_covariance[0], msg->position_covariance[4]);
  }
  FileSet* set = placeInTime(&usbl_, fix.stamp, true);
  if (set == nullptr) return;
  if (have_datum_) {
    writeFix(&usbl_, set, fix);
    return;
  }
  pending_fixes_.push_back(fix);
  std::string note = std::to_string(pending_fixes_.size()) + " USBL fixes wait for a datum on " + datum_stream_.topic +
                     " to be converted to UTM";
  if (pending_fixes_.size() > kMaxPendingFixes) {
    writeFix(&usbl_, set, pending_fixes_.front());
    pending_fixes_.pop_front();
    ++fixes_written_unconverted_;
    note += "; the oldest are written with latitude/longitude only (easting_m, northing_m nan)";
  }
  uint64_t held_back = 0;
  if (pending_warnings_.allow(kWarningPeriod_s, &held_back)) ROS_WARN("%s", note.c_str());
}

void TrajectoryLogger::writeFix(Stream* stream, FileSet* set, const PendingFix& fix) {
  double easting_m = std::nan("");
  double northing_m = std::nan("");
  if (have_datum_) {
    try {
      const Eigen::Vector2d grid = exocet_common::latLonToGrid(datum_, fix.latitude_deg, fix.longitude_deg);
      easting_m = grid.x();
      northing_m = grid.y();
    } catch (const std::exception& e) {
      reject(stream, "latitude/longitude",
             formatNumber(fix.latitude_deg) + ", " + formatNumber(fix.longitude_deg) +
                 " cannot be expressed in EPSG:" + std::to_string(datum_.epsg) + ": " + e.what());
      return;
    }
  }
  std::string row;
  row.reserve(160);
  appendStamp(&row, fix.stamp);
  row += ',';
  appendStamp(&row, fix.arrival);
  for (const double value : {fix.latitude_deg, fix.longitude_deg, easting_m, northing_m, fix.horizontal_sigma_m}) {
    row += ',';
    appendNumber(&row, value);
  }
  row += '\n';
  if (!set->usbl->append(row)) {
    noteWriteError(set->usbl->path(),
                   "rows dropped: " + std::to_string(kMaxBufferedBytes) + " bytes already wait for the disk");
    return;
  }
  ++stream->logged;
  ++stream->window_logged;
  if (stream->window_first_stamp.isZero()) stream->window_first_stamp = fix.stamp;
  stream->window_last_stamp = fix.stamp;
}

void TrajectoryLogger::onDatum(const exocet_msgs::GeoDatum::ConstPtr& msg) {
  ++datum_stream_.received;
  const exocet_msgs::GeoDatum& d = *msg;
  if (d.frame_id != config_.utm_frame) {
    reject(&datum_stream_, "frame_id",
           "is '" + d.frame_id + "' but the odometry is logged in '" + config_.utm_frame +
               "' (parameter ~utm_frame): this datum describes another frame");
    return;
  }
  if (d.utm_zone < 0 || d.utm_zone > 60) {
    reject(&datum_stream_, "utm_zone", "is " + std::to_string(d.utm_zone) + ", outside [0, 60] (0 = UPS)");
    return;
  }
  const int expected_epsg =
      d.utm_zone == 0 ? (d.northern_hemisphere ? 32661 : 32761) : (d.northern_hemisphere ? 32600 : 32700) + d.utm_zone;
  if (d.epsg != expected_epsg) {
    reject(&datum_stream_, "epsg",
           "is " + std::to_string(d.epsg) + " but utm_zone " + std::to_string(d.utm_zone) +
               (d.northern_hemisphere ? " north" : " south") + " is EPSG:" + std::to_string(expected_epsg));
    return;
  }
  for (const auto& field : {std::make_pair("origin_latitude_deg", d.origin_latitude_deg),
                            std::make_pair("origin_longitude_deg", d.origin_longitude_deg),
                            std::make_pair("origin_easting_m", d.origin_easting_m),
                            std::make_pair("origin_northing_m", d.origin_northing_m)}) {
    if (!std::isfinite(field.second)) {
      reject(&datum_stream_, field.first, "is " + formatNumber(field.second));
      return;
    }
  }
  if (have_datum_ && d.utm_zone == datum_msg_.utm_zone && d.northern_hemisphere == datum_msg_.northern_hemisphere &&
      d.origin_latitude_deg == datum_msg_.origin_latitude_deg &&
      d.origin_longitude_deg == datum_msg_.origin_longitude_deg) {
    ++datum_stream_.logged;  // the same datum again (latched topic, replay restarted): nothing changes
    return;
  }
  const bool zone_changed =
      have_datum_ && (d.utm_zone != datum_msg_.utm_zone || d.northern_hemisphere != datum_msg_.northern_hemisphere);
  if (zone_changed) {
    // Easting/northing of two zones in one file would be nonsense side by side.
    startNewFileSet("the datum changed from EPSG:" + std::to_string(datum_msg_.epsg) +
                    " to EPSG:" + std::to_string(d.epsg));
  }
  datum_msg_ = d;
  datum_.utm_zone = d.utm_zone;
  datum_.northern_hemisphere = d.northern_hemisphere;
  datum_.epsg = d.epsg;
  datum_.origin_latitude_deg = d.origin_latitude_deg;
  datum_.origin_longitude_deg = d.origin_longitude_deg;
  datum_.origin_easting_m = d.origin_easting_m;
  datum_.origin_northing_m = d.origin_northing_m;
  have_datum_ = true;
  ++datum_stream_.logged;
  // The reopened set's datum.json is an earlier run's until the first message says the run is this one.
  if (!reopened_pending_) writeDatumFile(current_set_.get());
  const std::string waiting = pending_fixes_.empty() ? std::string()
                                                     : "; converting the " + std::to_string(pending_fixes_.size()) +
                                                           " USBL fixes that came before it";
  ROS_INFO("datum on %s: EPSG:%d (UTM zone %d %s), frame '%s'%s", datum_stream_.topic.c_str(), d.epsg, d.utm_zone,
           d.northern_hemisphere ? "north" : "south", d.frame_id.c_str(), waiting.c_str());
  convertPendingFixes();
}

void TrajectoryLogger::convertPendingFixes() {
  for (const PendingFix& fix : pending_fixes_) writeFix(&usbl_, current_set_.get(), fix);
  pending_fixes_.clear();
}

// ---- Diagnostics --------------------------------------------------------------------------------------------------

void TrajectoryLogger::diagnoseStream(Stream* stream, diagnostic_updater::DiagnosticStatusWrapper& status) {
  double rate_hz = 0.0;
  if (stream->window_logged >= 2) {
    const double span_s = (stream->window_last_stamp - stream->window_first_stamp).toSec();
    if (span_s > 0.0) rate_hz = static_cast<double>(stream->window_logged - 1) / span_s;
  }
  if (stream->window_rejected > 0) {
    status.summaryf(DiagnosticStatus::WARN, "%" PRIu64 " messages rejected since the last report: %s",
                    stream->window_rejected, stream->last_rejection.c_str());
  } else if (stream->received == 0) {
    status.summaryf(DiagnosticStatus::OK, "no message yet on %s", stream->topic.c_str());
  } else if (stream->window_logged == 0) {
    status.summaryf(DiagnosticStatus::OK, "no message since the last report (%" PRIu64 " logged)", stream->logged);
  } else {
    status.summaryf(DiagnosticStatus::OK, "logging at %.1f Hz", rate_hz);
  }
  status.add("topic", stream->topic);
  status.add("messages received", stream->received);
  status.add("messages logged", stream->logged);
  status.add("messages rejected", stream->rejected);
  status.add("messages rejected since the last report", stream->window_rejected);
  status.addf("rate (Hz, from the header stamps since the last report)", "%.3f", rate_hz);
  status.add("last stamp", stream->last_stamp.isZero() ? std::string("none") : formatStamp(stream->last_stamp));
  status.add("last rejection", stream->last_rejection.empty() ? std::string("none") : stream->last_rejection);
  stream->window_logged = 0;
  stream->window_rejected = 0;
  stream->window_first_stamp = ros::Time();
  stream->window_last_stamp = ros::Time();
}

void TrajectoryLogger::diagnoseUsbl(diagnostic_updater::DiagnosticStatusWrapper& status) {
  diagnoseStream(&usbl_, status);
  status.add("fixes waiting for the datum", pending_fixes_.size());
  status.add("fixes written without easting/northing", fixes_written_unconverted_);
  if (!pending_fixes_.empty())
    status.mergeSummaryf(DiagnosticStatus::WARN, "%zu fixes wait for a datum on %s", pending_fixes_.size(),
                         datum_stream_.topic.c_str());
}

void TrajectoryLogger::diagnoseDatum(diagnostic_updater::DiagnosticStatusWrapper& status) {
  status.add("topic", datum_stream_.topic);
  status.add("messages received", datum_stream_.received);
  status.add("messages rejected", datum_stream_.rejected);
  status.add("last rejection",
             datum_stream_.last_rejection.empty() ? std::string("none") : datum_stream_.last_rejection);
  if (!have_datum_) {
    status.summaryf(datum_stream_.rejected > 0 ? DiagnosticStatus::WARN : DiagnosticStatus::OK,
                    "no valid datum yet on %s: USBL fixes wait for it", datum_stream_.topic.c_str());
    return;
  }
  status.summaryf(DiagnosticStatus::OK, "EPSG:%d (UTM zone %d %s)", datum_msg_.epsg, datum_msg_.utm_zone,
                  datum_msg_.northern_hemisphere ? "north" : "south");
  status.add("EPSG", datum_msg_.epsg);
  status.add("UTM zone", datum_msg_.utm_zone);
  status.add("northern hemisphere", datum_msg_.northern_hemisphere);
  status.add("frame", datum_msg_.frame_id);
}

void TrajectoryLogger::diagnoseFiles(diagnostic_updater::DiagnosticStatusWrapper& status) {
  status.add("output folder", output_dir_abs_);
  status.add("file set", current_set_->index);
  if (!resume_note_.empty()) status.add("files at start-up", resume_note_);
  status.add("clock jumps back", clock_jumps_);
  status.add("write errors", write_errors_);
  status.add("last write error", last_write_error_.empty() ? std::string("none") : last_write_error_);
  bool failing = false;
  uint64_t dropped_rows = 0;
  for (const CsvFile* file : current_set_->files()) {
    status.addf(file->path(), "%" PRIu64 " rows on disk (%" PRIu64 " bytes), %" PRIu64 " waiting", file->rowsOnDisk(),
                file->bytesOnDisk(), file->rows() - file->rowsOnDisk());
    failing = failing || file->failing();
    dropped_rows += file->droppedRows();
  }
  if (current_set_->datum_written) status.add(current_set_->datum_path, "written");
  status.add("rows dropped (disk failing for too long)", dropped_rows);
  if (failing || window_write_errors_ > 0) {
    status.summaryf(DiagnosticStatus::ERROR, "cannot write: %s", last_write_error_.c_str());
  } else {
    status.summaryf(DiagnosticStatus::OK, "writing %s/*%s.csv", output_dir_abs_.c_str(),
                    suffixFor(current_set_->index).c_str());
  }
  window_write_errors_ = 0;
}

}  // namespace exocet_mosaic
