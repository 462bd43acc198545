#include "exocet_stereo/geometry/similarity_alignment.h"

#include <stdexcept>
#include <string>

#include <Eigen/Geometry>

namespace exocet_stereo {
namespace geometry {

Similarity alignSimilarity(const std::vector<Eigen::Vector3d>& source, const std::vector<Eigen::Vector3d>& target) {
  if (source.size() != target.size() || source.size() < 3)
    throw std::invalid_argument("alignSimilarity: needs two lists of the same length >= 3, got " +
                                std::to_string(source.size()) + " and " + std::to_string(target.size()));
  Eigen::Matrix3Xd src(3, source.size()), dst(3, target.size());
  for (size_t i = 0; i < source.size(); ++i) {
    src.col(i) = source[i];
    dst.col(i) = target[i];
  }
  const Eigen::Matrix4d T = Eigen::umeyama(src, dst, true);
  Similarity S;
  S.scale = T.topLeftCorner<3, 3>().col(0).norm();
  S.R = T.topLeftCorner<3, 3>() / S.scale;
  S.t = T.topRightCorner<3, 1>();
  return S;
}

std::vector<double> alignedErrors(const Similarity& S, const std::vector<Eigen::Vector3d>& source,
                                  const std::vector<Eigen::Vector3d>& target) {
  std::vector<double> errors;
  for (size_t i = 0; i < source.size() && i < target.size(); ++i)
    errors.push_back((S.apply(source[i]) - target[i]).norm());
  return errors;
}

}  // namespace geometry
}  // namespace exocet_stereo
