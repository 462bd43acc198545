// self_calibrate: the camera's intrinsics from a dive's images alone, without a calibration pattern (2D3 section 3.3):
// KLT tracks, fundamental matrices (8-point + RANSAC), planarity test (GRIC), Mendonca-Cipolla, extrinsics.
//   rosrun exocet_mosaic self_calibrate --bag B --image-topic T --output camera.yaml [options]
//   rosrun exocet_mosaic self_calibrate --images DIR --output camera.yaml [options]
// Exit status: 0 calibrated, 2 bad input (the message names it), 3 calibration impossible (flat seabed, too few
// tracks, motion that does not constrain the intrinsics), 1 unexpected error.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <limits>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <cv_bridge/cv_bridge.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/CompressedImage.h>
#include <sensor_msgs/Image.h>
#include <opencv2/imgcodecs.hpp>

#include "exocet_common/atomic_file.h"
#include "exocet_mosaic/registration/gray_converter.h"
#include "exocet_mosaic/selfcal/self_calibration.h"
#include "exocet_common/camera_model.h"
#include "exocet_common/command_line.h"

namespace {

using namespace exocet_mosaic;

const char kDescription[] =
    "self_calibrate: estimates alpha_u, alpha_v, u0, v0 (no skew, no distortion) from a sequence of seabed images\n"
    "without a calibration pattern: the camera must move over relief, turning about its optical axis and\n"
    "rolling/pitching. Give either --bag with --image-topic, or --images.";

struct Options {
  std::string bag, topic, images_dir, output, camera_name = "self_calibrated";
  int step = 10, max_frames = 300, start_frame = 0;
  double initial_hfov_deg = 60.0;
  bool planar = false;
  uint64_t seed = 1;
};

/// A bad command line or unreadable input: exit code 2.
struct BadInput : std::invalid_argument {
  using std::invalid_argument::invalid_argument;
};

/// Declares the options into `o`; parseCommandLine() fills them.
void addOptions(CLI::App& app, Options* o) {
  app.add_option("--bag", o->bag,
                 "a bag with sensor_msgs/Image (mono8, mono16, bgr8, rgb8, bayer...) or\n"
                 "sensor_msgs/CompressedImage (JPEG, PNG) messages")
      ->check(CLI::ExistingFile);
  app.add_option("--image-topic", o->topic, "the bag's image topic, e.g. /camera/image_raw/compressed")
      ->type_name("TOPIC");
  app.add_option("--images", o->images_dir, "image files (png, jpg, tif, bmp, pgm, ppm), taken in name order")
      ->check(CLI::ExistingDirectory);
  app.add_option("--output", o->output,
                 "camera_calibration_parsers YAML, with the 1-sigma of each parameter under\n'self_calibration'")
      ->type_name("FILE")
      ->required();
  app.add_option("--step", o->step, "key frame every N frames: key frames must overlap but differ by a visible motion")
      ->type_name("N")
      ->check(exocet_common::atLeast(1))
      ->capture_default_str();
  app.add_option("--max-frames", o->max_frames, "frames read, at least 2")
      ->type_name("N")
      ->check(exocet_common::atLeast(2))
      ->capture_default_str();
  app.add_option("--start-frame", o->start_frame, "frames skipped first")
      ->type_name("N")
      ->check(exocet_common::atLeast(0))
      ->capture_default_str();
  app.add_option("--initial-hfov-deg", o->initial_hfov_deg,
                 "nominal horizontal field of view of the initial guess (degrees), in (1, 179)")
      ->type_name("D")
      ->check(exocet_common::numberIn(1.0, true, 179.0, true))
      ->capture_default_str();
  app.add_flag("--planar", o->planar,
               "on a flat seabed, calibrate from the plane's homographies (needs roll and pitch)");
  app.add_option("--seed", o->seed, "RANSAC's random seed")
      ->type_name("S")
      ->check(CLI::Range(0, std::numeric_limits<int>::max()))
      ->capture_default_str();
  app.add_option("--camera-name", o->camera_name, "camera_name in the YAML")->type_name("NAME")->capture_default_str();
  app.footer("Exit status: 0 calibrated, 2 bad input, 3 calibration impossible (the message says why and what to do).");
}

/// What the options cannot say alone: which input, and the topic that goes with a bag.
void checkInputs(const Options& o) {
  if (o.bag.empty() == o.images_dir.empty()) throw BadInput("give either --bag (with --image-topic) or --images");
  if (!o.bag.empty() && o.topic.empty()) throw BadInput("--bag needs --image-topic");
}

/// 8-bit grey from a decoded image file or compressed message, by its pixel type.
cv::Mat grayFromDecoded(const cv::Mat& image, registration::GrayConverter* converter, const std::string& what) {
  switch (image.type()) {
    case CV_8UC1:
      return image;
    case CV_8UC3:
      return converter->convert(image, "bgr8");  // imdecode's order
    case CV_8UC4:
      return converter->convert(image, "bgra8");
    case CV_16UC1:
      return converter->convert(image, "mono16");
    default:
      throw BadInput(what + " has an unsupported pixel type (8-bit grey/BGR/BGRA or 16-bit grey)");
  }
}

/// Feeds the frames of a folder of images to `sink`; returns the number read.
int readImages(const Options& o, const std::function<void(const cv::Mat&)>& sink) {
  namespace fs = std::filesystem;
  if (!fs::is_directory(o.images_dir)) throw BadInput("--images '" + o.images_dir + "' is not a folder");
  const std::set<std::string> extensions = {".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".pgm", ".ppm"};
  std::vector<std::string> files;
  for (const fs::directory_entry& e : fs::directory_iterator(o.images_dir)) {
    std::string ext = e.path().extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
    if (e.is_regular_file() && extensions.count(ext)) files.push_back(e.path().string());
  }
  std::sort(files.begin(), files.end());
  if (files.empty())
    throw BadInput("--images '" + o.images_dir + "' holds no image files (png, jpg, tif, bmp, pgm, ppm)");
  registration::GrayConverter converter;
  int read = 0;
  for (size_t i = o.start_frame; i < files.size() && read < o.max_frames; ++i) {
    const cv::Mat image = cv::imread(files[i], cv::IMREAD_UNCHANGED);
    if (image.empty()) throw BadInput("cannot read image '" + files[i] + "'");
    sink(grayFromDecoded(image, &converter, "image '" + files[i] + "'"));
    ++read;
  }
  return read;
}

/// Feeds the frames of a bag topic (raw or compressed images) to `sink`; returns the number read.
int readBag(const Options& o, const std::function<void(const cv::Mat&)>& sink) {
  rosbag::Bag bag;
  try {
    bag.open(o.bag, rosbag::bagmode::Read);
  } catch (const rosbag::BagException& e) {
    throw BadInput("cannot open bag '" + o.bag + "': " + e.what());
  }
  rosbag::View view(bag, rosbag::TopicQuery(o.topic));
  if (view.size() == 0) {
    std::string topics;
    rosbag::View all(bag);
    for (const rosbag::ConnectionInfo* c : all.getConnections())
      if (c->datatype == "sensor_msgs/Image" || c->datatype == "sensor_msgs/CompressedImage")
        topics += (topics.empty() ? "" : ", ") + c->topic + " (" + c->datatype + ")";
    throw BadInput("topic '" + o.topic + "' has no messages in bag '" + o.bag +
                   "'; its image topics: " + (topics.empty() ? "none" : topics));
  }
  registration::GrayConverter converter;
  int index = 0, read = 0;
  for (const rosbag::MessageInstance& m : view) {
    if (read >= o.max_frames) break;
    if (index++ < o.start_frame) continue;
    cv::Mat gray;
    if (const auto compressed = m.instantiate<sensor_msgs::CompressedImage>()) {
      cv::Mat decoded;
      try {
        decoded = cv::imdecode(compressed->data, cv::IMREAD_UNCHANGED);
      } catch (const cv::Exception&) {
        decoded.release();
      }
      if (decoded.empty())
        throw BadInput("message " + std::to_string(index - 1) + " of '" + o.topic + "': compressed image (format '" +
                       compressed->format + "') cannot be decoded");
      // A Bayer image compressed losslessly decodes to one channel and must be demosaiced as such.
      std::string encoding = compressed->format.substr(0, compressed->format.find(';'));
      encoding.erase(std::remove(encoding.begin(), encoding.end(), ' '), encoding.end());
      if (encoding.rfind("bayer_", 0) == 0 && decoded.channels() == 1)
        gray = converter.convert(decoded, encoding);
      else
        gray = grayFromDecoded(decoded, &converter, "message " + std::to_string(index - 1) + " of '" + o.topic + "'");
    } else if (const auto raw = m.instantiate<sensor_msgs::Image>()) {
      if (!registration::GrayConverter::supports(raw->encoding))
        throw BadInput("topic '" + o.topic + "' has encoding '" + raw->encoding +
                       "'; supported: " + registration::GrayConverter::supportedList());
      cv_bridge::CvImageConstPtr image;
      try {
        image = cv_bridge::toCvShare(raw);
      } catch (const std::exception& e) {
        throw BadInput("topic '" + o.topic + "': image with encoding '" + raw->encoding +
                       "' cannot be read: " + e.what());
      }
      gray = converter.convert(image->image, raw->encoding);
    } else {
      throw BadInput("topic '" + o.topic + "' carries " + m.getDataType() +
                     ", not sensor_msgs/Image or sensor_msgs/CompressedImage");
    }
    sink(gray);
    ++read;
  }
  return read;
}

void writeCalibration(const Options& o, const selfcal::SelfCalibrationResult& result) {
  exocet_common::CameraModel camera;
  camera.width = result.image_size.width;
  camera.height = result.image_size.height;
  camera.fx = result.intrinsics.value.alpha_u;
  camera.fy = result.intrinsics.value.alpha_v;
  camera.cx = result.intrinsics.value.u0;
  camera.cy = result.intrinsics.value.v0;
  // The standard file first (through the project's writer), then our keys appended, then one atomic rename.
  const std::string temporary = exocet_common::temporaryPathFor(o.output) + ".base";
  exocet_common::saveCameraModelYaml(temporary, camera, o.camera_name);
  std::ifstream in(temporary);
  std::stringstream text;
  text << in.rdbuf();
  in.close();
  std::error_code ignored;
  std::filesystem::remove(temporary, ignored);
  exocet_common::writeFileAtomically(o.output, text.str() + selfcal::selfCalibrationYamlBlock(result));
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  CLI::App app(kDescription, "self_calibrate");
  addOptions(app, &o);
  if (const auto exit_status = exocet_common::parseCommandLine(app, argc, argv)) return *exit_status;
  try {
    checkInputs(o);
    const std::string destination_problem = exocet_common::checkWritableDestination(o.output);
    if (!destination_problem.empty()) throw BadInput("--output: " + destination_problem);

    selfcal::SelfCalibrationConfig config;
    config.fundamental.seed = o.seed;
    config.intrinsics.initial_hfov_deg = o.initial_hfov_deg;
    config.planar_intrinsics.initial_hfov_deg = o.initial_hfov_deg;
    config.allow_planar = o.planar;
    selfcal::TrackerConfig tracking;
    tracking.step = o.step;
    selfcal::FeatureTrackBuilder tracks(tracking);
    auto sink = [&](const cv::Mat& gray) {
      try {
        tracks.addFrame(gray);
      } catch (const std::invalid_argument& e) {
        throw BadInput(e.what());
      }
    };
    const int frames = o.bag.empty() ? readImages(o, sink) : readBag(o, sink);
    const std::vector<selfcal::KeyFramePair> pairs = tracks.keyFramePairs();
    std::cout << "Read " << frames << " frames (" << tracks.imageSize().width << "x" << tracks.imageSize().height
              << "), " << tracks.keyFrameCount() << " key frames every " << o.step << ", " << tracks.tracksStarted()
              << " tracks, " << pairs.size() << " key-frame pairs sharing at least " << tracking.min_shared_tracks
              << " tracks\n";
    if (tracks.keyFrameCount() < config.min_key_frames)
      throw selfcal::CalibrationImpossible(selfcal::CalibrationImpossible::Reason::kTooFewTracks,
                                           "too few key frames: " + std::to_string(tracks.keyFrameCount()) + " from " +
                                               std::to_string(frames) + " frames at --step " + std::to_string(o.step) +
                                               ", at least " + std::to_string(config.min_key_frames) +
                                               " needed; read more frames (--max-frames) or use a smaller --step");
    const selfcal::SelfCalibrationResult result = selfcal::selfCalibrate(pairs, tracks.imageSize(), config);
    std::cout << selfcal::summaryText(result);
    writeCalibration(o, result);
    std::cout << "Wrote " << o.output << " (distortion not estimated: written as zero)\n";
    return 0;
  } catch (const BadInput& e) {
    std::cerr << "self_calibrate: " << e.what() << "\nRun 'self_calibrate --help' for the options.\n";
    return exocet_common::kExitBadInput;
  } catch (const std::invalid_argument& e) {  // an image the converter refuses, a bad setting
    std::cerr << "self_calibrate: " << e.what() << "\n";
    return exocet_common::kExitBadInput;
  } catch (const selfcal::CalibrationImpossible& e) {
    std::cerr << "self_calibrate: calibration impossible: " << e.what() << "\n";
    return 3;
  } catch (const std::exception& e) {
    std::cerr << "self_calibrate: " << e.what() << "\n";
    return 1;
  }
}
