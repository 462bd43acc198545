#include "exocet_mosaic/ros/bounded_path.h"

#include <cmath>
#include <sstream>
#include <stdexcept>

namespace exocet_mosaic {

BoundedPath::BoundedPath(double min_spacing_m, int max_poses, const std::string& frame_id)
    : min_spacing_m_(min_spacing_m), spacing_m_(min_spacing_m), max_poses_(max_poses) {
  std::ostringstream err;
  if (!(min_spacing_m >= 0.0) || !std::isfinite(min_spacing_m))
    err << "path spacing " << min_spacing_m << " m out of range [0, inf); ";
  if (max_poses < 3) err << "path max poses " << max_poses << " out of range [3, inf); ";
  if (!err.str().empty()) throw std::invalid_argument("BoundedPath: " + err.str());
  path_.header.frame_id = frame_id;
}

void BoundedPath::append(const ros::Time& stamp, const Eigen::Vector2d& position_m) {
  geometry_msgs::PoseStamped pose;
  pose.header.stamp = stamp;
  pose.header.frame_id = path_.header.frame_id;
  pose.pose.position.x = position_m.x();
  pose.pose.position.y = position_m.y();
  pose.pose.orientation.w = 1.0;
  path_.header.stamp = stamp;
  std::vector<geometry_msgs::PoseStamped>& poses = path_.poses;
  const size_t n = poses.size();
  if (n >= 2) {
    // The last pose follows the newest position while it lies within a spacing of the one before it.
    const geometry_msgs::Point& a = poses[n - 2].pose.position;
    const geometry_msgs::Point& b = poses[n - 1].pose.position;
    if (std::hypot(b.x - a.x, b.y - a.y) < spacing_m_) {
      poses.back() = pose;
      return;
    }
  }
  poses.push_back(pose);
  if (static_cast<int>(poses.size()) <= max_poses_) return;
  std::vector<geometry_msgs::PoseStamped> thinned;
  thinned.reserve(static_cast<size_t>(max_poses_) + 1);
  for (size_t i = 0; i + 1 < poses.size(); i += 2) thinned.push_back(poses[i]);
  thinned.push_back(poses.back());
  poses.swap(thinned);
  spacing_m_ = spacing_m_ > 0.0 ? 2.0 * spacing_m_ : 0.0;
}

void BoundedPath::clear() {
  path_.poses.clear();
  spacing_m_ = min_spacing_m_;
}

}  // namespace exocet_mosaic
