/**
 * @file motion_model.h
 * @brief The parametric 2D motion models shared by the KLT and RMR registrations, their parameterisation, warp
 * Jacobians and conversions to a 3x3 matrix. No ROS in it.
 *
 * Every model maps a pixel of the previous image A to the current image B. Parameters are expressed in coordinates
 * centred on a reference point c (the image centre): u = x - c_x, v = y - c_y, so that the translation parameters
 * are the displacement of the image centre and the covariance is well conditioned.
 *
 *  - translation (2): [tx, ty]                          u' = u + tx,                v' = v + ty
 *  - similarity  (4): [tx, ty, a, b]                    u' = (1+a) u - b v + tx,    v' = b u + (1+a) v + ty
 *                     (scale = |1+a+ib|, rotation = atan2(b, 1+a))
 *  - affine      (6): [tx, ty, a11, a12, a21, a22]      u' = (1+a11) u + a12 v + tx, v' = a21 u + (1+a22) v + ty
 *  - homography  (8): [tx, ty, a11, a12, a21, a22, g1, g2]
 *                     (u', v', 1) ~ [[1+a11, a12, tx], [a21, 1+a22, ty], [g1, g2, 1]] (u, v, 1)
 * The zero vector is the identity motion for every model.
 */
#pragma once

#include <string>

#include <Eigen/Core>

namespace exocet_mosaic {
namespace registration {

enum class MotionModel { kTranslation, kSimilarity, kAffine, kHomography };

/// "translation", "similarity", "affine", "homography".
std::string toString(MotionModel model);
/// Inverse of toString; throws std::invalid_argument naming the allowed values.
MotionModel motionModelFromString(const std::string& name);
/// Number of parameters: 2, 4, 6, 8.
int parameterCount(MotionModel model);

/// 3x3 matrix in centred coordinates from the parameters (size parameterCount(model)).
Eigen::Matrix3d centredMatrix(MotionModel model, const Eigen::VectorXd& parameters);
/// 3x3 matrix in pixel coordinates (x_B ~ H x_A) from the parameters and the centre c.
Eigen::Matrix3d pixelMatrix(MotionModel model, const Eigen::VectorXd& parameters, const Eigen::Vector2d& centre_px);
/// Parameters of `model` closest to a pixel matrix H (exact when H belongs to the model; otherwise the model fitted
/// by least squares to H's action on a grid over a width x height image).
Eigen::VectorXd parametersFromPixelMatrix(MotionModel model, const Eigen::Matrix3d& pixel_matrix,
                                          const Eigen::Vector2d& centre_px, int width, int height);

/// Applies a pixel matrix to a pixel.
Eigen::Vector2d transferPoint(const Eigen::Matrix3d& pixel_matrix, const Eigen::Vector2d& point_px);

/// Derivative of the warped centred point (u', v') with respect to the parameters, at centred point (u, v), evaluated
/// at `parameters` (2 x parameterCount). For the linear models it does not depend on the parameters.
Eigen::MatrixXd warpJacobian(MotionModel model, const Eigen::VectorXd& parameters, double u, double v);

/// Largest distance (pixels) between where two pixel matrices send the four corners of a width x height image: the
/// corner-transfer error used to compare an estimate with ground truth.
double cornerTransferError_px(const Eigen::Matrix3d& estimate, const Eigen::Matrix3d& truth, int width, int height);

/// Covariance (2x2, pixels^2) of where `point_px` lands under the motion, from the parameter covariance.
Eigen::Matrix2d transferCovariance(MotionModel model, const Eigen::VectorXd& parameters,
                                   const Eigen::MatrixXd& covariance, const Eigen::Vector2d& centre_px,
                                   const Eigen::Vector2d& point_px);

}  // namespace registration
}  // namespace exocet_mosaic
