/**
 * @file surface_texturing.h
 * @brief Multi-view texture mapping of a surface mesh (after Lempitsky & Ivanov 2007 and Waechter et al. 2014, in a
 *        simple form): each triangle takes its texture from ONE of the calibrated images that see it. A view is a
 *        candidate for a triangle when the three vertices project inside its image, the triangle faces it, and the
 *        mesh itself does not hide it there (z-buffer of the mesh rasterised into the view: independent of the holes
 *        of any depth map). The best candidate is the largest projected area (resolution and obliqueness together);
 *        a few ICM passes of a Potts smoothing over the triangle adjacency then trade a little of that score for
 *        fewer seams. The used images are tiled into ONE atlas (so TexturedMesh and its exporters are unchanged),
 *        optionally with one gain per view so that overlapping views agree in mean intensity. No ROS.
 */
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "exocet_stereo/mesh/textured_mesh.h"

namespace exocet_stereo {
namespace mesh {

/// One image to take texture from: a pinhole camera without distortion.
struct TextureView {
  cv::Mat image;                                                     ///< CV_8UC1 or CV_8UC3 (BGR)
  Eigen::Matrix3d K = Eigen::Matrix3d::Identity();                   ///< intrinsics, pixels
  Eigen::Isometry3d world_T_camera = Eigen::Isometry3d::Identity();  ///< camera (x right, y down, z forward) to world
};

/// Parameters; validate() lists every bad field with its allowed range.
struct SurfaceTexturingConfig {
  /// A view sees a triangle only if the angle between the triangle's normal and the direction to the camera is below
  /// this, (0, 90) degrees.
  double max_angle_deg = 75.0;
  /// The three vertices must project at least this far inside the image (bilinear sampling stays inside), [0, 1000].
  double margin_px = 2.0;
  bool check_occlusion = true;  ///< z-buffer the mesh into each view (off: for comparisons only)
  /// A triangle is hidden in a view when its centroid is farther than the z-buffer there by more than this fraction
  /// of its depth, (0, 1].
  double occlusion_tolerance = 0.02;
  /// Potts weight: cost of a label = -score / best score of the triangle + lambda x neighbours labelled otherwise,
  /// [0, 100] (0: best view per triangle, no smoothing).
  double smoothing_lambda = 0.25;
  int icm_passes = 5;  ///< passes of iterated conditional modes over the triangles, [0, 100]
  /// The images are downscaled by this factor in the atlas, (0, 1]; lowered further when the atlas would exceed
  /// max_atlas_side_px.
  double atlas_scale = 1.0;
  int max_atlas_side_px = 8192;  ///< width and height of the atlas at most, [256, 32768]
  /// One gain per used view, least squares over the pairs of views on the vertices both see, so that they agree in
  /// mean intensity (lighting differences make seams otherwise); the median gain over the triangles is 1.
  bool adjust_gains = true;
  /// Colour (RGB) of the triangles no view sees, when the mesh has no vertex colours (otherwise their mean).
  cv::Vec3b untextured_rgb = cv::Vec3b(128, 128, 128);
  /// Empty if usable, otherwise every bad field with its allowed range ("; "-joined).
  std::string validate() const;
};

/// What the texturing did.
struct SurfaceTexturingStats {
  long textured_triangles = 0;    ///< taken from a view
  long untextured_triangles = 0;  ///< seen by no view: flat colour
  int views_used = 0;             ///< views with at least one triangle (tiles of the atlas)
  int atlas_width_px = 0;
  int atlas_height_px = 0;
  double atlas_scale = 0.0;              ///< the downscaling applied to the images in the atlas
  long seam_edges = 0;                   ///< edges between two textured triangles taken from different views
  int icm_changes = 0;                   ///< labels changed by the smoothing
  std::vector<long> triangles_per_view;  ///< one per input view
  std::vector<double> gains;             ///< one per input view (1 when not adjusted or unused)
};

/**
 * @brief Textures a surface from calibrated views. The result has the surface's triangles in the same order and
 *        winding, with their corners DUPLICATED (vertex 3 i + k is corner k of triangle i) so that each triangle has
 *        its own texture coordinates; one atlas image (BGR, or grey when every used image is grey); per-vertex
 *        colours (RGB) sampled from the atlas, so viewers without texture show the same colours.
 *        Triangles must face their cameras (counter-clockwise seen from outside: surfaceFromCloud()'s convention).
 * @param triangle_views when not null, receives for each triangle the index of its view, -1 when untextured.
 * @throws std::invalid_argument on an invalid config (the message lists the fields), an empty or inconsistent mesh,
 *         no view, an image that is empty or not 8-bit with 1 or 3 channels, or a K that is not invertible.
 */
TexturedMesh textureSurface(const TexturedMesh& surface, const std::vector<TextureView>& views,
                            const SurfaceTexturingConfig& config, SurfaceTexturingStats* stats = nullptr,
                            std::vector<int>* triangle_views = nullptr);

}  // namespace mesh
}  // namespace exocet_stereo
