// Rotations as 3-vectors: the exponential and logarithm maps of SO(3) and the
// Jacobians that relate a change of the rotation vector to a change of the
// rotation. Nodes with rotational DOFs (shell nodes, frames) store a rotation
// R and take increments R <- Exp(theta) R (a spatial, left increment).
#pragma once

#include <Eigen/Core>

namespace arreg::mechanics {

// [v]x: the matrix with [v]x w = v x w.
Eigen::Matrix3d Skew(const Eigen::Vector3d& v);
// The vector v of a skew-symmetric part: v = axial((A - A^T) / 2).
Eigen::Vector3d Axial(const Eigen::Matrix3d& a);

// Exp(theta) = exp([theta]x) (Rodrigues; series near zero, exact to rounding).
Eigen::Matrix3d ExpSO3(const Eigen::Vector3d& theta);
// Log(R): the rotation vector with |theta| <= pi and Exp(theta) = R. R must be
// a rotation (orthonormal, det +1) to rounding; near |theta| = pi the axis is
// taken from the symmetric part.
Eigen::Vector3d LogSO3(const Eigen::Matrix3d& rotation);

// Left Jacobian J_l(theta): Exp(theta + d) = Exp(J_l(theta) d) Exp(theta) + O(|d|^2).
// A gradient g with respect to a left increment phi at R = Exp(theta) R0 is the
// gradient J_l(theta)^T g with respect to theta.
Eigen::Matrix3d LeftJacobianSO3(const Eigen::Vector3d& theta);
// Inverse of the left Jacobian (well defined for |theta| < 2 pi).
Eigen::Matrix3d LeftJacobianInverseSO3(const Eigen::Vector3d& theta);

}  // namespace arreg::mechanics
