/**
 * @file pair_depth.h
 * @brief One calibrated stereo pair to a depth map in the world: the rig from the two cameras' intrinsics and poses,
 * rectification, dense stereo restricted to the disparities of a depth range, the depth map of the rectified left
 * camera with its pose. The step each pair of an acquisition goes through before the depth maps are fused
 * (cloud_fusion.h). No ROS.
 */
#pragma once

#include <string>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "exocet_stereo/mesh/cloud_fusion.h"

namespace exocet_stereo {
namespace mesh {

/// A stereo pair with its calibration and poses.
struct CalibratedPair {
  cv::Mat left, right;  ///< 8-bit gray or BGR, same size
  Eigen::Matrix3d K_left = Eigen::Matrix3d::Identity(), K_right = Eigen::Matrix3d::Identity();  ///< no distortion
  Eigen::Isometry3d world_T_left = Eigen::Isometry3d::Identity();   ///< camera (x right, y down, z forward)
  Eigen::Isometry3d world_T_right = Eigen::Isometry3d::Identity();
};

/// Parameters; validate() lists every bad field with its allowed range.
struct PairDepthConfig {
  std::string method = "sgm";  ///< a dense method of dense/dense_stereo.h (ssd, dp, so, sgm, gc, bd, sgbm)
  double min_depth_m = 0.2;    ///< depth range searched, in the rectified left camera, (0, max_depth_m)
  double max_depth_m = 2.0;    ///< (min_depth_m, 1e4]
  std::string validate() const;
};

/// What one pair gave.
struct PairDepthStats {
  int disparities_px = 0;   ///< searched
  int offset_px = 0;        ///< smallest disparity searched (the right image is shifted by it)
  long depth_pixels = 0;    ///< pixels with a depth
  double baseline_m = 0.0;  ///< of the rectified pair
};

/**
 * @brief Rectifies the pair (alpha -1: the focal length is kept), computes the left disparity with `method` over the
 * disparities of [min_depth_m, max_depth_m] (winners at the ends of the range are points outside it: unknown;
 * holes are not filled: a filled disparity is no measurement) and returns the rectified left camera's depth map,
 * intrinsics, pose and image.
 * @throws std::invalid_argument for an invalid config, images of different sizes, or coincident camera centres.
 */
DepthView depthFromPair(const CalibratedPair& pair, const PairDepthConfig& config, PairDepthStats* stats = nullptr);

}  // namespace mesh
}  // namespace exocet_stereo
