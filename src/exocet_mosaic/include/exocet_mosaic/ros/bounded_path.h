/**
 * @file bounded_path.h
 * @brief A nav_msgs/Path for display whose size stays bounded on a dive of any length, at one resolution from its
 * start to its end.
 *
 * The kept poses are at least spacing_m apart; the newest pose is always the path's last (it replaces a last pose
 * that is still closer than spacing_m to the one before it), so the path ends where the vehicle is. When the path
 * would exceed max_poses, every other pose is dropped (the first and the newest stay) and the spacing doubles: the
 * whole path keeps one density instead of an exponentially thinner past. An hour's survey of about 2 km fits in 5000
 * poses at 0.4 m.
 */
#pragma once

#include <nav_msgs/Path.h>
#include <ros/time.h>
#include <Eigen/Core>

namespace exocet_mosaic {

class BoundedPath {
 public:
  /// @param min_spacing_m spacing of the kept poses until the first thinning, >= 0
  /// @param max_poses poses at most, >= 3
  /// @param frame_id the path's and its poses' frame
  /// @throws std::invalid_argument for a value out of range.
  BoundedPath(double min_spacing_m, int max_poses, const std::string& frame_id);

  /// Adds the position (z 0, identity orientation) at the stamp; the path's stamp becomes it.
  void append(const ros::Time& stamp, const Eigen::Vector2d& position_m);
  /// Empties the path and returns to min_spacing_m.
  void clear();

  const nav_msgs::Path& path() const { return path_; }
  /// Spacing of the poses kept from now on (min_spacing_m times 2 per thinning so far).
  double spacingM() const { return spacing_m_; }

 private:
  double min_spacing_m_, spacing_m_;
  int max_poses_;
  nav_msgs::Path path_;
};

}  // namespace exocet_mosaic
