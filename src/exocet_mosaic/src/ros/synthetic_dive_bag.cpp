#include "exocet_mosaic/ros/synthetic_dive_bag.h"

#include <cmath>
#include <iomanip>
#include <sstream>
#include <stdexcept>

#include "exocet_mosaic/ros/dive_bag_writer.h"
#include "exocet_mosaic/ros/dive_topics.h"
#include "exocet_common/atomic_file.h"
#include "exocet_common/geo_reference.h"
#include "exocet_mosaic/sim/image_seabed.h"

namespace exocet_mosaic {

namespace {

std::string csvNumber(double v, int precision) {
  std::ostringstream ss;
  ss << std::fixed << std::setprecision(precision) << v;
  return ss.str();
}

}  // namespace

SyntheticDiveSummary writeSyntheticDive(const sim::DiveDescription& dive, const std::string& output,
                                        const std::function<void(int frames_done, int frames_total)>& progress) {
  using namespace sim;
  if (output.size() < 5 || output.substr(output.size() - 4) != ".bag")
    throw std::invalid_argument("--output '" + output + "' must end in .bag");
  const std::string base = output.substr(0, output.size() - 4);
  const std::string writable = exocet_common::checkWritableDestination(output);
  if (!writable.empty()) throw std::runtime_error(writable);

  Seabed seabed = makeSeabed(dive.seabed, dive.synthesis.seed);
  DiveSynthesizer synth(dive.synthesis, seabed.texture.get(), seabed.relief.get());
  const DiveSynthesisConfig& cfg = dive.synthesis;
  if (const auto* picture = dynamic_cast<const ImageSeabed*>(seabed.texture.get())) {
    // A picture ends somewhere: refuse a dive that would film past its edge rather than render filler.
    for (double t = 0.0; t <= synth.duration_s() + 1e-9; t += 0.5) {
      if (!picture->covers(synth.footprintOnReferencePlane(t)))
        throw std::invalid_argument("the camera leaves the seabed image '" + dive.seabed.image +
                                    "' at t = " + std::to_string(t) +
                                    " s: enlarge seabed.image_pixel_size_m, move "
                                    "seabed.image_center_x_m/_y_m or shorten the trajectory");
    }
  }

  DiveBagWriter::Options options;
  options.image_storage = parseImageStorage(dive.image_storage);
  options.jpeg_quality = dive.jpeg_quality;
  options.compress_chunks = dive.compress_chunks;
  DiveBagWriter writer(output, options);
  writer.writeDatum(cfg.geo, cfg.start_time_unix_s);
  dive::StaticTransform camera{frames::kBaseLink, frames::kCameraOptical, cfg.rig.baseFromCamera()};
  dive::StaticTransform altimeter{frames::kBaseLink, frames::kAltimeter, Eigen::Isometry3d::Identity()};
  altimeter.parent_from_child.linear() = Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitY()).toRotationMatrix();
  dive::StaticTransform usbl{frames::kBaseLink, frames::kUsbl, Eigen::Isometry3d::Identity()};
  writer.writeStaticTransforms({camera, altimeter, usbl}, cfg.start_time_unix_s);

  std::ostringstream truth_csv;
  truth_csv << "frame,stamp_s,dropped,easting_m,northing_m,up_m,roll_deg,pitch_deg,yaw_deg,cam_easting_m,"
               "cam_northing_m,cam_up_m,cam_qx,cam_qy,cam_qz,cam_qw,camera_altitude_m,gsd_m,latitude_deg,"
               "longitude_deg,depth_m\n";
  DiveSink sink;
  sink.navigation.imu = [&](const dive::ImuRecord& r) { writer.writeImu(r); };
  sink.navigation.dvl = [&](const dive::DvlRecord& r) { writer.writeDvl(r); };
  sink.navigation.dead_reckoning = [&](const dive::PoseRecord& r) { writer.writeNavOdometry(r); };
  sink.navigation.depth = [&](const dive::DepthRecord& r) { writer.writeDepth(r); };
  sink.navigation.altitude = [&](const dive::AltitudeRecord& r) { writer.writeAltitude(r); };
  sink.navigation.usbl = [&](const dive::FixRecord& r) { writer.writeUsbl(r); };
  sink.ground_truth = [&](const dive::PoseRecord& r) { writer.writeGroundTruth(r); };
  // Compression on the rendering threads: JPEG encoding would otherwise queue on the one thread that writes.
  sink.prepare_frame = [&writer](FrameTruth* f) { writer.compressFrame(&f->frame); };
  sink.frame = [&](const FrameTruth& f) {
    if (!f.dropped) writer.writeCameraFrame(f.frame, cfg.rig.camera);
    writer.writeGroundTruthCamera(f.frame.stamp_s, f.world_from_camera, f.camera_altitude_m);
    const VehicleState& v = f.vehicle;
    const Eigen::Vector3d base_m = synth.toWorld(v.position_m);
    const Eigen::Vector3d cam = f.world_from_camera.translation();
    const Eigen::Quaterniond q(f.world_from_camera.rotation());
    truth_csv << f.frame.index << ',' << csvNumber(f.frame.stamp_s, 6) << ',' << (f.dropped ? 1 : 0) << ','
              << csvNumber(base_m.x(), 4) << ',' << csvNumber(base_m.y(), 4) << ',' << csvNumber(base_m.z(), 4) << ','
              << csvNumber(v.roll_rad * 180 / M_PI, 5) << ',' << csvNumber(v.pitch_rad * 180 / M_PI, 5) << ','
              << csvNumber(v.yaw_rad * 180 / M_PI, 5) << ',' << csvNumber(cam.x(), 4) << ',' << csvNumber(cam.y(), 4)
              << ',' << csvNumber(cam.z(), 4) << ',' << csvNumber(q.x(), 9) << ',' << csvNumber(q.y(), 9) << ','
              << csvNumber(q.z(), 9) << ',' << csvNumber(q.w(), 9) << ',' << csvNumber(f.camera_altitude_m, 5) << ','
              << csvNumber(f.ground_sample_distance_m, 7) << ',' << csvNumber(f.latlon_deg.x(), 9) << ','
              << csvNumber(f.latlon_deg.y(), 9) << ',' << csvNumber(-base_m.z(), 4) << '\n';
  };
  sink.progress = progress;
  synth.run(sink);

  std::ostringstream marks_csv;
  marks_csv << "id,x_m,y_m,easting_m,northing_m,up_m,latitude_deg,longitude_deg,size_m\n";
  for (const Landmark& m : synth.renderer().landmarks()) {
    const Eigen::Vector3d w = synth.toWorld(Eigen::Vector3d(m.x_m, m.y_m, seabed.relief->heightAt_m(m.x_m, m.y_m)));
    const Eigen::Vector2d ll = exocet_common::gridToLatLon(cfg.geo, w.x(), w.y());
    marks_csv << m.id << ',' << csvNumber(m.x_m, 4) << ',' << csvNumber(m.y_m, 4) << ',' << csvNumber(w.x(), 4) << ','
              << csvNumber(w.y(), 4) << ',' << csvNumber(w.z(), 4) << ',' << csvNumber(ll.x(), 9) << ','
              << csvNumber(ll.y(), 9) << ',' << csvNumber(m.size_m, 3) << '\n';
  }
  exocet_common::writeFileAtomically(base + ".ground_truth.csv", truth_csv.str());
  exocet_common::writeFileAtomically(base + ".landmarks.csv", marks_csv.str());
  exocet_common::writeFileAtomically(base + ".config.yaml",
                      "# Written by dive_synth: the complete description of " + output +
                          "\n# Reproduce with: dive_synth --config THIS_FILE --output OUT.bag\n" + toYaml(dive));
  writer.commit();
  SyntheticDiveSummary summary;
  summary.frames = synth.frameCount();
  summary.duration_s = synth.duration_s();
  summary.messages = writer.messageCount();
  summary.epsg = cfg.geo.epsg;
  return summary;
}

}  // namespace exocet_mosaic
