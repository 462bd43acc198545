#include "exocet_stereo/geometry/pinhole_view.h"

#include <fstream>
#include <sstream>
#include <stdexcept>

namespace exocet_stereo {
namespace geometry {

Projection PinholeView::projection() const {
  Projection P;
  P.leftCols<3>() = K * R;
  P.col(3) = K * t;
  return P;
}

Eigen::Vector2d PinholeView::project(const Eigen::Vector3d& X) const {
  const Eigen::Vector3d x = K * (R * X + t);
  return x.head<2>() / x.z();
}

std::vector<PinholeView> readMiddleburyViews(const std::string& par_path) {
  std::ifstream in(par_path);
  if (!in) throw std::runtime_error("readMiddleburyViews: cannot open '" + par_path + "'");
  int count = 0;
  if (!(in >> count) || count < 1 || count > 100000)
    throw std::runtime_error("readMiddleburyViews: '" + par_path + "' must start with the view count in [1, 100000]");
  std::vector<PinholeView> views;
  std::string line;
  std::getline(in, line);
  for (int i = 0; i < count; ++i) {
    if (!std::getline(in, line))
      throw std::runtime_error("readMiddleburyViews: '" + par_path + "' announces " + std::to_string(count) +
                               " views but has " + std::to_string(i));
    std::istringstream fields(line);
    PinholeView view;
    fields >> view.name;
    double v[21];
    for (double& value : v) fields >> value;
    if (!fields)
      throw std::runtime_error("readMiddleburyViews: line " + std::to_string(i + 2) + " of '" + par_path +
                               "' must hold a name and 21 numbers (K, R row-major, t)");
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) {
        view.K(r, c) = v[3 * r + c];
        view.R(r, c) = v[9 + 3 * r + c];
      }
    view.t = Eigen::Vector3d(v[18], v[19], v[20]);
    views.push_back(view);
  }
  return views;
}

}  // namespace geometry
}  // namespace exocet_stereo
