// Test fixtures of the loop closure: a small downward camera, true vehicle poses and a procedural seabed rendered
// under a lamp (test_loop_closure, test_loop_closer).
#pragma once

#include <cmath>
#include <memory>
#include <vector>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "exocet_common/camera_model.h"
#include "exocet_mosaic/graph/loop_candidates.h"
#include "exocet_mosaic/graph/loop_verifier.h"
#include "exocet_mosaic/graph/pose_graph.h"
#include "exocet_mosaic/sim/imaging_config.h"
#include "exocet_mosaic/sim/procedural_seabed.h"
#include "exocet_mosaic/sim/seabed_renderer.h"
#include "exocet_mosaic/sim/seabed_texture.h"

namespace exocet_mosaic {
namespace graph {
namespace testing {

inline FootprintCamera smallCamera() {
  FootprintCamera c;
  c.width_px = 384;
  c.height_px = 288;
  c.fx_px = c.fy_px = 0.5 * 384 / std::tan(30.0 * M_PI / 180.0);  // 60 deg horizontal field of view
  c.cx_px = 192;
  c.cy_px = 144;
  return c;
}


inline exocet_common::CameraModel renderCamera() {
  exocet_common::CameraModel c;
  const FootprintCamera f = smallCamera();
  c.width = f.width_px;
  c.height = f.height_px;
  c.fx = f.fx_px;
  c.fy = f.fy_px;
  c.cx = f.cx_px;
  c.cy = f.cy_px;
  return c;
}

/// A vehicle pose: camera centre (local x east, y north), height, yaw (ENU), roll and pitch of base_link.
struct TruePose {
  double e_m, n_m, height_m, yaw_rad, roll_rad = 0.0, pitch_rad = 0.0;
  Eigen::Matrix3d levelFromBase() const {
    return (Eigen::AngleAxisd(pitch_rad, Eigen::Vector3d::UnitY()) *
            Eigen::AngleAxisd(roll_rad, Eigen::Vector3d::UnitX()))
        .toRotationMatrix();
  }
  /// The simulator's camera: base_link -> camera optical, image top forward, image x to starboard.
  Eigen::Isometry3d localFromCamera() const {
    Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
    t.linear() = Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix() * levelFromBase() *
                 downwardLevelFromCamera().toRotationMatrix();
    t.translation() = Eigen::Vector3d(e_m, n_m, height_m);
    return t;
  }
  /// What the verifier is told: the view from the true local_from_camera, with the yaw removed.
  LoopView view() const {
    const Eigen::Isometry3d local_from_camera = localFromCamera();
    LoopView v;
    const exocet_common::CameraModel c = renderCamera();
    v.camera_matrix << c.fx, 0, c.cx, 0, c.fy, c.cy, 0, 0, 1;
    v.image_size = cv::Size(c.width, c.height);
    v.camera_height_m = local_from_camera.translation().z();  // flat seabed at z = 0
    v.level_from_camera = Eigen::Quaterniond(Eigen::AngleAxisd(-yaw_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix() *
                                             local_from_camera.linear());
    return v;
  }
  Pose2d pose2d() const {
    const Eigen::Isometry3d t = localFromCamera();
    return Pose2d{t.translation().head<2>(), yaw_rad};
  }
};

/// A procedural seabed and a renderer of a small camera over it.
struct Scene {
  std::unique_ptr<sim::ProceduralSeabedTexture> texture;
  sim::FlatRelief relief;
  std::unique_ptr<sim::SeabedRenderer> renderer;
  Scene(const sim::ProceduralSeabedConfig& seabed, const sim::ImagingConfig& imaging) {
    texture = std::make_unique<sim::ProceduralSeabedTexture>(seabed);
    renderer = std::make_unique<sim::SeabedRenderer>(renderCamera(), imaging, texture.get(), &relief,
                                                     std::vector<sim::Landmark>(), seabed.seed, 2.5);
  }
  cv::Mat render(const TruePose& p, int frame) const {
    const Eigen::Isometry3d pose = p.localFromCamera();
    return renderer->render([&](double) { return pose; }, frame * 0.2, frame, "mono8");
  }
};

inline sim::ImagingConfig murkyLamp() {
  sim::ImagingConfig imaging;
  imaging.light_cone_strength = 0.6;  // the lamp ahead of the camera: a revisit at 180 deg is lit from the other side
  imaging.vignetting = 0.3;
  imaging.attenuation_per_m = {{0.25, 0.08, 0.06}};
  imaging.backscatter = 0.1;
  imaging.noise_sigma_dn = 1.5;
  return imaging;
}

}  // namespace testing
}  // namespace graph
}  // namespace exocet_mosaic
