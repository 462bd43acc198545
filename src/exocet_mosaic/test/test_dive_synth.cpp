// Tests of the dive simulator: determinism, rendering geometry against ground truth, sensor noise statistics,
// trajectories, and the rejection of bad descriptions by the library and by the dive_synth tool.
#include <cstdio>
#include <fstream>
#include <iterator>
#include <sstream>
#include <string>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sys/stat.h>
#include <unistd.h>

#include "exocet_mosaic/sim/dive_description.h"
#include "exocet_common/geo_reference.h"
#include "exocet_common/testing/paths.h"

using namespace exocet_mosaic::sim;
namespace dive = exocet_mosaic::dive;

namespace {

std::string readFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}
bool exists(const std::string& path) {
  struct stat st;
  return ::stat(path.c_str(), &st) == 0;
}
std::string tempDir() {
  char tmpl[] = "/tmp/exocet_synth_test_XXXXXX";
  return std::string(::mkdtemp(tmpl));
}
/// Runs a command, returning its exit status; stderr is captured into *err.
int runCommand(const std::string& cmd, std::string* err) {
  const std::string err_file = tempDir() + "/stderr.txt";
  const int status = std::system((cmd + " > /dev/null 2> " + err_file).c_str());
  *err = readFile(err_file);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}
const std::string kSynth = exocet_common::testing::executableDir() + "/dive_synth";

/// Dive-time standard deviation of a sample.
double stddev(const std::vector<double>& v) {
  double mean = 0;
  for (double x : v) mean += x;
  mean /= v.size();
  double s = 0;
  for (double x : v) s += (x - mean) * (x - mean);
  return std::sqrt(s / (v.size() - 1));
}

}  // namespace

// ---------------------------------------------------------------------------------------------------- determinism
TEST(DiveSynthTool, SameSeedGivesByteIdenticalBagAndOtherSeedDiffers) {
  const std::string dir = tempDir();
  const std::string common = " --duration 1.2 --set camera.fps=5 --set landmarks.count=2 --relief --quiet"
                             " --set imaging.noise_sigma_dn=2 --set imaging.marine_snow_per_m3=20";
  std::string err;
  ASSERT_EQ(runCommand(kSynth + common + " --seed 7 --output " + dir + "/a.bag", &err), 0) << err;
  ASSERT_EQ(runCommand(kSynth + common + " --seed 7 --threads 2 --output " + dir + "/b.bag", &err), 0) << err;
  ASSERT_EQ(runCommand(kSynth + common + " --seed 8 --output " + dir + "/c.bag", &err), 0) << err;
  const std::string a = readFile(dir + "/a.bag"), b = readFile(dir + "/b.bag"), c = readFile(dir + "/c.bag");
  ASSERT_GT(a.size(), 1000000u);  // 7 PAL frames and the sensors
  EXPECT_TRUE(a == b) << "same seed (1 vs 2 threads) must give the same bytes";
  EXPECT_FALSE(a == c) << "another seed must give another dive";
  EXPECT_EQ(readFile(dir + "/a.ground_truth.csv"), readFile(dir + "/b.ground_truth.csv"));
  EXPECT_TRUE(exists(dir + "/a.landmarks.csv"));
  EXPECT_TRUE(exists(dir + "/a.config.yaml"));
  // The written description reproduces the dive.
  ASSERT_EQ(runCommand(kSynth + " --config " + dir + "/a.config.yaml --quiet --output " + dir + "/d.bag", &err), 0)
      << err;
  EXPECT_TRUE(readFile(dir + "/d.bag") == a);
}

// ------------------------------------------------------------------------------------------------------- geometry
namespace {
struct GeometryCase {
  bool relief;
  bool distortion;
};

/// Renders ideal images with a landmark in view and checks that its saddle point is where the ground-truth pose
/// and intrinsics project it. Returns the worst error (px).
double worstLandmarkError(const GeometryCase& c, int* checked) {
  std::vector<std::string> o = {"trajectory.kind=out_and_back", "trajectory.line_length_m=6",
                                "trajectory.roll_amplitude_deg=4", "trajectory.pitch_amplitude_deg=5",
                                "trajectory.yaw_oscillation_deg=8", "trajectory.altitude_variation_m=0.3",
                                "camera.mounting_rpy_deg=[2,-3,5]", "landmarks.count=6", "landmarks.size_m=0.25",
                                "landmarks.lateral_offset_m=0.4", "imaging.light_cone_strength=0",
                                "imaging.attenuation_per_m=[0,0,0]", "imaging.noise_sigma_dn=0",
                                "imaging.vignetting=0", "imaging.marine_snow_per_m3=0", "imaging.gamma=1"};
  o.push_back(std::string("seabed.relief=") + (c.relief ? "true" : "false"));
  if (c.distortion) o.push_back("camera.distortion=[-0.25,0.08,0.001,-0.0015,0.0]");
  const DiveDescription dive = parseDiveDescription("", o, ".");
  Seabed seabed = makeSeabed(dive.seabed, dive.synthesis.seed);
  DiveSynthesizer synth(dive.synthesis, seabed.texture.get(), seabed.relief.get());
  const exocet_common::CameraModel& cam = dive.synthesis.rig.camera;
  double worst = 0.0;
  *checked = 0;
  for (const Landmark& m : synth.renderer().landmarks()) {
    // The frame whose camera is closest above the landmark.
    double best_t = 0, best_d = 1e9;
    for (double t = 0; t < synth.duration_s(); t += 0.1) {
      const Eigen::Vector3d p = synth.cameraPoseLocal(t).translation();
      const double d = std::hypot(p.x() - m.x_m, p.y() - m.y_m);
      if (d < best_d) best_d = d, best_t = t;
    }
    const Eigen::Isometry3d pose = synth.cameraPoseLocal(best_t);
    const Eigen::Vector3d landmark(m.x_m, m.y_m, seabed.relief->heightAt_m(m.x_m, m.y_m));
    Eigen::Vector2d predicted;
    if (!cam.project(pose.inverse() * landmark, &predicted)) continue;
    if (predicted.x() < 20 || predicted.y() < 20 || predicted.x() > cam.width - 20 || predicted.y() > cam.height - 20)
      continue;
    cv::Mat rgb = synth.renderer().encode(synth.renderer().renderRadiance(pose, best_t, 0), 0, "mono8");
    // Start the saddle search away from the prediction so that the detector, not the prediction, decides.
    std::vector<cv::Point2f> corner{cv::Point2f(predicted.x() + 1.6f, predicted.y() - 1.3f)};
    cv::cornerSubPix(rgb, corner, cv::Size(6, 6), cv::Size(-1, -1),
                     cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 100, 1e-4));
    const double err = std::hypot(corner[0].x - predicted.x(), corner[0].y - predicted.y());
    worst = std::max(worst, err);
    ++*checked;
  }
  return worst;
}
}  // namespace

TEST(DiveSynthGeometry, LandmarkAppearsAtPredictedPixelFlatSeabed) {
  int checked = 0;
  const double worst = worstLandmarkError({false, false}, &checked);
  EXPECT_GE(checked, 4);
  EXPECT_LT(worst, 0.5);
  std::cout << "flat seabed: worst landmark error " << worst << " px over " << checked << " landmarks\n";
}

TEST(DiveSynthGeometry, LandmarkAppearsAtPredictedPixelWithReliefAndDistortion) {
  int checked = 0;
  const double worst = worstLandmarkError({true, true}, &checked);
  EXPECT_GE(checked, 4);
  EXPECT_LT(worst, 0.5);
  std::cout << "relief + distortion: worst landmark error " << worst << " px over " << checked << " landmarks\n";
}

TEST(DiveSynthGeometry, CameraModelDistortionRoundTrip) {
  exocet_common::CameraModel c = exocet_common::CameraModel::pal();
  c.distortion = {-0.3, 0.1, 0.002, -0.001, 0.01};
  for (double x = -0.6; x <= 0.6; x += 0.2)
    for (double y = -0.45; y <= 0.45; y += 0.15) {
      const Eigen::Vector2d d = c.distortNormalized({x, y});
      const Eigen::Vector2d u = c.undistortNormalized(d);
      EXPECT_NEAR(u.x(), x, 1e-10);
      EXPECT_NEAR(u.y(), y, 1e-10);
    }
}

// ------------------------------------------------------------------------------------------------ sensor noise
namespace {
struct NoiseRun {
  std::vector<double> depth, altitude, usbl_e, usbl_n, usbl_u, dvl_x, dvl_y, gyro_x, gyro_z, roll, pitch, accel_x;
  std::vector<double> latency, bias_steps;
  int usbl_count = 0, outliers = 0;
};

NoiseRun runSensors(const NavigationSensorConfig& cfg, double duration_s) {
  TrajectoryConfig tc;
  tc.kind = TrajectoryConfig::Kind::kLawnmower;
  tc.line_length_m = 300;
  tc.line_count = 3;
  tc.roll_amplitude_deg = 3;
  tc.pitch_amplitude_deg = 3;
  tc.altitude_variation_m = 0.3;
  const VehicleTrajectory traj(tc);
  const exocet_common::GeoReference geo = exocet_common::makeGeoReference(43.0, 5.9);
  const double t0 = 1.78e9, depth0 = 60.0;
  NavigationSensorSimulator sim(cfg, geo, depth0, t0, 99);
  NoiseRun r;
  NavigationSinks s;
  auto truth = [&](double stamp) { return traj.stateAt(stamp - t0); };
  s.depth = [&](const dive::DepthRecord& d) { r.depth.push_back(d.depth_m - (depth0 - truth(d.stamp_s).position_m.z())); };
  s.altitude = [&](const dive::AltitudeRecord& a) {
    const VehicleState st = truth(a.stamp_s);
    r.altitude.push_back(a.range_m - rayToSeabed_m(st.position_m, -st.rotation().col(2), FlatRelief()));
  };
  s.usbl = [&](const dive::FixRecord& f) {
    const VehicleState st = truth(f.stamp_s);
    const Eigen::Vector2d en = exocet_common::latLonToGrid(geo, f.latitude_deg, f.longitude_deg);
    const double de = en.x() - (geo.origin_easting_m + st.position_m.x());
    const double dn = en.y() - (geo.origin_northing_m + st.position_m.y());
    ++r.usbl_count;
    if (std::hypot(de, dn) > 5 * std::max(cfg.usbl_noise_m, 0.1)) {
      ++r.outliers;
      return;
    }
    r.usbl_e.push_back(de);
    r.usbl_n.push_back(dn);
    r.usbl_u.push_back(f.altitude_m - (st.position_m.z() - depth0));
    r.latency.push_back(f.arrival_s - f.stamp_s);
  };
  s.dvl = [&](const dive::DvlRecord& d) {
    const VehicleState st = truth(d.stamp_s);
    const Eigen::Vector3d v = st.rotation().transpose() * st.velocity_mps;
    r.dvl_x.push_back(d.velocity_mps.x() - v.x());
    r.dvl_y.push_back(d.velocity_mps.y() - v.y());
  };
  s.imu = [&](const dive::ImuRecord& m) {
    const VehicleState st = truth(m.stamp_s);
    const Eigen::Vector3d e = m.angular_velocity_rps - st.angular_velocity_rps - sim.gyroBias();
    r.gyro_x.push_back(e.x());
    r.gyro_z.push_back(e.z());
    const Eigen::Vector3d rpy = rpyFromRotation(m.orientation.toRotationMatrix());
    r.roll.push_back(rpy.x() - st.roll_rad);
    r.pitch.push_back(rpy.y() - st.pitch_rad);
    const Eigen::Vector3d f = st.rotation().transpose() * (st.acceleration_mps2 + Eigen::Vector3d(0, 0, 9.80665));
    r.accel_x.push_back(m.linear_acceleration_mps2.x() - f.x());
  };
  Eigen::Vector3d last_bias = sim.gyroBias();
  for (double t = 1.0; t <= duration_s; t += 1.0) {
    sim.advanceTo(traj, t, s);
    r.bias_steps.push_back(sim.gyroBias().z() - last_bias.z());
    last_bias = sim.gyroBias();
  }
  return r;
}

void expectSigma(const std::vector<double>& v, double sigma, const char* what) {
  ASSERT_GT(v.size(), 500u) << what;
  const double s = stddev(v);
  EXPECT_NEAR(s, sigma, 0.10 * sigma) << what << ": measured sigma " << s << " vs configured " << sigma;
}
}  // namespace

TEST(NavigationSensors, NoiseOfEachSensorWithinTenPercentOfItsSigma) {
  NavigationSensorConfig cfg;
  cfg.gyro_bias_walk_rps_sqrt_s = 0.0;  // the bias is then constant and known: the white noise alone remains
  cfg.dvl_scale_error = 0.0;
  cfg.depth_noise_m = 0.05;
  cfg.altimeter_noise_m = 0.03;
  cfg.usbl_noise_m = 0.8;
  cfg.usbl_vertical_noise_m = 0.4;
  cfg.usbl_latency_s = 2.0;
  const NoiseRun r = runSensors(cfg, 1500.0);
  expectSigma(r.depth, cfg.depth_noise_m, "depth");
  expectSigma(r.altitude, cfg.altimeter_noise_m, "altimeter");
  expectSigma(r.usbl_e, cfg.usbl_noise_m, "USBL easting");
  expectSigma(r.usbl_n, cfg.usbl_noise_m, "USBL northing");
  expectSigma(r.usbl_u, cfg.usbl_vertical_noise_m, "USBL vertical");
  expectSigma(r.dvl_x, cfg.dvl_noise_mps, "DVL x");
  expectSigma(r.dvl_y, cfg.dvl_noise_mps, "DVL y");
  expectSigma(r.gyro_x, cfg.gyro_noise_rps, "gyro x");
  expectSigma(r.gyro_z, cfg.gyro_noise_rps, "gyro z");
  expectSigma(r.roll, cfg.attitude_noise_rad, "roll");
  expectSigma(r.pitch, cfg.attitude_noise_rad, "pitch");
  expectSigma(r.accel_x, cfg.accel_noise_mps2, "accelerometer x");
  for (double l : r.latency) ASSERT_NEAR(l, 2.0, 1e-9);
  EXPECT_EQ(r.outliers, 0);
}

TEST(NavigationSensors, GyroBiasRandomWalkAndUsblOutliersMatchTheirConfiguration) {
  NavigationSensorConfig cfg;
  cfg.gyro_bias_walk_rps_sqrt_s = 1e-4;
  cfg.usbl_outlier_probability = 0.1;
  cfg.usbl_noise_m = 0.5;
  const NoiseRun r = runSensors(cfg, 2000.0);
  expectSigma(r.bias_steps, cfg.gyro_bias_walk_rps_sqrt_s * std::sqrt(1.0), "gyro bias walk over 1 s");
  const double fraction = static_cast<double>(r.outliers) / r.usbl_count;
  EXPECT_NEAR(fraction, 0.1, 0.02) << r.outliers << " outliers of " << r.usbl_count;
}

TEST(NavigationSensors, DeadReckoningDriftsWhileUsblDoesNot) {
  std::vector<std::string> o = {"trajectory.line_length_m=60", "trajectory.line_count=3"};
  const DiveDescription dive = parseDiveDescription("", o, ".");
  const exocet_common::GeoReference& geo = dive.synthesis.geo;
  const VehicleTrajectory traj(dive.synthesis.trajectory);
  NavigationSensorSimulator sim(dive.synthesis.navigation, geo, 60.0, 0.0, 5);
  double last_error = 0;
  NavigationSinks s;
  s.dead_reckoning = [&](const dive::PoseRecord& p) {
    const VehicleState st = traj.stateAt(p.stamp_s);
    last_error = std::hypot(p.position_m.x() - geo.origin_easting_m - st.position_m.x(),
                            p.position_m.y() - geo.origin_northing_m - st.position_m.y());
  };
  sim.advanceTo(traj, 1.0, s);
  EXPECT_LT(last_error, 0.05);
  sim.advanceTo(traj, traj.duration_s(), s);
  EXPECT_GT(last_error, 0.05) << "dead reckoning should drift over " << traj.pathLength_m() << " m";
  EXPECT_LT(last_error, 0.1 * traj.pathLength_m());
}

// --------------------------------------------------------------------------------------------------- trajectories
TEST(VehicleTrajectory, LawnmowerLegsSpacingAndHeadingConvention) {
  TrajectoryConfig c;
  c.heading_deg = 90;  // compass east
  c.line_length_m = 10;
  c.line_spacing_m = 3;
  c.line_count = 3;
  const VehicleTrajectory t(c);
  const VehicleState s0 = t.stateAt(5.0);
  EXPECT_NEAR(s0.yaw_rad, 0.0, 1e-9) << "compass 90 deg is ENU yaw 0 (east)";
  EXPECT_GT(s0.velocity_mps.x(), 0.3);
  EXPECT_NEAR(s0.position_m.y(), 0.0, 1e-9);
  const VehicleState end = t.stateAt(t.duration_s());
  EXPECT_NEAR(end.position_m.x(), 10.0, 1e-6);
  EXPECT_NEAR(end.position_m.y(), -6.0, 1e-6) << "first turn to starboard: south of an eastbound leg";
  EXPECT_NEAR(t.pathLength_m(), 30.0 + 2 * M_PI * 1.5, 1e-6);
  EXPECT_NEAR(end.velocity_mps.norm(), 0.0, 1e-3);
}

TEST(VehicleTrajectory, OutAndBackReturnsOverTheSameLine) {
  TrajectoryConfig c;
  c.kind = TrajectoryConfig::Kind::kOutAndBack;
  c.heading_deg = 0;
  c.line_length_m = 12;
  const VehicleTrajectory t(c);
  const VehicleState end = t.stateAt(t.duration_s());
  EXPECT_NEAR(end.position_m.head<2>().norm(), 0.0, 1e-6);
  double max_cross = 0;
  for (double s = 0; s < t.duration_s(); s += 0.5) max_cross = std::max(max_cross, std::abs(t.stateAt(s).position_m.x()));
  EXPECT_LT(max_cross, 1e-9);
  // Speed never exceeds the cruise speed; the numerical derivative matches the motion.
  for (double s = 0.3; s < t.duration_s(); s += 0.7) {
    const VehicleState a = t.stateAt(s);
    EXPECT_LE(a.velocity_mps.head<2>().norm(), c.speed_mps + 1e-6);
    const VehicleState b = t.stateAt(s + 0.01);
    EXPECT_NEAR((b.position_m.y() - a.position_m.y()) / 0.01, a.velocity_mps.y(), 0.01);
  }
}

// ------------------------------------------------------------------------------------------------------ bad input
TEST(DiveDescription, RejectsBadValuesNamingTheField) {
  auto error_of = [](const std::vector<std::string>& o) {
    try {
      parseDiveDescription("", o, ".");
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_NE(error_of({"trajectory.altitude_m=-2"}).find("trajectory.altitude_m"), std::string::npos);
  EXPECT_NE(error_of({"trajectory.altitud_m=2"}).find("unknown key 'trajectory.altitud_m'"), std::string::npos);
  EXPECT_NE(error_of({"imaging.segments=[{start_s: 10, end_s: 5}]"}).find("end_s must be greater than start_s"),
            std::string::npos);
  EXPECT_NE(error_of({"navigation.usbl_dropouts_s=[[30, 20]]"}).find("usbl_dropouts_s"), std::string::npos);
  EXPECT_NE(error_of({"camera.fps=0"}).find("camera.fps"), std::string::npos);
  EXPECT_NE(error_of({"origin.latitude_deg=95"}).find("latitude"), std::string::npos);
  EXPECT_NE(error_of({"camera.encoding=yuv422"}).find("camera.encoding"), std::string::npos);
  EXPECT_NE(error_of({"trajectory.kind=waypoints", "trajectory.waypoints_csv=/nonexistent/wp.csv"}).find("/nonexistent/wp.csv"),
            std::string::npos);
  EXPECT_NE(error_of({"camera.intrinsics_yaml=/nonexistent/k.yaml"}).find("/nonexistent/k.yaml"), std::string::npos);
  EXPECT_NE(error_of({"camera.preset=8k"}).find("pal, hd, uhd"), std::string::npos);
  EXPECT_EQ(error_of({}), "");
}

TEST(DiveDescription, CameraPresetsGiveTheirSizes) {
  const DiveDescription uhd = parseDiveDescription("", {"camera.preset=uhd", "camera.hfov_deg=60"}, ".");
  EXPECT_EQ(uhd.synthesis.rig.camera.width, 3840);
  EXPECT_EQ(uhd.synthesis.rig.camera.height, 2160);
  const DiveDescription hd = parseDiveDescription("", {"camera.preset=hd"}, ".");
  EXPECT_EQ(hd.synthesis.rig.camera.width, 1920);
  EXPECT_EQ(parseDiveDescription("", {}, ".").synthesis.rig.camera.width, 720);
}

TEST(DiveSynthTool, BadInputsExitWithAClearErrorAndLeaveNoOutput) {
  const std::string dir = tempDir();
  const std::string out = dir + "/bad.bag";
  struct Case {
    std::string args;
    int status;
    std::string message;
  };
  {
    std::ofstream wp(dir + "/backwards.csv");
    wp << "x_m,y_m,altitude_m\n0,0,2\n5,0,-1\n";
  }
  {
    // A 200x200 px picture of 1 cm pixels: 2 m wide, smaller than the camera's footprint.
    cv::Mat picture(200, 200, CV_8UC3, cv::Scalar(90, 120, 140));
    cv::imwrite(dir + "/small.png", picture);
  }
  const std::vector<Case> cases = {
      {"--seabed-image " + dir + "/small.png --seabed-pixel-size 0.01", 2, "leaves the seabed image"},
      {"--set trajectory.altitude_m=-3", 2, "trajectory.altitude_m"},
      {"--waypoints " + dir + "/backwards.csv", 2, "altitude_m"},
      {"--waypoints " + dir + "/missing.csv", 2, "missing.csv"},
      {"--config " + dir + "/missing.yaml", 2, "missing.yaml"},
      {"--seabed-image " + dir + "/missing.png", 1, "missing.png"},
      {"--set 'imaging.segments=[{start_s: 9, end_s: 3}]'", 2, "end_s"},
      {"--set camera.fps=-5", 2, "camera.fps"},
      {"--frobnicate", 2, "not expected: --frobnicate"},
  };
  for (const Case& c : cases) {
    std::string err;
    const int status = runCommand(kSynth + " --quiet --duration 0.5 " + c.args + " --output " + out, &err);
    EXPECT_EQ(status, c.status) << c.args << ": " << err;
    EXPECT_NE(err.find(c.message), std::string::npos) << c.args << ": stderr was: " << err;
    EXPECT_FALSE(exists(out)) << c.args;
  }
  std::string err;
  EXPECT_EQ(runCommand(kSynth + " --quiet --duration 0.5 --output /nonexistent_dir/x.bag", &err), 1);
  EXPECT_NE(err.find("/nonexistent_dir"), std::string::npos) << err;
  // Interrupted mid-dive: nothing under the final name, no temporary file left behind.
  const int status = std::system(("timeout --preserve-status -s INT 2 " + kSynth + " --quiet --output " + out + " > /dev/null 2>&1").c_str());
  EXPECT_EQ(WEXITSTATUS(status), 130);
  EXPECT_FALSE(exists(out));
  std::string listing;
  runCommand("ls -A " + dir + " 1>&2", &listing);
  EXPECT_EQ(listing.find(".partial"), std::string::npos) << listing;
}
