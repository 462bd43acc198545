#include "exocet_mosaic/sim/dive_description.h"

#include <fstream>
#include <set>
#include <sstream>
#include <stdexcept>

#include <yaml-cpp/yaml.h>

#include "exocet_common/geo_reference.h"

namespace exocet_mosaic {
namespace sim {

namespace {

/// Reads the keys of one YAML map, remembering which were consumed so that unknown (misspelt) keys are errors.
class Section {
 public:
  Section(const YAML::Node& node, std::string name) : node_(node), name_(std::move(name)) {
    if (node_ && !node_.IsNull() && !node_.IsMap()) throw std::invalid_argument(name_ + " must be a map of key: value");
  }
  template <typename T>
  void get(const char* key, T* value) {
    known_.insert(key);
    if (!node_ || node_.IsNull() || !node_[key]) return;
    try {
      *value = node_[key].template as<T>();
    } catch (const YAML::Exception&) {
      throw std::invalid_argument(path(key) + ": '" + text(node_[key]) + "' is not a valid value");
    }
  }
  template <size_t N>
  void getArray(const char* key, std::array<double, N>* value) {
    std::vector<double> v(value->begin(), value->end());
    getList(key, &v, N);
    std::copy(v.begin(), v.end(), value->begin());
  }
  void getVector3(const char* key, Eigen::Vector3d* value) {
    std::vector<double> v{value->x(), value->y(), value->z()};
    getList(key, &v, 3);
    *value = Eigen::Vector3d(v[0], v[1], v[2]);
  }
  void getList(const char* key, std::vector<double>* value, size_t expected) {
    known_.insert(key);
    if (!node_ || node_.IsNull() || !node_[key]) return;
    const YAML::Node list = node_[key];
    if (!list.IsSequence() || list.size() != expected)
      throw std::invalid_argument(path(key) + " must be a list of " + std::to_string(expected) + " numbers");
    value->clear();
    for (const auto& x : list) {
      try {
        value->push_back(x.as<double>());
      } catch (const YAML::Exception&) {
        throw std::invalid_argument(path(key) + ": '" + text(x) + "' is not a number");
      }
    }
  }
  YAML::Node child(const char* key) {
    known_.insert(key);
    return node_ && !node_.IsNull() ? node_[key] : YAML::Node();
  }
  void finish() const {
    if (!node_ || node_.IsNull()) return;
    for (const auto& kv : node_) {
      const std::string key = kv.first.as<std::string>();
      if (!known_.count(key)) {
        std::string allowed;
        for (const auto& k : known_) allowed += (allowed.empty() ? "" : ", ") + k;
        throw std::invalid_argument("unknown key '" + path(key.c_str()) + "' (allowed in " + name_ + ": " + allowed + ")");
      }
    }
  }
  std::string path(const char* key) const { return name_.empty() ? key : name_ + "." + key; }

 private:
  static std::string text(const YAML::Node& n) {
    std::stringstream ss;
    ss << n;
    return ss.str();
  }
  YAML::Node node_;
  std::string name_;
  std::set<std::string> known_;
};

void applyOverride(YAML::Node root, const std::string& assignment) {
  const auto eq = assignment.find('=');
  if (eq == std::string::npos || eq == 0)
    throw std::invalid_argument("override '" + assignment + "' must look like section.key=value");
  const std::string key_path = assignment.substr(0, eq);
  YAML::Node value;
  try {
    value = YAML::Load(assignment.substr(eq + 1));
  } catch (const YAML::Exception& e) {
    throw std::invalid_argument("override '" + assignment + "': value is not valid YAML");
  }
  std::vector<std::string> keys;
  std::stringstream ss(key_path);
  std::string k;
  while (std::getline(ss, k, '.')) keys.push_back(k);
  // yaml-cpp nodes are handles: walk down with fresh handles, creating maps as needed.
  std::vector<YAML::Node> chain{root};
  for (size_t i = 0; i + 1 < keys.size(); ++i) {
    YAML::Node next = chain.back()[keys[i]];
    if (!next || next.IsNull()) {
      chain.back()[keys[i]] = YAML::Node(YAML::NodeType::Map);
      next = chain.back()[keys[i]];
    }
    chain.push_back(next);
  }
  chain.back()[keys.back()] = value;
}

TrajectoryConfig::Kind trajectoryKind(const std::string& s) {
  if (s == "lawnmower") return TrajectoryConfig::Kind::kLawnmower;
  if (s == "out_and_back") return TrajectoryConfig::Kind::kOutAndBack;
  if (s == "waypoints") return TrajectoryConfig::Kind::kWaypoints;
  throw std::invalid_argument("trajectory.kind '" + s + "' is not one of lawnmower, out_and_back, waypoints");
}
std::string trajectoryKindName(TrajectoryConfig::Kind k) {
  switch (k) {
    case TrajectoryConfig::Kind::kLawnmower:
      return "lawnmower";
    case TrajectoryConfig::Kind::kOutAndBack:
      return "out_and_back";
    case TrajectoryConfig::Kind::kWaypoints:
      return "waypoints";
  }
  return "lawnmower";
}

std::string resolvePath(const std::string& p, const std::string& base_dir) {
  if (p.empty() || p[0] == '/' || base_dir.empty()) return p;
  return base_dir + "/" + p;
}

}  // namespace

DiveDescription parseDiveDescription(const std::string& yaml_text, const std::vector<std::string>& overrides,
                                     const std::string& base_dir) {
  YAML::Node root;
  try {
    root = yaml_text.empty() ? YAML::Node(YAML::NodeType::Map) : YAML::Load(yaml_text);
  } catch (const YAML::Exception& e) {
    throw std::invalid_argument(std::string("malformed YAML: ") + e.what());
  }
  if (root.IsNull()) root = YAML::Node(YAML::NodeType::Map);
  for (const auto& o : overrides) applyOverride(root, o);

  DiveDescription d;
  DiveSynthesisConfig& s = d.synthesis;
  Section top(root, "");
  top.get("seed", &s.seed);
  top.get("start_time_unix_s", &s.start_time_unix_s);
  top.get("duration_s", &s.duration_s);
  top.get("seabed_depth_m", &s.seabed_depth_m);
  top.get("ground_truth_rate_hz", &s.ground_truth_rate_hz);
  top.get("threads", &s.threads);

  Section origin(top.child("origin"), "origin");
  origin.get("latitude_deg", &d.origin_latitude_deg);
  origin.get("longitude_deg", &d.origin_longitude_deg);
  origin.finish();

  Section seabed(top.child("seabed"), "seabed");
  seabed.get("kind", &d.seabed.kind);
  seabed.get("texel_m", &d.seabed.texel_m);
  seabed.get("cache_budget_mb", &d.seabed.cache_budget_mb);
  seabed.get("relief", &d.seabed.relief);
  seabed.get("relief_scale", &d.seabed.relief_scale);
  seabed.get("objects", &d.seabed.objects);
  seabed.get("objects_density_per_m2", &d.seabed.objects_density_per_m2);
  seabed.get("image", &d.seabed.image);
  seabed.get("image_pixel_size_m", &d.seabed.image_pixel_size_m);
  seabed.get("image_center_x_m", &d.seabed.image_center_x_m);
  seabed.get("image_center_y_m", &d.seabed.image_center_y_m);
  seabed.finish();
  d.seabed.image = resolvePath(d.seabed.image, base_dir);

  Section camera(top.child("camera"), "camera");
  CameraRig& rig = s.rig;
  camera.get("preset", &d.camera_preset);
  camera.get("hfov_deg", &d.camera_hfov_deg);
  camera.get("intrinsics_yaml", &d.intrinsics_yaml);
  d.intrinsics_yaml = resolvePath(d.intrinsics_yaml, base_dir);
  if (d.camera_preset != "pal" && d.camera_preset != "hd" && d.camera_preset != "uhd")
    throw std::invalid_argument("camera.preset '" + d.camera_preset + "' is not one of pal, hd, uhd");
  if (!(d.camera_hfov_deg >= 10.0 && d.camera_hfov_deg <= 150.0))
    throw std::invalid_argument("camera.hfov_deg = " + std::to_string(d.camera_hfov_deg) + " out of range [10, 150] deg");
  rig.camera = d.camera_preset == "uhd"  ? exocet_common::CameraModel::uhd(d.camera_hfov_deg)
               : d.camera_preset == "hd" ? exocet_common::CameraModel::hd(d.camera_hfov_deg)
                                         : exocet_common::CameraModel::pal(d.camera_hfov_deg);
  if (!d.intrinsics_yaml.empty()) {
    try {
      rig.camera = exocet_common::loadCameraModelYaml(d.intrinsics_yaml);
    } catch (const std::runtime_error& e) {
      throw std::invalid_argument(std::string("camera.intrinsics_yaml: ") + e.what());
    }
  }
  camera.get("width", &rig.camera.width);
  camera.get("height", &rig.camera.height);
  camera.get("fx", &rig.camera.fx);
  camera.get("fy", &rig.camera.fy);
  camera.get("cx", &rig.camera.cx);
  camera.get("cy", &rig.camera.cy);
  camera.getArray("distortion", &rig.camera.distortion);
  camera.get("fps", &rig.fps);
  camera.get("encoding", &rig.encoding);
  camera.getVector3("lever_arm_m", &rig.lever_arm_m);
  camera.getVector3("mounting_rpy_deg", &rig.mounting_rpy_deg);
  camera.get("drop_probability", &rig.drop_probability);
  camera.finish();

  Section traj(top.child("trajectory"), "trajectory");
  TrajectoryConfig& t = s.trajectory;
  std::string kind = trajectoryKindName(t.kind);
  traj.get("kind", &kind);
  t.kind = trajectoryKind(kind);
  traj.get("start_x_m", &t.start_x_m);
  traj.get("start_y_m", &t.start_y_m);
  traj.get("heading_deg", &t.heading_deg);
  traj.get("speed_mps", &t.speed_mps);
  traj.get("acceleration_mps2", &t.acceleration_mps2);
  traj.get("line_length_m", &t.line_length_m);
  traj.get("line_spacing_m", &t.line_spacing_m);
  traj.get("line_count", &t.line_count);
  traj.get("turn_to_starboard", &t.turn_to_starboard);
  traj.get("turn_rate_deg_s", &t.turn_rate_deg_s);
  traj.get("altitude_m", &t.altitude_m);
  traj.get("altitude_variation_m", &t.altitude_variation_m);
  traj.get("altitude_period_s", &t.altitude_period_s);
  traj.get("roll_amplitude_deg", &t.roll_amplitude_deg);
  traj.get("roll_period_s", &t.roll_period_s);
  traj.get("pitch_amplitude_deg", &t.pitch_amplitude_deg);
  traj.get("pitch_period_s", &t.pitch_period_s);
  traj.get("yaw_oscillation_deg", &t.yaw_oscillation_deg);
  traj.get("yaw_period_s", &t.yaw_period_s);
  traj.get("waypoints_csv", &d.waypoints_csv);
  traj.finish();
  d.waypoints_csv = resolvePath(d.waypoints_csv, base_dir);
  if (t.kind == TrajectoryConfig::Kind::kWaypoints) {
    if (d.waypoints_csv.empty())
      throw std::invalid_argument("trajectory.kind is waypoints but trajectory.waypoints_csv is not given");
    try {
      t.waypoints = loadWaypointsCsv(d.waypoints_csv);
    } catch (const std::runtime_error& e) {
      throw std::invalid_argument(std::string("trajectory.waypoints_csv: ") + e.what());
    }
  }

  Section nav(top.child("navigation"), "navigation");
  NavigationSensorConfig& n = s.navigation;
  nav.get("imu_rate_hz", &n.imu_rate_hz);
  nav.get("gyro_noise_rps", &n.gyro_noise_rps);
  nav.get("gyro_bias_rps", &n.gyro_bias_rps);
  nav.get("gyro_bias_walk_rps_sqrt_s", &n.gyro_bias_walk_rps_sqrt_s);
  nav.get("attitude_noise_rad", &n.attitude_noise_rad);
  nav.get("accel_noise_mps2", &n.accel_noise_mps2);
  nav.get("dvl_rate_hz", &n.dvl_rate_hz);
  nav.get("dvl_noise_mps", &n.dvl_noise_mps);
  nav.get("dvl_scale_error", &n.dvl_scale_error);
  nav.get("nav_rate_hz", &n.nav_rate_hz);
  nav.get("dr_sigma_per_m", &n.dr_sigma_per_m);
  nav.get("dr_launch_sigma_m", &n.dr_launch_sigma_m);
  nav.get("heading_alignment_sigma_rad", &n.heading_alignment_sigma_rad);
  nav.get("depth_rate_hz", &n.depth_rate_hz);
  nav.get("depth_noise_m", &n.depth_noise_m);
  nav.get("altimeter_rate_hz", &n.altimeter_rate_hz);
  nav.get("altimeter_noise_m", &n.altimeter_noise_m);
  nav.get("altimeter_max_range_m", &n.altimeter_max_range_m);
  nav.get("usbl_rate_hz", &n.usbl_rate_hz);
  nav.get("usbl_noise_m", &n.usbl_noise_m);
  nav.get("usbl_vertical_noise_m", &n.usbl_vertical_noise_m);
  nav.get("usbl_latency_s", &n.usbl_latency_s);
  nav.get("usbl_outlier_probability", &n.usbl_outlier_probability);
  nav.get("usbl_outlier_scale", &n.usbl_outlier_scale);
  {
    const YAML::Node drops = nav.child("usbl_dropouts_s");
    if (drops && !drops.IsNull()) {
      if (!drops.IsSequence()) throw std::invalid_argument("navigation.usbl_dropouts_s must be a list of [start, end]");
      for (const auto& pair : drops) {
        if (!pair.IsSequence() || pair.size() != 2)
          throw std::invalid_argument("navigation.usbl_dropouts_s: each entry must be [start_s, end_s]");
        n.usbl_dropouts_s.emplace_back(pair[0].as<double>(), pair[1].as<double>());
      }
    }
  }
  nav.finish();

  Section img(top.child("imaging"), "imaging");
  ImagingConfig& im = s.imaging;
  img.get("exposure_gain", &im.exposure_gain);
  img.get("gamma", &im.gamma);
  img.get("light_cone_strength", &im.light_cone_strength);
  img.get("light_half_angle_deg", &im.light_half_angle_deg);
  img.getArray("light_offset_m", &im.light_offset_m);
  img.get("vignetting", &im.vignetting);
  img.getArray("attenuation_per_m", &im.attenuation_per_m);
  img.get("backscatter", &im.backscatter);
  img.getArray("backscatter_colour", &im.backscatter_colour);
  img.get("noise_sigma_dn", &im.noise_sigma_dn);
  img.get("shot_noise_dn", &im.shot_noise_dn);
  img.get("marine_snow_per_m3", &im.marine_snow_per_m3);
  img.get("marine_snow_size_m", &im.marine_snow_size_m);
  img.get("marine_snow_brightness", &im.marine_snow_brightness);
  img.get("marine_snow_sink_mps", &im.marine_snow_sink_mps);
  img.get("motion_blur_exposure_s", &im.motion_blur_exposure_s);
  img.get("motion_blur_samples", &im.motion_blur_samples);
  {
    const YAML::Node segs = img.child("segments");
    if (segs && !segs.IsNull()) {
      if (!segs.IsSequence()) throw std::invalid_argument("imaging.segments must be a list");
      for (size_t i = 0; i < segs.size(); ++i) {
        Section seg(segs[i], "imaging.segments[" + std::to_string(i) + "]");
        WaterSegment w;
        seg.get("start_s", &w.start_s);
        seg.get("end_s", &w.end_s);
        seg.get("turbidity", &w.turbidity);
        seg.get("light_gain", &w.light_gain);
        seg.finish();
        im.segments.push_back(w);
      }
    }
  }
  img.finish();

  Section marks(top.child("landmarks"), "landmarks");
  marks.get("count", &d.landmark_count);
  marks.get("size_m", &d.landmark_size_m);
  marks.get("lateral_offset_m", &d.landmark_lateral_offset_m);
  marks.finish();
  if (d.landmark_count < 0 || d.landmark_count > 10000)
    throw std::invalid_argument("landmarks.count = " + std::to_string(d.landmark_count) + " out of range [0, 10000]");

  Section out(top.child("output"), "output");
  out.get("image_storage", &d.image_storage);
  out.get("jpeg_quality", &d.jpeg_quality);
  out.get("compress_chunks", &d.compress_chunks);
  out.finish();
  top.finish();
  if (d.image_storage != "raw" && d.image_storage != "jpeg" && d.image_storage != "png")
    throw std::invalid_argument("output.image_storage '" + d.image_storage + "' is not one of raw, jpeg, png");
  if (d.jpeg_quality < 1 || d.jpeg_quality > 100)
    throw std::invalid_argument("output.jpeg_quality = " + std::to_string(d.jpeg_quality) + " out of range [1, 100]");
  if (d.seabed.kind != "procedural" && d.seabed.kind != "image")
    throw std::invalid_argument("seabed.kind '" + d.seabed.kind + "' is not one of procedural, image");
  if (d.seabed.kind == "image" && d.seabed.image.empty())
    throw std::invalid_argument("seabed.kind is image but seabed.image (a file path) is not given");
  if (!(d.seabed.relief_scale >= 0.0 && d.seabed.relief_scale <= 2.0))
    throw std::invalid_argument("seabed.relief_scale = " + std::to_string(d.seabed.relief_scale) + " out of range [0, 2]");
  if (d.seabed.objects != "none" && d.seabed.objects != "wreck" && d.seabed.objects != "boulders")
    throw std::invalid_argument("seabed.objects = '" + d.seabed.objects + "' is not one of none, wreck, boulders");
  if (d.seabed.objects != "none" && d.seabed.kind != "procedural")
    throw std::invalid_argument("seabed.objects = '" + d.seabed.objects + "' needs seabed.kind = procedural");
  if (d.seabed.objects_density_per_m2 > 5.0)
    throw std::invalid_argument("seabed.objects_density_per_m2 = " + std::to_string(d.seabed.objects_density_per_m2) +
                                " out of range [0, 5] (negative: the preset's)");

  s.geo = exocet_common::makeGeoReference(d.origin_latitude_deg, d.origin_longitude_deg);
  const std::string problem = s.validate();
  if (!problem.empty()) throw std::invalid_argument(problem);
  if (d.landmark_count > 0) {
    const VehicleTrajectory trajectory(t);
    s.landmarks = landmarksAlongTrajectory(trajectory, d.landmark_count, d.landmark_size_m, d.landmark_lateral_offset_m);
  }
  return d;
}

DiveDescription loadDiveDescription(const std::string& path, const std::vector<std::string>& overrides) {
  std::ifstream in(path);
  if (!in) throw std::invalid_argument("cannot read dive description '" + path + "'");
  std::stringstream ss;
  ss << in.rdbuf();
  const auto slash = path.find_last_of('/');
  const std::string base = slash == std::string::npos ? "." : path.substr(0, slash);
  try {
    return parseDiveDescription(ss.str(), overrides, base);
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(path + ": " + e.what());
  }
}

std::string toYaml(const DiveDescription& d) {
  const DiveSynthesisConfig& s = d.synthesis;
  YAML::Emitter e;
  e.SetDoublePrecision(17);  // round-trips every double: the description reproduces the bag
  auto seq3 = [&](const char* key, const double* v) {
    e << YAML::Key << key << YAML::Value << YAML::Flow << YAML::BeginSeq << v[0] << v[1] << v[2] << YAML::EndSeq;
  };
  e << YAML::BeginMap;
  e << YAML::Key << "seed" << YAML::Value << s.seed;
  e << YAML::Key << "start_time_unix_s" << YAML::Value << s.start_time_unix_s;
  e << YAML::Key << "duration_s" << YAML::Value << s.duration_s;
  e << YAML::Key << "seabed_depth_m" << YAML::Value << s.seabed_depth_m;
  e << YAML::Key << "ground_truth_rate_hz" << YAML::Value << s.ground_truth_rate_hz;
  e << YAML::Key << "threads" << YAML::Value << s.threads;
  e << YAML::Key << "origin" << YAML::Value << YAML::BeginMap << YAML::Key << "latitude_deg" << YAML::Value
    << d.origin_latitude_deg << YAML::Key << "longitude_deg" << YAML::Value << d.origin_longitude_deg << YAML::EndMap;
  e << YAML::Key << "seabed" << YAML::Value << YAML::BeginMap;
  e << YAML::Key << "kind" << YAML::Value << d.seabed.kind << YAML::Key << "texel_m" << YAML::Value << d.seabed.texel_m
    << YAML::Key << "cache_budget_mb" << YAML::Value << d.seabed.cache_budget_mb << YAML::Key << "relief"
    << YAML::Value << d.seabed.relief << YAML::Key << "relief_scale" << YAML::Value << d.seabed.relief_scale
    << YAML::Key << "objects" << YAML::Value << d.seabed.objects << YAML::Key << "objects_density_per_m2"
    << YAML::Value << d.seabed.objects_density_per_m2
    << YAML::Key << "image" << YAML::Value << d.seabed.image << YAML::Key << "image_pixel_size_m" << YAML::Value
    << d.seabed.image_pixel_size_m << YAML::Key << "image_center_x_m" << YAML::Value << d.seabed.image_center_x_m
    << YAML::Key << "image_center_y_m" << YAML::Value << d.seabed.image_center_y_m << YAML::EndMap;
  const CameraRig& r = s.rig;
  e << YAML::Key << "camera" << YAML::Value << YAML::BeginMap;
  e << YAML::Key << "preset" << YAML::Value << d.camera_preset << YAML::Key << "hfov_deg" << YAML::Value
    << d.camera_hfov_deg << YAML::Key << "intrinsics_yaml" << YAML::Value << d.intrinsics_yaml;
  e << YAML::Key << "width" << YAML::Value << r.camera.width << YAML::Key << "height" << YAML::Value << r.camera.height
    << YAML::Key << "fx" << YAML::Value << r.camera.fx << YAML::Key << "fy" << YAML::Value << r.camera.fy << YAML::Key
    << "cx" << YAML::Value << r.camera.cx << YAML::Key << "cy" << YAML::Value << r.camera.cy;
  e << YAML::Key << "distortion" << YAML::Value << YAML::Flow << YAML::BeginSeq;
  for (double k : r.camera.distortion) e << k;
  e << YAML::EndSeq;
  e << YAML::Key << "fps" << YAML::Value << r.fps << YAML::Key << "encoding" << YAML::Value << r.encoding;
  seq3("lever_arm_m", r.lever_arm_m.data());
  seq3("mounting_rpy_deg", r.mounting_rpy_deg.data());
  e << YAML::Key << "drop_probability" << YAML::Value << r.drop_probability << YAML::EndMap;
  const TrajectoryConfig& t = s.trajectory;
  e << YAML::Key << "trajectory" << YAML::Value << YAML::BeginMap;
  e << YAML::Key << "kind" << YAML::Value << trajectoryKindName(t.kind);
  const std::pair<const char*, double> tnums[] = {
      {"start_x_m", t.start_x_m}, {"start_y_m", t.start_y_m}, {"heading_deg", t.heading_deg},
      {"speed_mps", t.speed_mps}, {"acceleration_mps2", t.acceleration_mps2}, {"line_length_m", t.line_length_m},
      {"line_spacing_m", t.line_spacing_m}, {"turn_rate_deg_s", t.turn_rate_deg_s}, {"altitude_m", t.altitude_m},
      {"altitude_variation_m", t.altitude_variation_m}, {"altitude_period_s", t.altitude_period_s},
      {"roll_amplitude_deg", t.roll_amplitude_deg}, {"roll_period_s", t.roll_period_s},
      {"pitch_amplitude_deg", t.pitch_amplitude_deg}, {"pitch_period_s", t.pitch_period_s},
      {"yaw_oscillation_deg", t.yaw_oscillation_deg}, {"yaw_period_s", t.yaw_period_s}};
  for (const auto& kv : tnums) e << YAML::Key << kv.first << YAML::Value << kv.second;
  e << YAML::Key << "line_count" << YAML::Value << t.line_count << YAML::Key << "turn_to_starboard" << YAML::Value
    << t.turn_to_starboard << YAML::Key << "waypoints_csv" << YAML::Value << d.waypoints_csv << YAML::EndMap;
  const NavigationSensorConfig& n = s.navigation;
  e << YAML::Key << "navigation" << YAML::Value << YAML::BeginMap;
  const std::pair<const char*, double> nnums[] = {
      {"imu_rate_hz", n.imu_rate_hz}, {"gyro_noise_rps", n.gyro_noise_rps}, {"gyro_bias_rps", n.gyro_bias_rps},
      {"gyro_bias_walk_rps_sqrt_s", n.gyro_bias_walk_rps_sqrt_s}, {"attitude_noise_rad", n.attitude_noise_rad},
      {"accel_noise_mps2", n.accel_noise_mps2}, {"dvl_rate_hz", n.dvl_rate_hz}, {"dvl_noise_mps", n.dvl_noise_mps},
      {"dvl_scale_error", n.dvl_scale_error}, {"nav_rate_hz", n.nav_rate_hz}, {"dr_sigma_per_m", n.dr_sigma_per_m},
      {"dr_launch_sigma_m", n.dr_launch_sigma_m}, {"heading_alignment_sigma_rad", n.heading_alignment_sigma_rad},
      {"depth_rate_hz", n.depth_rate_hz}, {"depth_noise_m", n.depth_noise_m},
      {"altimeter_rate_hz", n.altimeter_rate_hz}, {"altimeter_noise_m", n.altimeter_noise_m},
      {"altimeter_max_range_m", n.altimeter_max_range_m}, {"usbl_rate_hz", n.usbl_rate_hz},
      {"usbl_noise_m", n.usbl_noise_m}, {"usbl_vertical_noise_m", n.usbl_vertical_noise_m},
      {"usbl_latency_s", n.usbl_latency_s}, {"usbl_outlier_probability", n.usbl_outlier_probability},
      {"usbl_outlier_scale", n.usbl_outlier_scale}};
  for (const auto& kv : nnums) e << YAML::Key << kv.first << YAML::Value << kv.second;
  e << YAML::Key << "usbl_dropouts_s" << YAML::Value << YAML::Flow << YAML::BeginSeq;
  for (const auto& dr : n.usbl_dropouts_s) e << YAML::Flow << YAML::BeginSeq << dr.first << dr.second << YAML::EndSeq;
  e << YAML::EndSeq << YAML::EndMap;
  const ImagingConfig& im = s.imaging;
  e << YAML::Key << "imaging" << YAML::Value << YAML::BeginMap;
  const std::pair<const char*, double> inums[] = {
      {"exposure_gain", im.exposure_gain}, {"gamma", im.gamma}, {"light_cone_strength", im.light_cone_strength},
      {"light_half_angle_deg", im.light_half_angle_deg}, {"vignetting", im.vignetting}, {"backscatter", im.backscatter},
      {"noise_sigma_dn", im.noise_sigma_dn}, {"shot_noise_dn", im.shot_noise_dn},
      {"marine_snow_per_m3", im.marine_snow_per_m3}, {"marine_snow_size_m", im.marine_snow_size_m},
      {"marine_snow_brightness", im.marine_snow_brightness}, {"marine_snow_sink_mps", im.marine_snow_sink_mps},
      {"motion_blur_exposure_s", im.motion_blur_exposure_s}};
  for (const auto& kv : inums) e << YAML::Key << kv.first << YAML::Value << kv.second;
  e << YAML::Key << "motion_blur_samples" << YAML::Value << im.motion_blur_samples;
  seq3("light_offset_m", im.light_offset_m.data());
  seq3("attenuation_per_m", im.attenuation_per_m.data());
  seq3("backscatter_colour", im.backscatter_colour.data());
  e << YAML::Key << "segments" << YAML::Value << YAML::BeginSeq;
  for (const WaterSegment& w : im.segments)
    e << YAML::Flow << YAML::BeginMap << YAML::Key << "start_s" << YAML::Value << w.start_s << YAML::Key << "end_s"
      << YAML::Value << w.end_s << YAML::Key << "turbidity" << YAML::Value << w.turbidity << YAML::Key << "light_gain"
      << YAML::Value << w.light_gain << YAML::EndMap;
  e << YAML::EndSeq << YAML::EndMap;
  e << YAML::Key << "landmarks" << YAML::Value << YAML::BeginMap << YAML::Key << "count" << YAML::Value
    << d.landmark_count << YAML::Key << "size_m" << YAML::Value << d.landmark_size_m << YAML::Key
    << "lateral_offset_m" << YAML::Value << d.landmark_lateral_offset_m << YAML::EndMap;
  e << YAML::Key << "output" << YAML::Value << YAML::BeginMap << YAML::Key << "image_storage" << YAML::Value
    << d.image_storage << YAML::Key << "jpeg_quality" << YAML::Value << d.jpeg_quality << YAML::Key
    << "compress_chunks" << YAML::Value << d.compress_chunks << YAML::EndMap;
  e << YAML::EndMap;
  return std::string(e.c_str()) + "\n";
}

}  // namespace sim
}  // namespace exocet_mosaic
