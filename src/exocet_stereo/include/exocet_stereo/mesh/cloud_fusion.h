/**
 * @file cloud_fusion.h
 * @brief Fusion of the depth maps of all the views around an object into one point cloud (issue 7): each pixel's 3D
 *        point is kept only if enough OTHER depth maps confirm it (it projects there within a relative tolerance of
 *        their depth: multi-view consistency, which removes mismatches that one pair alone cannot see), then the kept
 *        points are merged in a voxel grid, averaging position, colour and a normal taken from the depth map's local
 *        gradient (oriented towards the camera). No ROS.
 */
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <opencv2/core.hpp>

namespace exocet_stereo {
namespace mesh {

/// One calibrated depth map.
struct DepthView {
  Eigen::Matrix3d K = Eigen::Matrix3d::Identity();                   ///< intrinsics of the depth map's camera, pixels
  Eigen::Isometry3d world_T_camera = Eigen::Isometry3d::Identity();  ///< camera (x right, y down, z forward) to world
  cv::Mat depth_m;  ///< CV_32FC1, Z along the optical axis (m); NaN, inf or <= 0 = unknown
  cv::Mat image;    ///< optional CV_8UC1 or CV_8UC3 (BGR) of the same size, for the colours
};

/// Parameters of the fusion. validate() lists every bad field with its allowed range.
struct CloudFusionConfig {
  int min_confirmations = 1;  ///< other views that must confirm a pixel's point, [0, 64] (0: no consistency check)
  /// A view confirms a point whose depth in it is within this fraction of its depth map's value there, (0, 1].
  double depth_tolerance = 0.01;
  double voxel_m = 0.002;  ///< edge of the merging voxels, (0, 1e3]
  int step_px = 1;         ///< every step-th pixel in x and y is a candidate, [1, 64]
  /// The normal is the cross product of the central differences over +-normal_radius_px, [1, 16].
  int normal_radius_px = 1;
  /// A pixel whose gradient neighbours differ from its depth by more than this fraction is on a depth discontinuity
  /// (a silhouette, where stereo mixes foreground and background) and is dropped, (0, 10].
  double max_relative_depth_step = 0.03;
  /// Pixels whose surface is seen more obliquely than this (angle between the normal and the ray) are dropped: their
  /// stereo depth is the least accurate, [0, 90] degrees.
  double max_incidence_deg = 80.0;
  int min_samples_per_voxel = 1;  ///< voxels that merged fewer pixels are dropped, [1, 1000000]
  /// Empty if usable, otherwise every bad field with its allowed range ("; "-joined).
  std::string validate() const;
};

/// The fused cloud, one entry per kept voxel (world frame).
struct FusedCloud {
  std::vector<Eigen::Vector3d> points;   ///< mean position of the voxel's pixels
  std::vector<Eigen::Vector3d> normals;  ///< unit, mean of the pixels' normals (towards the cameras that saw them)
  std::vector<cv::Vec3b> colors;         ///< RGB mean; empty when no view has an image
  std::vector<int> confirmations;        ///< largest number of other views confirming one of the voxel's pixels
  std::vector<int> samples;              ///< pixels merged into the voxel

  size_t size() const { return points.size(); }
  /// The entries whose point lies inside the axis-aligned box [min_m, max_m] (e.g. around the object).
  FusedCloud cropped(const Eigen::Vector3d& min_m, const Eigen::Vector3d& max_m) const;
};

/// What the fusion kept and dropped.
struct CloudFusionStats {
  long candidates = 0;     ///< pixels with a known depth (on the step grid)
  long discontinuity = 0;  ///< dropped by max_relative_depth_step or a missing gradient neighbour
  long oblique = 0;        ///< dropped by max_incidence_deg
  long unconfirmed = 0;    ///< dropped by min_confirmations
  long fused_pixels = 0;   ///< kept and merged
  long sparse_voxels = 0;  ///< voxels dropped by min_samples_per_voxel
};

/**
 * @brief Fuses the depth maps. Confirmation of a point X of view i by view j: X projects inside j in front of it at
 *        depth z, and j's depth there (bilinear when its 4 neighbours are known and smooth, nearest otherwise) is
 *        within depth_tolerance * z. Parallel over rows (cv::parallel_for_).
 * @throws std::invalid_argument on an invalid config (message lists the fields), an empty or non-CV_32FC1 depth map,
 *         an image of another size or type, or a K that is not invertible.
 */
FusedCloud fuseDepthMaps(const std::vector<DepthView>& views, const CloudFusionConfig& config,
                         CloudFusionStats* stats = nullptr);

}  // namespace mesh
}  // namespace exocet_stereo
