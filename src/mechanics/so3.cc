#include "mechanics/so3.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>

namespace arreg::mechanics {

Eigen::Matrix3d Skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d s;
  s << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return s;
}

Eigen::Vector3d Axial(const Eigen::Matrix3d& a) {
  return 0.5 * Eigen::Vector3d(a(2, 1) - a(1, 2), a(0, 2) - a(2, 0), a(1, 0) - a(0, 1));
}

namespace {

// sin(t)/t, (1 - cos t)/t^2 and (t - sin t)/t^3 with their Taylor series where
// the closed forms lose digits (t below 1e-4 keeps every term below 1e-17).
struct RodriguesCoefficients {
  double a, b, c;
};
RodriguesCoefficients Coefficients(double t) {
  const double t2 = t * t;
  if (t < 1e-4) return {1.0 - t2 / 6.0, 0.5 - t2 / 24.0, 1.0 / 6.0 - t2 / 120.0};
  const double s = std::sin(t), co = std::cos(t);
  return {s / t, (1.0 - co) / t2, (t - s) / (t2 * t)};
}

}  // namespace

Eigen::Matrix3d ExpSO3(const Eigen::Vector3d& theta) {
  const RodriguesCoefficients k = Coefficients(theta.norm());
  const Eigen::Matrix3d s = Skew(theta);
  return Eigen::Matrix3d::Identity() + k.a * s + k.b * s * s;
}

Eigen::Vector3d LogSO3(const Eigen::Matrix3d& r) {
  const double cos_t = std::clamp(0.5 * (r.trace() - 1.0), -1.0, 1.0);
  const double t = std::acos(cos_t);
  const Eigen::Vector3d w = Axial(r);  // sin(t) * axis
  if (t < 1e-4) return (1.0 + t * t / 6.0) * w;
  if (M_PI - t > 1e-3) return (t / std::sin(t)) * w;
  // Near pi: R + R^T = 2 cos t I + 2 (1 - cos t) a a^T gives the axis up to
  // sign; the sign comes from the (small) skew part.
  const Eigen::Matrix3d sym = 0.5 * (r + r.transpose()) - cos_t * Eigen::Matrix3d::Identity();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(sym);
  Eigen::Vector3d axis = eig.eigenvectors().col(2);
  if (axis.dot(w) < 0) axis = -axis;
  return t * axis;
}

Eigen::Matrix3d LeftJacobianSO3(const Eigen::Vector3d& theta) {
  const RodriguesCoefficients k = Coefficients(theta.norm());
  const Eigen::Matrix3d s = Skew(theta);
  return Eigen::Matrix3d::Identity() + k.b * s + k.c * s * s;
}

Eigen::Matrix3d LeftJacobianInverseSO3(const Eigen::Vector3d& theta) {
  const double t = theta.norm();
  const Eigen::Matrix3d s = Skew(theta);
  // 1/t^2 - (1 + cos t) / (2 t sin t), series 1/12 + t^2/720 near zero.
  const double d = t < 1e-4 ? 1.0 / 12.0 + t * t / 720.0
                            : 1.0 / (t * t) - (1.0 + std::cos(t)) / (2.0 * t * std::sin(t));
  return Eigen::Matrix3d::Identity() - 0.5 * s + d * s * s;
}

}  // namespace arreg::mechanics
