// Tests of dive_import: the real Sparus II AUV data imported through the library and the tool and read back from
// the bag, the CSV and frame conventions, and every bad input (clear message, exit code, no output).

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include <sys/wait.h>

#include <cv_bridge/cv_bridge.h>
#include <exocet_msgs/Depth.h>
#include <exocet_msgs/GeoDatum.h>
#include <gtest/gtest.h>
#include <nav_msgs/Odometry.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/Range.h>
#include <tf2_msgs/TFMessage.h>
#include <yaml-cpp/yaml.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "exocet_common/json_file.h"
#include "exocet_common/testing/temp_dir.h"
#include "exocet_mosaic/ros/dive_bag_writer.h"
#include "exocet_mosaic/ros/dive_topics.h"
#include "exocet_mosaic/dive/dive_import.h"
#include "exocet_common/geo_reference.h"
#include "exocet_common/testing/paths.h"

namespace fs = std::filesystem;
using exocet_mosaic::DiveBagWriter;
namespace dive = exocet_mosaic::dive;
namespace topics = exocet_mosaic::topics;

namespace {

const std::string kSparus = exocet_common::testing::sharedDataDir() + "/sparus_auv";
const std::string kTool = exocet_common::testing::executableDir() + "/dive_import";
constexpr int kSparusFrames = 22;
constexpr int kSparusNavRows = 50;

/// A fresh folder under the system's temporary folder, removed with everything in it.
using TempDir = exocet_common::testing::TempDir;

void writeText(const std::string& path, const std::string& text) {
  std::ofstream out(path);
  out << text;
  ASSERT_TRUE(out.good()) << path;
}

std::vector<std::string> readLines(const std::string& path) {
  std::ifstream in(path);
  std::vector<std::string> lines;
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

std::string readText(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

/// A simple CSV (no quotes) as rows of name -> value, for the expected values.
std::vector<std::map<std::string, std::string>> readCsvRows(const std::string& path) {
  const std::vector<std::string> lines = readLines(path);
  std::vector<std::map<std::string, std::string>> rows;
  const auto split = [](const std::string& line) {
    std::vector<std::string> fields;
    std::stringstream s(line);
    for (std::string f; std::getline(s, f, ',');) fields.push_back(f);
    return fields;
  };
  const std::vector<std::string> header = split(lines.at(0));
  for (size_t i = 1; i < lines.size(); ++i) {
    const std::vector<std::string> fields = split(lines[i]);
    std::map<std::string, std::string> row;
    for (size_t k = 0; k < header.size() && k < fields.size(); ++k) row[header[k]] = fields[k];
    rows.push_back(row);
  }
  return rows;
}

struct RunResult {
  int exit_code = -1;
  std::string out, err;
};

/// Runs the built tool with `args`, capturing its exit code, stdout and stderr.
RunResult runTool(const std::vector<std::string>& args, const TempDir& scratch) {
  std::string command = "'" + kTool + "'";
  for (const auto& a : args) command += " '" + a + "'";
  const std::string out_path = scratch / "tool.stdout", err_path = scratch / "tool.stderr";
  command += " >'" + out_path + "' 2>'" + err_path + "'";
  const int status = std::system(command.c_str());
  RunResult r;
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  r.out = readText(out_path);
  r.err = readText(err_path);
  std::remove(out_path.c_str());
  std::remove(err_path.c_str());
  return r;
}

std::vector<std::string> sparusArgs(const std::string& output) {
  return {"--images",      kSparus + "/frames",
          "--image-times", kSparus + "/frames_index.csv",
          "--nav",         kSparus + "/sparus_snippet.csv",
          "--camera",      kSparus + "/camera_intrinsics.yaml",
          "--output",      output};
}

/// Everything of interest in a dive bag.
struct BagContents {
  std::vector<sensor_msgs::Image> images;
  std::vector<sensor_msgs::CameraInfo> infos;
  std::vector<nav_msgs::Odometry> odometry;
  std::vector<exocet_msgs::Depth> depths;
  std::vector<exocet_msgs::GeoDatum> datums;
  std::vector<tf2_msgs::TFMessage> tf_static;
  std::vector<sensor_msgs::Range> altitudes;
  std::vector<std::string> topics;     ///< every connection's topic
  std::vector<double> record_times_s;  ///< in file order
};

/// Appends the message `m` as a T to `out`; a message that does not instantiate as T is a failure, not a crash.
template <typename T>
void take(const rosbag::MessageInstance& m, std::vector<T>* out) {
  const auto msg = m.instantiate<T>();
  if (msg) {
    out->push_back(*msg);
  } else {
    ADD_FAILURE() << m.getTopic() << ": recorded as '" << m.getDataType() << "', not readable as "
                  << ros::message_traits::datatype<T>();
  }
}

BagContents readBag(const std::string& path) {
  BagContents c;
  rosbag::Bag bag(path, rosbag::bagmode::Read);
  rosbag::View view(bag);
  // Readers (rosbag info, rosbag play, the Python API) need each connection's type, md5sum and definition.
  for (const rosbag::ConnectionInfo* connection : view.getConnections()) {
    EXPECT_FALSE(connection->datatype.empty()) << connection->topic << ": connection record has no type";
    EXPECT_FALSE(connection->md5sum.empty()) << connection->topic << ": connection record has no md5sum";
    EXPECT_FALSE(connection->msg_def.empty()) << connection->topic << ": connection record has no definition";
    c.topics.push_back(connection->topic);
  }
  for (const rosbag::MessageInstance& m : view) {
    c.record_times_s.push_back(m.getTime().toSec());
    const std::string& topic = m.getTopic();
    if (topic == topics::kImageRaw) take(m, &c.images);
    if (topic == topics::kCameraInfo) take(m, &c.infos);
    if (topic == topics::kNavOdometry) take(m, &c.odometry);
    if (topic == topics::kNavDepth) take(m, &c.depths);
    if (topic == topics::kNavDatum) take(m, &c.datums);
    if (topic == topics::kTfStatic) take(m, &c.tf_static);
    if (topic == topics::kNavAltitude) take(m, &c.altitudes);
  }
  return c;
}

/// The checks of the Sparus round trip: images, stamps, intrinsics, navigation, depth and frames.
void expectSparusBag(const std::string& path) {
  const BagContents bag = readBag(path);
  const auto index = readCsvRows(kSparus + "/frames_index.csv");
  ASSERT_EQ(index.size(), static_cast<size_t>(kSparusFrames));
  ASSERT_EQ(bag.images.size(), static_cast<size_t>(kSparusFrames));
  ASSERT_EQ(bag.infos.size(), static_cast<size_t>(kSparusFrames));
  for (int k = 0; k < kSparusFrames; ++k) {
    const sensor_msgs::Image& msg = bag.images[k];
    EXPECT_EQ(msg.encoding, "bgr8");
    EXPECT_EQ(msg.header.frame_id, exocet_mosaic::frames::kCameraOptical);
    EXPECT_NEAR(msg.header.stamp.toSec(), std::stod(index[k].at("t_unix_s")), 1e-6) << "frame " << k;
    const cv::Mat expected = cv::imread(kSparus + "/" + index[k].at("file"), cv::IMREAD_COLOR);
    ASSERT_FALSE(expected.empty());
    const cv::Mat decoded = cv_bridge::toCvCopy(msg, "bgr8")->image;
    ASSERT_EQ(decoded.size(), expected.size());
    EXPECT_EQ(cv::norm(decoded, expected, cv::NORM_INF), 0.0) << "frame " << k << " differs from its PNG";
    EXPECT_EQ(bag.infos[k].header.stamp, msg.header.stamp);
  }
  // camera_info equals the YAML, read here independently of the importer.
  const YAML::Node yaml = YAML::LoadFile(kSparus + "/camera_intrinsics.yaml");
  const auto K = yaml["K"].as<std::vector<double>>();
  const auto D = yaml["D"].as<std::vector<double>>();
  for (const auto& info : bag.infos) {
    EXPECT_EQ(info.width, yaml["image_width"].as<unsigned>());
    EXPECT_EQ(info.height, yaml["image_height"].as<unsigned>());
    for (int i = 0; i < 9; ++i) EXPECT_EQ(info.K[i], K[i]) << "K[" << i << "]";
    ASSERT_EQ(info.D.size(), D.size());
    for (size_t i = 0; i < D.size(); ++i) EXPECT_EQ(info.D[i], D[i]) << "D[" << i << "]";
  }
  // One odometry per CSV row, equal to it; no lat/lon and no origin: the local "map" frame.
  const auto nav = readCsvRows(kSparus + "/sparus_snippet.csv");
  ASSERT_EQ(nav.size(), static_cast<size_t>(kSparusNavRows));
  ASSERT_EQ(bag.odometry.size(), nav.size());
  ASSERT_EQ(bag.depths.size(), nav.size());
  for (size_t i = 0; i < nav.size(); ++i) {
    const nav_msgs::Odometry& o = bag.odometry[i];
    EXPECT_EQ(o.header.frame_id, "map");
    EXPECT_EQ(o.child_frame_id, "base_link");
    EXPECT_NEAR(o.header.stamp.toSec(), std::stod(nav[i].at("ts")), 1e-6);
    EXPECT_NEAR(o.pose.pose.position.x, std::stod(nav[i].at("x")), 1e-9);
    EXPECT_NEAR(o.pose.pose.position.y, std::stod(nav[i].at("y")), 1e-9);
    EXPECT_NEAR(o.pose.pose.position.z, std::stod(nav[i].at("z")), 1e-9);
    EXPECT_NEAR(o.pose.pose.orientation.x, std::stod(nav[i].at("qx")), 1e-9);
    EXPECT_NEAR(o.pose.pose.orientation.y, std::stod(nav[i].at("qy")), 1e-9);
    EXPECT_NEAR(o.pose.pose.orientation.z, std::stod(nav[i].at("qz")), 1e-9);
    EXPECT_NEAR(o.pose.pose.orientation.w, std::stod(nav[i].at("qw")), 1e-9);
    EXPECT_NEAR(bag.depths[i].depth_m, -std::stod(nav[i].at("z")), 1e-9);  // no depth column: depth = -z
  }
  EXPECT_TRUE(bag.datums.empty());
  ASSERT_EQ(bag.tf_static.size(), 1u);
  ASSERT_EQ(bag.tf_static[0].transforms.size(), 1u);
  const auto& tf = bag.tf_static[0].transforms[0];
  EXPECT_EQ(tf.header.frame_id, "base_link");
  EXPECT_EQ(tf.child_frame_id, "camera_optical");
  EXPECT_EQ(tf.transform.translation.x, 0.0);
  EXPECT_EQ(tf.transform.rotation.w, 1.0);
  // Written in time order, so that the bag plays back without seeking.
  for (size_t i = 1; i < bag.record_times_s.size(); ++i) EXPECT_LE(bag.record_times_s[i - 1], bag.record_times_s[i]);
}

/// Records what writeDiveImport writes, for tests that need no bag.
class RecordingSink : public dive::DiveRecordSink {
 public:
  void writeDatum(const exocet_common::GeoReference& d, double) override { datum = d; }
  void writeStaticTransforms(const std::vector<dive::StaticTransform>& t, double) override { transforms = t; }
  void writeCameraFrame(const dive::CameraFrame& f, const exocet_common::CameraModel&) override {
    frames.push_back(f);
    stamps_s.push_back(f.stamp_s);
  }
  void writeNavOdometry(const dive::PoseRecord& p) override {
    poses.push_back(p);
    stamps_s.push_back(p.stamp_s);
  }
  void writeDepth(const dive::DepthRecord& d) override { depths.push_back(d); }
  void writeAltitude(const dive::AltitudeRecord& a) override { altitudes.push_back(a); }

  std::optional<exocet_common::GeoReference> datum;
  std::vector<dive::StaticTransform> transforms;
  std::vector<dive::CameraFrame> frames;
  std::vector<dive::PoseRecord> poses;
  std::vector<dive::DepthRecord> depths;
  std::vector<dive::AltitudeRecord> altitudes;
  std::vector<double> stamps_s;
};

/// Three 384x288 noise images (the Sparus camera's size) named img_0.png.. in `folder`.
void writeNoiseImages(const std::string& folder, int count = 3) {
  fs::create_directories(folder);
  for (int k = 0; k < count; ++k) {
    cv::Mat image(288, 384, CV_8UC3);
    cv::randu(image, cv::Scalar::all(0), cv::Scalar::all(255));
    ASSERT_TRUE(cv::imwrite(folder + "/img_" + std::to_string(k) + ".png", image));
  }
}

/// Expects `action` to throw a DiveImportError of `kind` whose message contains every one of `parts`.
template <typename F>
void expectImportError(F action, dive::DiveImportError::Kind kind, const std::vector<std::string>& parts) {
  try {
    action();
    ADD_FAILURE() << "no error; expected one mentioning " << parts.front();
  } catch (const dive::DiveImportError& e) {
    EXPECT_EQ(e.kind(), kind) << e.what();
    for (const auto& p : parts) EXPECT_NE(std::string(e.what()).find(p), std::string::npos) << e.what();
  }
}

std::vector<std::string> replaceArg(std::vector<std::string> args, const std::string& option,
                                    const std::string& value) {
  for (size_t i = 0; i + 1 < args.size(); ++i)
    if (args[i] == option) args[i + 1] = value;
  return args;
}

dive::DiveImport prepare(const std::vector<std::string>& args) {
  return dive::prepareDiveImport(dive::parseDiveImportArguments(args));
}

// ------------------------------------------------------------------------------------------------------------

TEST(DiveImportSparus, LibraryRoundTripIsExact) {
  TempDir dir;
  const std::string output = dir / "sparus.bag";
  const dive::DiveImport dive = prepare(sparusArgs(output));
  EXPECT_EQ(dive.navigation.world_frame, "map");
  EXPECT_EQ(dive.navigation.time_column, "ts");
  EXPECT_EQ(dive.navigation.orientation_columns, "qx,qy,qz,qw");
  EXPECT_EQ(dive.navigation.ignored_columns, (std::vector<std::string>{"source", "target"}));
  DiveBagWriter::Options options;
  options.world_frame = dive.navigation.world_frame;
  dive::DiveImportSummary summary;
  {
    DiveBagWriter writer(output, options);
    dive::DiveRecordSinkFor<DiveBagWriter> sink(&writer);
    summary = dive::writeDiveImport(dive, &sink);
    writer.commit();
  }
  EXPECT_EQ(summary.frames, kSparusFrames);
  EXPECT_EQ(summary.nav_rows, kSparusNavRows);
  EXPECT_EQ(summary.frames_before_nav, 1);  // frame 0 is 16 ms before the first navigation row
  EXPECT_EQ(dir.files(), std::vector<std::string>{"sparus.bag"});
  expectSparusBag(output);
}

TEST(DiveImportSparus, ToolRoundTripIsExact) {
  TempDir dir;
  const std::string output = dir / "sparus_tool.bag";
  const RunResult run = runTool(sparusArgs(output), dir);
  ASSERT_EQ(run.exit_code, 0) << run.err;
  EXPECT_NE(run.out.find("22 frames, 50 nav rows"), std::string::npos) << run.out;
  EXPECT_NE(run.out.find(output), std::string::npos) << run.out;
  EXPECT_NE(run.err.find("1 frame(s) before the first navigation row"), std::string::npos) << run.err;
  EXPECT_NE(run.out.find("rosrun exocet_mosaic replay_dive " + output + " " + (dir / "sparus_tool_tiles") +
                         " ground_truth:=false\n"),
            std::string::npos)
      << run.out;
  EXPECT_NE(run.out.find("camera_height_m:="), std::string::npos) << "no altitude: the output says what to give";
  EXPECT_EQ(dir.files(), (std::vector<std::string>{"sparus_tool.bag", "sparus_tool.bag.replay.json"}));
  expectSparusBag(output);
}

TEST(DiveImportSparus, VideoTimedByStartAndContainerFps) {
  TempDir dir;
  const std::string output = dir / "video.bag";
  const double start_s = 1372687208.617628827;
  const RunResult run =
      runTool({"--images", kSparus + "/sparus_snippet.mp4", "--start-time", "1372687208.617628827", "--nav",
               kSparus + "/sparus_snippet.csv", "--camera", kSparus + "/camera_intrinsics.yaml", "--output", output},
              dir);
  ASSERT_EQ(run.exit_code, 0) << run.err;
  const BagContents bag = readBag(output);
  ASSERT_EQ(bag.images.size(), static_cast<size_t>(kSparusFrames));
  // The container says 4.998803534754 fps (SOURCE.txt rounds it to 4.9988): consecutive frames are 1/4.9988 s
  // apart to within 1 us, and frame k is at start + k / container fps. frames_index.csv was made with the rounded
  // 4.9988, so it drifts from the container's timing by up to 3 us at frame 21.
  const double fps = dive::listImages(kSparus + "/sparus_snippet.mp4").container_fps;
  EXPECT_NEAR(fps, 4.9988, 1e-4);
  const auto index = readCsvRows(kSparus + "/frames_index.csv");
  for (int k = 0; k < kSparusFrames; ++k) {
    const double stamp_s = bag.images[k].header.stamp.toSec();
    EXPECT_NEAR(stamp_s - start_s, k / fps, 1e-6) << "frame " << k;
    EXPECT_NEAR(stamp_s, std::stod(index[k].at("t_unix_s")), 5e-6) << "frame " << k;
    if (k > 0) {
      EXPECT_NEAR(stamp_s - bag.images[k - 1].header.stamp.toSec(), 1 / 4.9988, 1e-6) << "frame " << k;
    }
    // Same decoder as the PNGs were made with (SOURCE.txt): the frames should be those PNGs, give or take a
    // decoder version.
    char name[64];
    std::snprintf(name, sizeof(name), "/frames/frame_%04d.png", k);
    const cv::Mat expected = cv::imread(kSparus + name, cv::IMREAD_COLOR);
    const cv::Mat decoded = cv_bridge::toCvCopy(bag.images[k], "bgr8")->image;
    EXPECT_LT(cv::norm(decoded, expected, cv::NORM_L1) / expected.total() / 3.0, 1.0) << "frame " << k;
  }
  EXPECT_EQ(bag.odometry.size(), static_cast<size_t>(kSparusNavRows));
}

TEST(DiveImportSparus, Mono8AndCameraPose) {
  TempDir dir;
  std::vector<std::string> args = sparusArgs(dir / "unused.bag");
  args.insert(args.end(), {"--encoding", "mono8", "--camera-pose", "0.1,-0.2,0.3,180,0,-90"});
  const dive::DiveImport dive = prepare(args);
  RecordingSink sink;
  dive::writeDiveImport(dive, &sink);
  ASSERT_EQ(sink.frames.size(), static_cast<size_t>(kSparusFrames));
  cv::Mat gray;
  cv::cvtColor(cv::imread(kSparus + "/frames/frame_0005.png", cv::IMREAD_COLOR), gray, cv::COLOR_BGR2GRAY);
  EXPECT_EQ(sink.frames[5].encoding, "mono8");
  ASSERT_EQ(sink.frames[5].image.type(), CV_8UC1);
  EXPECT_EQ(cv::norm(sink.frames[5].image, gray, cv::NORM_INF), 0.0);
  ASSERT_EQ(sink.transforms.size(), 1u);
  const Eigen::Isometry3d& pose = sink.transforms[0].parent_from_child;
  EXPECT_TRUE(pose.translation().isApprox(Eigen::Vector3d(0.1, -0.2, 0.3)));
  // Optical z looks down, optical -y (image top) points forward, optical x (image right) points right.
  EXPECT_TRUE(pose.linear().col(2).isApprox(Eigen::Vector3d(0, 0, -1), 1e-12));
  EXPECT_TRUE(pose.linear().col(1).isApprox(Eigen::Vector3d(-1, 0, 0), 1e-12));
  EXPECT_TRUE(pose.linear().col(0).isApprox(Eigen::Vector3d(0, -1, 0), 1e-12));
  for (size_t i = 1; i < sink.stamps_s.size(); ++i) EXPECT_LE(sink.stamps_s[i - 1], sink.stamps_s[i]);
}

// ------------------------------------------------------------------------------------------------------------
// Navigation and frame-time conventions

TEST(DiveImportNavigation, GeodeticRowsGiveUtmWithGridHeading) {
  TempDir dir;
  // Zone 31 (central meridian 3 E): the first row is on it, the second 2 degrees east at 45 N.
  writeText(dir / "nav.csv",
            "# a comment line\n"
            "time,lat,lon,depth,heading_deg,pitch_deg,roll_deg,altitude\n"
            "1000.0,45.0,3.0,12.5,90,0,0,3.5\n"
            "1000.5,45.0,5.0,13.0,0,0,0,\n"
            "1001.0,45.0,3.0,13.0,90,10,0,4\n"
            "1001.5,45.0,3.0,13.0,90,0,10,4\n");
  const dive::NavigationTable nav = dive::readNavigationCsv(dir / "nav.csv", std::nullopt);
  ASSERT_EQ(nav.world_frame, "utm");
  ASSERT_TRUE(nav.datum);
  EXPECT_EQ(nav.datum->utm_zone, 31);
  EXPECT_EQ(nav.datum->epsg, 32631);
  EXPECT_EQ(nav.position_columns, "lat,lon,depth");
  ASSERT_EQ(nav.rows.size(), 4u);
  EXPECT_EQ(nav.rows[0].line, 3);
  const Eigen::Vector2d grid = exocet_common::latLonToGrid(*nav.datum, 45.0, 5.0);
  EXPECT_NEAR(nav.rows[1].pose.position_m.x(), grid.x(), 1e-6);
  EXPECT_NEAR(nav.rows[1].pose.position_m.y(), grid.y(), 1e-6);
  EXPECT_NEAR(nav.rows[1].pose.position_m.z(), -13.0, 1e-12);
  EXPECT_NEAR(nav.rows[0].depth->depth_m, 12.5, 1e-12);
  // Heading 90 (east) on the central meridian: yaw 0, the identity.
  EXPECT_NEAR(nav.rows[0].pose.orientation.angularDistance(Eigen::Quaterniond::Identity()), 0.0, 1e-9);
  // Heading 0 (true north) east of the central meridian: true north points west of grid north by the
  // convergence, about atan(tan(2 deg) sin(45 deg)) = 1.41 deg.
  const Eigen::Vector3d forward = nav.rows[1].pose.orientation * Eigen::Vector3d::UnitX();
  EXPECT_NEAR(std::atan2(forward.x(), forward.y()) * 180.0 / M_PI, -1.4147, 0.02);
  // Pitch 10 deg nose up (NED convention) while heading east: forward rises.
  const Eigen::Vector3d nose_up = nav.rows[2].pose.orientation * Eigen::Vector3d::UnitX();
  EXPECT_TRUE(nose_up.isApprox(Eigen::Vector3d(std::cos(10 * M_PI / 180), 0, std::sin(10 * M_PI / 180)), 1e-9));
  // Roll 10 deg starboard down while heading east: the left side (north) rises.
  const Eigen::Vector3d left = nav.rows[3].pose.orientation * Eigen::Vector3d::UnitY();
  EXPECT_TRUE(left.isApprox(Eigen::Vector3d(0, std::cos(10 * M_PI / 180), std::sin(10 * M_PI / 180)), 1e-9));
  // The empty altitude cell is no measurement.
  EXPECT_TRUE(nav.rows[0].altitude && !nav.rows[1].altitude && nav.rows[2].altitude);
  EXPECT_NEAR(nav.rows[0].altitude->range_m, 3.5, 1e-12);
}

TEST(DiveImportNavigation, LocalOffsetsWithOriginAndYaw) {
  TempDir dir;
  writeText(dir / "nav.csv", "t_unix_s,x,y,z,yaw_deg,altitude\n10,1.5,-2.0,-20,30,2\n11,2.5,-2.0,-20,30,60\n");
  dive::GeoOrigin origin;
  origin.latitude_deg = 42.0;
  origin.longitude_deg = 3.1;
  const dive::NavigationTable nav = dive::readNavigationCsv(dir / "nav.csv", origin);
  ASSERT_EQ(nav.world_frame, "utm");
  const exocet_common::GeoReference ref = exocet_common::makeGeoReference(42.0, 3.1);
  EXPECT_NEAR(nav.rows[0].pose.position_m.x(), ref.origin_easting_m + 1.5, 1e-6);
  EXPECT_NEAR(nav.rows[0].pose.position_m.y(), ref.origin_northing_m - 2.0, 1e-6);
  EXPECT_NEAR(nav.rows[0].depth->depth_m, 20.0, 1e-12);
  const Eigen::Quaterniond yaw30(Eigen::AngleAxisd(30 * M_PI / 180, Eigen::Vector3d::UnitZ()));
  EXPECT_NEAR(nav.rows[0].pose.orientation.angularDistance(yaw30), 0.0, 1e-12);
  // Every altitude lies inside the Range message's span.
  EXPECT_GE(nav.rows[1].altitude->max_range_m, 60.0);
  // Without an origin, the same file is local.
  const dive::NavigationTable local = dive::readNavigationCsv(dir / "nav.csv", std::nullopt);
  EXPECT_EQ(local.world_frame, "map");
  EXPECT_FALSE(local.datum);
  EXPECT_EQ(local.rows[0].pose.position_m, Eigen::Vector3d(1.5, -2.0, -20));
}

TEST(DiveImportNavigation, WithoutOrientationMarksItUnknown) {
  TempDir dir;
  writeText(dir / "nav.csv", "stamp,x,y,depth\r\n1,0,0,5\r\n2,1,0,\"5.5\"\r\n");
  const dive::NavigationTable nav = dive::readNavigationCsv(dir / "nav.csv", std::nullopt);
  EXPECT_EQ(nav.orientation_columns, "none");
  ASSERT_EQ(nav.rows.size(), 2u);
  EXPECT_EQ(nav.rows[0].pose.pose_covariance(5, 5), -1.0);
  EXPECT_EQ(nav.rows[0].pose.twist_covariance(0, 0), -1.0);
  EXPECT_NEAR(nav.rows[1].pose.position_m.z(), -5.5, 1e-12);
}

TEST(DiveImportFrames, IndexByFrameNumberAndRate) {
  TempDir dir;
  writeNoiseImages(dir / "images");
  const dive::ImageSource images = dive::listImages(dir / "images");
  ASSERT_EQ(images.files.size(), 3u);
  writeText(dir / "index.csv", "frame,t\n0,100.0\n1,100.25\n2,100.5\n7,101\n");
  const dive::FrameTimes times = dive::frameTimesFromIndex(images, dir / "index.csv");
  EXPECT_EQ(times.stamps_s, (std::vector<double>{100.0, 100.25, 100.5}));
  EXPECT_EQ(times.unused_index_rows, 1);
  const dive::FrameTimes rate = dive::frameTimesFromRate(images, 50.0, 4.0);
  EXPECT_EQ(rate.stamps_s, (std::vector<double>{50.0, 50.25, 50.5}));
  // Frame times must increase.
  writeText(dir / "bad_index.csv", "file,t\nimg_0.png,100\nimg_1.png,99\nimg_2.png,101\n");
  expectImportError([&] { dive::frameTimesFromIndex(images, dir / "bad_index.csv"); },
                    dive::DiveImportError::Kind::kInput, {"line 3", "img_1.png", "must increase"});
  // Every image needs a time.
  writeText(dir / "short_index.csv", "file,t\nimg_0.png,100\nimg_2.png,101\n");
  expectImportError([&] { dive::frameTimesFromIndex(images, dir / "short_index.csv"); },
                    dive::DiveImportError::Kind::kInput, {"img_1.png", "has no row"});
  expectImportError([&] { dive::frameTimesFromRate(images, 50.0, 0.0); }, dive::DiveImportError::Kind::kInput, {"--fps"});
}

// ------------------------------------------------------------------------------------------------------------
// A dive without navigation: --altitude (constant or CSV), --heading, the start point and the replay's arguments.

/// Arguments of a dive without navigation: three noise images timed 100, 100.25, 100.5 s, the Sparus camera.
std::vector<std::string> noNavArgs(const TempDir& dir, const std::string& altitude) {
  return {"--images",     dir / "images",
          "--start-time", "100",
          "--fps",        "4",
          "--camera",     kSparus + "/camera_intrinsics.yaml",
          "--altitude",   altitude,
          "--output",     dir / "out.bag"};
}

TEST(DiveImportNoNav, AltitudeArgument) {
  const dive::AltitudeOption constant = dive::parseAltitudeOption("3");
  ASSERT_TRUE(constant.constant_m);
  EXPECT_EQ(*constant.constant_m, 3.0);
  EXPECT_TRUE(constant.csv_path.empty());
  EXPECT_EQ(*dive::parseAltitudeOption("1000").constant_m, 1000.0);
  EXPECT_EQ(*dive::parseAltitudeOption("0.05").constant_m, 0.05);
  const dive::AltitudeOption csv = dive::parseAltitudeOption("/data/dive 1/alt.csv");
  EXPECT_FALSE(csv.constant_m);
  EXPECT_EQ(csv.csv_path, "/data/dive 1/alt.csv");
  EXPECT_EQ(csv.csv_column, "");
  const dive::AltitudeOption named = dive::parseAltitudeOption("logs/ALT.CSV:height_m");
  EXPECT_EQ(named.csv_path, "logs/ALT.CSV");
  EXPECT_EQ(named.csv_column, "height_m");
  for (const std::string bad : {"0", "-2", "1000.5", "nan", "inf"})
    expectImportError([&] { dive::parseAltitudeOption(bad); }, dive::DiveImportError::Kind::kInput,
                      {"--altitude", "(0, 1000] m"});
  for (const std::string bad : {"3m", "alt.txt", "alt.csv:", ""})
    expectImportError([&] { dive::parseAltitudeOption(bad); }, dive::DiveImportError::Kind::kInput, {"--altitude"});
  expectImportError([&] { dive::parseAltitudeOption("3m"); }, dive::DiveImportError::Kind::kInput,
                    {"FILE.csv", "(0, 1000] m"});
}

TEST(DiveImportNoNav, CommandLine) {
  TempDir dir;
  const dive::DiveImportOptions o = dive::parseDiveImportArguments(noNavArgs(dir, "2.5"));
  EXPECT_TRUE(o.nav_path.empty());
  ASSERT_TRUE(o.altitude && o.altitude->constant_m);
  EXPECT_EQ(*o.altitude->constant_m, 2.5);
  EXPECT_FALSE(o.heading_deg);
  const auto with = [&](std::vector<std::string> extra) {
    std::vector<std::string> args = noNavArgs(dir, "2.5");
    args.insert(args.end(), extra.begin(), extra.end());
    return args;
  };
  const dive::DiveImportOptions start =
      dive::parseDiveImportArguments(with({"--origin-lat", "39.55", "--origin-lon", "2.62", "--heading=-360"}));
  ASSERT_TRUE(start.origin && start.heading_deg);
  EXPECT_EQ(start.origin->latitude_deg, 39.55);
  EXPECT_EQ(*start.heading_deg, -360.0);
  EXPECT_EQ(*dive::parseDiveImportArguments(with({"--heading", "360"})).heading_deg, 360.0);
  const auto expectUsage = [&](const std::vector<std::string>& args, const std::vector<std::string>& parts) {
    expectImportError([&] { dive::parseDiveImportArguments(args); }, dive::DiveImportError::Kind::kInput, parts);
  };
  expectUsage(with({"--heading", "360.5"}), {"--heading", "[-360, 360]"});
  expectUsage(with({"--heading", "north"}), {"--heading", "not a number"});
  expectUsage(replaceArg(noNavArgs(dir, "2.5"), "--altitude", "1001"), {"--altitude", "(0, 1000] m"});
  // Without --nav, --altitude is required; with --nav, --altitude and --heading conflict with the CSV.
  std::vector<std::string> no_altitude = noNavArgs(dir, "2.5");
  no_altitude.erase(no_altitude.begin() + 8, no_altitude.begin() + 10);
  expectUsage(no_altitude, {"--altitude is required without --nav", "(0, 1000]", "FILE.csv"});
  std::vector<std::string> nav = sparusArgs(dir / "out.bag");
  nav.insert(nav.end(), {"--altitude", "3"});
  expectUsage(nav, {"--altitude cannot be combined with --nav"});
  nav = sparusArgs(dir / "out.bag");
  nav.insert(nav.end(), {"--heading", "10"});
  expectUsage(nav, {"--heading cannot be combined with --nav"});
}

TEST(DiveImportNoNav, MissingCameraSaysHowToGetIt) {
  TempDir dir;
  writeNoiseImages(dir / "images");
  std::vector<std::string> args = noNavArgs(dir, "2.5");
  args.erase(args.begin() + 6, args.begin() + 8);  // --camera
  const std::vector<std::string> parts = {"--camera is required", "rosrun exocet_mosaic self_calibrate --images DIR",
                                          "--output camera.yaml", "--bag BAG",
                                          "rosrun exocet_mosaic mosaic_video VIDEO --altitude M --output DIR"};
  expectImportError([&] { dive::parseDiveImportArguments(args); }, dive::DiveImportError::Kind::kInput, parts);
  const RunResult run = runTool(args, dir);
  EXPECT_EQ(run.exit_code, 2);
  for (const auto& part : parts) EXPECT_NE(run.err.find(part), std::string::npos) << run.err;
  EXPECT_EQ(dir.files(), std::vector<std::string>{"images"});
}

TEST(DiveImportNoNav, AltitudeCsv) {
  TempDir dir;
  writeText(dir / "alt.csv", "# altimeter log\nstamp,source,height_m\n10,a,2\n11,b,\n12,c,4\n");
  const dive::AltitudeTable table = dive::readAltitudeCsv(dir / "alt.csv", "HEIGHT_M");
  EXPECT_EQ(table.time_column, "stamp");
  EXPECT_EQ(table.altitude_column, "height_m");
  ASSERT_EQ(table.rows.size(), 2u);  // the empty cell is no measurement
  EXPECT_EQ(table.at(9.0), 2.0);
  EXPECT_EQ(table.at(10.0), 2.0);
  EXPECT_NEAR(table.at(11.5), 3.5, 1e-12);
  EXPECT_EQ(table.at(13.0), 4.0);
  for (const auto& row : table.rows) EXPECT_TRUE(row.min_range_m <= 2.0 && row.max_range_m >= 4.0);
  writeText(dir / "default.csv", "t_unix_s,altitude_m\n10,2\n");
  EXPECT_EQ(dive::readAltitudeCsv(dir / "default.csv", "").rows.at(0).range_m, 2.0);
  const auto expectCsvError = [&](const std::string& text, const std::string& column,
                                  const std::vector<std::string>& parts) {
    writeText(dir / "bad.csv", text);
    expectImportError([&] { dive::readAltitudeCsv(dir / "bad.csv", column); }, dive::DiveImportError::Kind::kInput,
                      parts);
  };
  expectCsvError("t,altitude\n10,2\n10,3\n", "", {"--altitude", "line 3, column 't'", "must increase"});
  expectCsvError("t,altitude\n10,2\n11,0\n", "", {"--altitude", "line 3, column 'altitude'", "(0, 1000] m"});
  expectCsvError("t,altitude\n10,2\n11,1200\n", "", {"line 3", "(0, 1000] m"});
  expectCsvError("t,altitude\n10,abc\n", "", {"line 2, column 'altitude'", "not a number"});
  expectCsvError("t,height\n10,2\n", "", {"no altitude column", "altitude or altitude_m", "FILE.csv:COLUMN"});
  expectCsvError("t,height\n10,2\n", "depth", {"no altitude column", "depth"});
  expectCsvError("when,altitude\n10,2\n", "", {"no time column", "t_unix_s, t, time, stamp, ts"});
  expectCsvError("t,altitude\n10,\n", "", {"no row has an altitude"});
}

/// The checks common to the bags of a dive without navigation: three images, their camera_info, no odometry.
void expectNoNavBag(const BagContents& bag) {
  ASSERT_EQ(bag.images.size(), 3u);
  ASSERT_EQ(bag.infos.size(), 3u);
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(bag.images[k].header.stamp.toSec(), 100.0 + 0.25 * k, 1e-9);
  EXPECT_TRUE(bag.odometry.empty());
  EXPECT_TRUE(bag.depths.empty());
  for (const auto& topic : bag.topics) {
    EXPECT_NE(topic, topics::kNavOdometry);
    EXPECT_NE(topic, topics::kNavDepth);
  }
  // base_link -> camera_optical, and base_link -> altimeter, where the fusion finds the altimeter.
  ASSERT_EQ(bag.tf_static.size(), 1u);
  ASSERT_EQ(bag.tf_static[0].transforms.size(), 2u);
  EXPECT_EQ(bag.tf_static[0].transforms[1].header.frame_id, "base_link");
  EXPECT_EQ(bag.tf_static[0].transforms[1].child_frame_id, "altimeter");
  EXPECT_EQ(bag.tf_static[0].transforms[1].transform.rotation.w, 1.0);
  for (const auto& a : bag.altitudes) {
    EXPECT_EQ(a.header.frame_id, "altimeter");
    EXPECT_EQ(a.radiation_type, sensor_msgs::Range::ULTRASOUND);
    EXPECT_TRUE(a.min_range <= a.range && a.range <= a.max_range) << a.range;
  }
  for (size_t i = 1; i < bag.record_times_s.size(); ++i) EXPECT_LE(bag.record_times_s[i - 1], bag.record_times_s[i]);
}

/// The replay arguments of the sidecar beside `bag`, as name -> value.
std::map<std::string, std::string> sidecarArguments(const std::string& bag) {
  const auto json = exocet_common::readJsonObjectFile<nlohmann::json>(bag + ".replay.json");
  std::map<std::string, std::string> out;
  if (!json || !json->contains("replay_arguments")) {
    ADD_FAILURE() << "no replay_arguments in " << bag << ".replay.json";
    return out;
  }
  for (const auto& [name, value] : (*json)["replay_arguments"].items()) out[name] = value.get<std::string>();
  return out;
}

TEST(DiveImportNoNav, ConstantAltitudeRoundTrip) {
  TempDir dir;
  writeNoiseImages(dir / "images");
  const RunResult run = runTool(noNavArgs(dir, "2.5"), dir);
  ASSERT_EQ(run.exit_code, 0) << run.err;
  EXPECT_NE(run.out.find("3 frames, no navigation (3 altitude)"), std::string::npos) << run.out;
  EXPECT_NE(run.err.find("no --heading"), std::string::npos) << run.err;
  EXPECT_NE(run.out.find("rosrun exocet_mosaic replay_dive " + (dir / "out.bag") + " " + (dir / "out_tiles") +
                         " ground_truth:=false fusion_preset:=images_only heading_deg:=0.0000\n"),
            std::string::npos)
      << run.out;
  EXPECT_NE(run.out.find("local frame 'map'"), std::string::npos) << run.out;
  EXPECT_EQ(dir.files(), (std::vector<std::string>{"images", "out.bag", "out.bag.replay.json"}));
  const BagContents bag = readBag(dir / "out.bag");
  expectNoNavBag(bag);
  // One altitude at each image, the constant, stamped as the image; no datum without a start point.
  ASSERT_EQ(bag.altitudes.size(), 3u);
  for (int k = 0; k < 3; ++k) {
    EXPECT_EQ(bag.altitudes[k].header.stamp, bag.images[k].header.stamp);
    EXPECT_FLOAT_EQ(bag.altitudes[k].range, 2.5f);
  }
  EXPECT_TRUE(bag.datums.empty());
  const auto args = sidecarArguments(dir / "out.bag");
  EXPECT_EQ(args, (std::map<std::string, std::string>{
                      {"ground_truth", "false"}, {"fusion_preset", "images_only"}, {"heading_deg", "0.0000"}}));
}

TEST(DiveImportNoNav, AltitudeCsvWithStartPointRoundTrip) {
  TempDir dir;
  writeNoiseImages(dir / "images");
  // Rows before, between and after the images (100, 100.25, 100.5 s); 130 s is beyond the 1 s margin: left out.
  writeText(dir / "alt.csv", "time,altitude\n98.5,9\n99.5,2\n100,2\n100.5,3\n101.2,4\n130,5\n");
  std::vector<std::string> args = noNavArgs(dir, dir / "alt.csv");
  args.insert(args.end(), {"--origin-lat", "39.55", "--origin-lon", "2.62", "--heading", "10"});
  const RunResult run = runTool(args, dir);
  ASSERT_EQ(run.exit_code, 0) << run.err;
  const BagContents bag = readBag(dir / "out.bag");
  expectNoNavBag(bag);
  // The rows from 99.5 s (98.5 is more than 1 s before the first image) to 101.2 s, and the image at 100.25 s
  // interpolated; the images at 100 and 100.5 s have a row at their stamp.
  const std::vector<std::pair<double, double>> expected = {
      {99.5, 2.0}, {100.0, 2.0}, {100.25, 2.5}, {100.5, 3.0}, {101.2, 4.0}};
  ASSERT_EQ(bag.altitudes.size(), expected.size());
  for (size_t i = 0; i < expected.size(); ++i) {
    EXPECT_NEAR(bag.altitudes[i].header.stamp.toSec(), expected[i].first, 1e-6) << i;
    EXPECT_NEAR(bag.altitudes[i].range, expected[i].second, 1e-6) << i;
  }
  // The start point's zone on /nav/datum; the heading turned to grid north: at 2.62 E, west of zone 31's central
  // meridian (3 E), grid north lies west of true north by atan(tan(0.38 deg) sin(39.55 deg)) = 0.242 deg.
  ASSERT_EQ(bag.datums.size(), 1u);
  EXPECT_EQ(bag.datums[0].epsg, 32631);
  const auto replay = sidecarArguments(dir / "out.bag");
  EXPECT_EQ(replay.at("fusion_preset"), "images_only");
  EXPECT_EQ(replay.at("origin_lat"), "39.55000000");
  EXPECT_EQ(replay.at("origin_lon"), "2.62000000");
  const double convergence_deg = std::atan(std::tan(0.38 * M_PI / 180) * std::sin(39.55 * M_PI / 180)) * 180 / M_PI;
  EXPECT_NEAR(std::stod(replay.at("heading_deg")), 10.0 + convergence_deg, 2e-4);
  EXPECT_NE(run.out.find("origin_lat:=39.55000000 origin_lon:=2.62000000 heading_deg:=" + replay.at("heading_deg")),
            std::string::npos)
      << run.out;
}

TEST(DiveImportNoNav, ImagesOutsideTheAltitudeCsv) {
  TempDir dir;
  writeNoiseImages(dir / "images");
  // The last image (100.5 s) is 1.1 s after the last row: beyond the 1 s margin; the one before is within it.
  writeText(dir / "alt.csv", "t,altitude\n98,2\n99.4,2\n");
  const auto args = noNavArgs(dir, dir / "alt.csv");
  expectImportError([&] { prepare(args); }, dive::DiveImportError::Kind::kInput,
                    {"--altitude", "img_2.png", "1.100 s after the last row", "1.0 s"});
  const RunResult run = runTool(args, dir);
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_NE(run.err.find("--altitude: image 'img_2.png'"), std::string::npos) << run.err;
  EXPECT_EQ(dir.files(), (std::vector<std::string>{"alt.csv", "images"}));
  // Within the margin the image takes the last row's value.
  writeText(dir / "alt.csv", "t,altitude\n99,2\n99.6,3\n");
  RecordingSink sink;
  dive::writeDiveImport(prepare(args), &sink);
  ASSERT_EQ(sink.altitudes.size(), 5u);  // 2 rows + 3 images
  EXPECT_EQ(sink.altitudes.back().stamp_s, 100.5);
  EXPECT_EQ(sink.altitudes.back().range_m, 3.0);
}

// ------------------------------------------------------------------------------------------------------------
// Bad inputs: a clear message naming the problem, exit 2, and nothing under the output's name.

class DiveImportErrors : public ::testing::Test {
 protected:
  void SetUp() override {
    output_ = dir_ / "out.bag";
    args_ = sparusArgs(output_);
    nav_lines_ = readLines(kSparus + "/sparus_snippet.csv");
  }
  /// The Sparus CSV with line `line_number` (from 1) changed by `edit`.
  std::string editedNav(int line_number, const std::function<std::string(const std::string&)>& edit) {
    std::vector<std::string> lines = nav_lines_;
    lines.at(line_number - 1) = edit(lines.at(line_number - 1));
    std::string text;
    for (const auto& l : lines) text += l + "\n";
    const std::string path = dir_ / ("nav_" + std::to_string(++edits_) + ".csv");
    writeText(path, text);
    return path;
  }
  void expectNoOutput() {
    for (const auto& name : dir_.files()) {
      EXPECT_NE(name, "out.bag");
      EXPECT_EQ(name.find(".partial"), std::string::npos) << name;
    }
  }

  TempDir dir_;
  std::string output_;
  std::vector<std::string> args_;
  std::vector<std::string> nav_lines_;
  int edits_ = 0;
};

TEST_F(DiveImportErrors, MissingImagesFolder) {
  const auto args = replaceArg(args_, "--images", dir_ / "no_such_folder");
  expectImportError([&] { prepare(args); }, dive::DiveImportError::Kind::kInput, {"--images", "does not exist"});
  const RunResult run = runTool(args, dir_);
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_NE(run.err.find("--images: '" + dir_ / "no_such_folder" + "' does not exist"), std::string::npos) << run.err;
  expectNoOutput();
}

TEST_F(DiveImportErrors, MissingOrUnreadableNav) {
  const auto missing = replaceArg(args_, "--nav", dir_ / "no_such.csv");
  expectImportError([&] { prepare(missing); }, dive::DiveImportError::Kind::kInput, {"--nav", "does not exist"});
  const RunResult run = runTool(missing, dir_);
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_NE(run.err.find("no_such.csv"), std::string::npos) << run.err;
  // A folder where the CSV should be cannot be read as one.
  expectImportError([&] { prepare(replaceArg(args_, "--nav", dir_.path())); }, dive::DiveImportError::Kind::kInput,
                    {"--nav", "is a folder"});
  writeText(dir_ / "empty.csv", "");
  expectImportError([&] { prepare(replaceArg(args_, "--nav", dir_ / "empty.csv")); },
                    dive::DiveImportError::Kind::kInput, {"--nav", "empty"});
  writeText(dir_ / "no_time.csv", "x,y,z\n1,2,3\n");
  expectImportError([&] { prepare(replaceArg(args_, "--nav", dir_ / "no_time.csv")); },
                    dive::DiveImportError::Kind::kInput, {"no time column", "t_unix_s, t, time, stamp, ts"});
  expectNoOutput();
}

TEST_F(DiveImportErrors, NavTimeGoingBackwards) {
  // Line 10's time put before line 9's.
  const std::string nav = editedNav(10, [](const std::string& l) { return "1372687209.0" + l.substr(l.find(',')); });
  const auto args = replaceArg(args_, "--nav", nav);
  expectImportError([&] { prepare(args); }, dive::DiveImportError::Kind::kInput,
                    {"line 10", "goes backwards", "line 9"});
  const RunResult run = runTool(args, dir_);
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_NE(run.err.find("line 10, column 'ts'"), std::string::npos) << run.err;
  expectNoOutput();
}

TEST_F(DiveImportErrors, NanOrGarbageInNav) {
  const std::string nan_nav = editedNav(7, [](const std::string& l) {
    // Fields: ts,source,target,x,y,z,...: replace z.
    std::vector<std::string> f;
    std::stringstream s(l);
    for (std::string x; std::getline(s, x, ',');) f.push_back(x);
    f[5] = "nan";
    std::string out;
    for (size_t i = 0; i < f.size(); ++i) out += (i ? "," : "") + f[i];
    return out;
  });
  const auto args = replaceArg(args_, "--nav", nan_nav);
  expectImportError([&] { prepare(args); }, dive::DiveImportError::Kind::kInput, {"line 7, column 'z'", "not finite"});
  const RunResult run = runTool(args, dir_);
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_NE(run.err.find("line 7, column 'z'"), std::string::npos) << run.err;
  const std::string garbage = editedNav(4, [](const std::string& l) { return l.substr(0, l.rfind(',')) + ",abc"; });
  expectImportError([&] { prepare(replaceArg(args_, "--nav", garbage)); }, dive::DiveImportError::Kind::kInput,
                    {"line 4, column 'qw'", "'abc' is not a number"});
  const std::string short_row = editedNav(5, [](const std::string& l) { return l.substr(0, l.rfind(',')); });
  expectImportError([&] { prepare(replaceArg(args_, "--nav", short_row)); }, dive::DiveImportError::Kind::kInput,
                    {"line 5 has 9 fields but the header has 10"});
  expectNoOutput();
}

TEST_F(DiveImportErrors, CameraYamlWithoutCameraMatrix) {
  writeText(dir_ / "camera.yaml",
            "image_width: 384\nimage_height: 288\ndistortion_coefficients:\n  rows: 1\n  cols: 5\n"
            "  data: [0, 0, 0, 0, 0]\n");
  const auto args = replaceArg(args_, "--camera", dir_ / "camera.yaml");
  expectImportError([&] { prepare(args); }, dive::DiveImportError::Kind::kInput, {"--camera", "camera_matrix"});
  const RunResult run = runTool(args, dir_);
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_NE(run.err.find("camera_matrix"), std::string::npos) << run.err;
  expectNoOutput();
}

TEST_F(DiveImportErrors, ImageOfAnotherSize) {
  writeNoiseImages(dir_ / "images");
  ASSERT_TRUE(cv::imwrite(dir_ / "images/img_1.png", cv::Mat(100, 200, CV_8UC3, cv::Scalar(1, 2, 3))));
  std::vector<std::string> args = replaceArg(args_, "--images", dir_ / "images");
  args.erase(args.begin() + 2, args.begin() + 4);  // --image-times: these images are timed by rate
  args.insert(args.end(), {"--start-time", "1372687209", "--fps", "5"});
  // Caught while writing: the temporary bag must go too.
  const RunResult run = runTool(args, dir_);
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_NE(run.err.find("img_1.png' is 200x100 pixels but the camera (--camera) is 384x288"), std::string::npos)
      << run.err;
  expectNoOutput();
  const dive::DiveImport dive = prepare(args);
  RecordingSink sink;
  expectImportError([&] { dive::writeDiveImport(dive, &sink); }, dive::DiveImportError::Kind::kInput,
                    {"img_1.png", "200x100", "384x288"});
}

TEST_F(DiveImportErrors, OutputFolderDoesNotExist) {
  const std::string output = dir_ / "no_such_folder/out.bag";
  const auto args = replaceArg(args_, "--output", output);
  expectImportError([&] { prepare(args); }, dive::DiveImportError::Kind::kInput, {"--output", "does not exist"});
  const RunResult run = runTool(args, dir_);
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_NE(run.err.find("--output"), std::string::npos) << run.err;
  EXPECT_NE(run.err.find("does not exist"), std::string::npos) << run.err;
  EXPECT_FALSE(fs::exists(output));
}

TEST_F(DiveImportErrors, UsageErrorsAndHelp) {
  const RunResult help = runTool({"--help"}, dir_);
  EXPECT_EQ(help.exit_code, 0);
  EXPECT_NE(help.out.find("Usage: dive_import"), std::string::npos);
  EXPECT_NE(help.out.find("t_unix_s, t, time, stamp, ts"), std::string::npos);
  EXPECT_TRUE(help.err.empty()) << help.err;
  const RunResult none = runTool({}, dir_);
  EXPECT_EQ(none.exit_code, 2);
  EXPECT_NE(none.err.find("--images is required"), std::string::npos) << none.err;
  const auto expectUsage = [&](std::vector<std::string> args, const std::string& part) {
    expectImportError([&] { dive::parseDiveImportArguments(args); }, dive::DiveImportError::Kind::kInput, {part});
  };
  std::vector<std::string> args = args_;
  args.insert(args.end(), {"--encoding", "rgb8"});
  expectUsage(args, "--encoding: rgb8 not in {bgr8,mono8}");
  args = args_;
  args.insert(args.end(), {"--image-storage=tiff"});
  expectUsage(args, "--image-storage: tiff not in {raw,jpeg,png}");
  args = args_;
  args.insert(args.end(), {"--start-time", "5"});
  expectUsage(args, "cannot be combined");
  args = args_;
  args.insert(args.end(), {"--origin-lat", "42"});
  expectUsage(args, "--origin-lat and --origin-lon");
  args = args_;
  args.insert(args.end(), {"--camera-pose", "1,2,3"});
  expectUsage(args, "--camera-pose");
  args = args_;
  args.insert(args.end(), {"--frobnicate", "1"});
  expectUsage(args, "--frobnicate");
  expectUsage(args, "not expected");
  expectUsage({"--images", "a", "--nav", "b", "--camera", "c", "--output", "d"}, "--image-times");
  expectNoOutput();
}

}  // namespace

// catkin's gtest does not link gtest_main.
int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
