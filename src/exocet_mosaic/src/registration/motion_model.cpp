#include "exocet_mosaic/registration/motion_model.h"

#include <cmath>
#include <stdexcept>

#include <Eigen/Dense>

namespace exocet_mosaic {
namespace registration {

std::string toString(MotionModel model) {
  switch (model) {
    case MotionModel::kTranslation:
      return "translation";
    case MotionModel::kSimilarity:
      return "similarity";
    case MotionModel::kAffine:
      return "affine";
    case MotionModel::kHomography:
      return "homography";
  }
  return "unknown";
}

MotionModel motionModelFromString(const std::string& name) {
  if (name == "translation") return MotionModel::kTranslation;
  if (name == "similarity") return MotionModel::kSimilarity;
  if (name == "affine") return MotionModel::kAffine;
  if (name == "homography") return MotionModel::kHomography;
  throw std::invalid_argument("motion model '" + name + "': allowed values are translation, similarity, affine, " +
                              "homography");
}

int parameterCount(MotionModel model) {
  switch (model) {
    case MotionModel::kTranslation:
      return 2;
    case MotionModel::kSimilarity:
      return 4;
    case MotionModel::kAffine:
      return 6;
    case MotionModel::kHomography:
      return 8;
  }
  return 0;
}

namespace {

void checkSize(MotionModel model, const Eigen::VectorXd& parameters) {
  if (parameters.size() != parameterCount(model))
    throw std::invalid_argument(toString(model) + " motion needs " + std::to_string(parameterCount(model)) +
                                " parameters, got " + std::to_string(parameters.size()));
}

Eigen::Matrix3d centring(const Eigen::Vector2d& centre_px) {
  Eigen::Matrix3d t = Eigen::Matrix3d::Identity();
  t(0, 2) = -centre_px.x();
  t(1, 2) = -centre_px.y();
  return t;
}

}  // namespace

Eigen::Matrix3d centredMatrix(MotionModel model, const Eigen::VectorXd& p) {
  checkSize(model, p);
  Eigen::Matrix3d m = Eigen::Matrix3d::Identity();
  m(0, 2) = p[0];
  m(1, 2) = p[1];
  switch (model) {
    case MotionModel::kTranslation:
      break;
    case MotionModel::kSimilarity:
      m(0, 0) = 1.0 + p[2];
      m(0, 1) = -p[3];
      m(1, 0) = p[3];
      m(1, 1) = 1.0 + p[2];
      break;
    case MotionModel::kAffine:
    case MotionModel::kHomography:
      m(0, 0) = 1.0 + p[2];
      m(0, 1) = p[3];
      m(1, 0) = p[4];
      m(1, 1) = 1.0 + p[5];
      if (model == MotionModel::kHomography) {
        m(2, 0) = p[6];
        m(2, 1) = p[7];
      }
      break;
  }
  return m;
}

Eigen::Matrix3d pixelMatrix(MotionModel model, const Eigen::VectorXd& parameters, const Eigen::Vector2d& centre_px) {
  const Eigen::Matrix3d c = centring(centre_px);
  return c.inverse() * centredMatrix(model, parameters) * c;
}

Eigen::Vector2d transferPoint(const Eigen::Matrix3d& h, const Eigen::Vector2d& x) {
  const Eigen::Vector3d y = h * Eigen::Vector3d(x.x(), x.y(), 1.0);
  return y.head<2>() / y.z();
}

Eigen::VectorXd parametersFromPixelMatrix(MotionModel model, const Eigen::Matrix3d& pixel_matrix,
                                          const Eigen::Vector2d& centre_px, int width, int height) {
  const Eigen::Matrix3d c = centring(centre_px);
  Eigen::Matrix3d m = c * pixel_matrix * c.inverse();
  m /= m(2, 2);
  Eigen::VectorXd p(parameterCount(model));
  if (model == MotionModel::kHomography) {
    p << m(0, 2), m(1, 2), m(0, 0) - 1.0, m(0, 1), m(1, 0), m(1, 1) - 1.0, m(2, 0), m(2, 1);
    return p;
  }
  // Linear models: least squares on the matrix's action over a grid of the image (exact when m is in the model).
  const int n = 9;
  Eigen::MatrixXd a(2 * n * n, p.size());
  Eigen::VectorXd b(2 * n * n);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(p.size());
  int row = 0;
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      const double u = (width - 1) * (i / double(n - 1)) - centre_px.x() + 0.0;
      const double v = (height - 1) * (j / double(n - 1)) - centre_px.y();
      const Eigen::Vector3d w = m * Eigen::Vector3d(u, v, 1.0);
      a.middleRows(row, 2) = warpJacobian(model, zero, u, v);
      b[row] = w.x() / w.z() - u;
      b[row + 1] = w.y() / w.z() - v;
      row += 2;
    }
  }
  p = a.colPivHouseholderQr().solve(b);
  return p;
}

Eigen::MatrixXd warpJacobian(MotionModel model, const Eigen::VectorXd& p, double u, double v) {
  checkSize(model, p);
  Eigen::MatrixXd j = Eigen::MatrixXd::Zero(2, parameterCount(model));
  j(0, 0) = 1.0;
  j(1, 1) = 1.0;
  switch (model) {
    case MotionModel::kTranslation:
      break;
    case MotionModel::kSimilarity:
      j(0, 2) = u;
      j(0, 3) = -v;
      j(1, 2) = v;
      j(1, 3) = u;
      break;
    case MotionModel::kAffine:
      j(0, 2) = u;
      j(0, 3) = v;
      j(1, 4) = u;
      j(1, 5) = v;
      break;
    case MotionModel::kHomography: {
      const Eigen::Matrix3d m = centredMatrix(model, p);
      const double xn = m(0, 0) * u + m(0, 1) * v + m(0, 2);
      const double yn = m(1, 0) * u + m(1, 1) * v + m(1, 2);
      const double w = m(2, 0) * u + m(2, 1) * v + 1.0;
      const double xw = xn / w, yw = yn / w;
      j(0, 0) = 1.0 / w;
      j(1, 1) = 1.0 / w;
      j(0, 2) = u / w;
      j(0, 3) = v / w;
      j(1, 4) = u / w;
      j(1, 5) = v / w;
      j(0, 6) = -xw * u / w;
      j(0, 7) = -xw * v / w;
      j(1, 6) = -yw * u / w;
      j(1, 7) = -yw * v / w;
      break;
    }
  }
  return j;
}

double cornerTransferError_px(const Eigen::Matrix3d& estimate, const Eigen::Matrix3d& truth, int width, int height) {
  const Eigen::Vector2d corners[4] = {{0.0, 0.0}, {width - 1.0, 0.0}, {0.0, height - 1.0}, {width - 1.0, height - 1.0}};
  double worst = 0.0;
  for (const Eigen::Vector2d& c : corners)
    worst = std::max(worst, (transferPoint(estimate, c) - transferPoint(truth, c)).norm());
  return worst;
}

Eigen::Matrix2d transferCovariance(MotionModel model, const Eigen::VectorXd& parameters,
                                   const Eigen::MatrixXd& covariance, const Eigen::Vector2d& centre_px,
                                   const Eigen::Vector2d& point_px) {
  const Eigen::MatrixXd j = warpJacobian(model, parameters, point_px.x() - centre_px.x(), point_px.y() - centre_px.y());
  return j * covariance * j.transpose();
}

}  // namespace registration
}  // namespace exocet_mosaic
