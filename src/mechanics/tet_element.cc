#include "mechanics/tet_element.h"

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "mechanics/units.h"

namespace arreg::mechanics {

void Material::Check() const {
  ARREG_CHECK_INPUT(std::isfinite(youngs_modulus_pa) && youngs_modulus_pa > 0, "",
                    "material.youngs_modulus_pa", "must be positive and finite, got ",
                    youngs_modulus_pa);
  ARREG_CHECK_INPUT(std::isfinite(poisson_ratio) && poisson_ratio > -1.0 && poisson_ratio < 0.5, "",
                    "material.poisson_ratio", "must lie in (-1, 0.5), got ", poisson_ratio);
  ARREG_CHECK_INPUT(std::isfinite(density_kg_per_m3) && density_kg_per_m3 > 0, "",
                    "material.density_kg_per_m3", "must be positive and finite, got ",
                    density_kg_per_m3);
}

double Material::LameLambdaKpa() const {
  const double e = youngs_modulus_pa * kPaToInternalStress;
  return e * poisson_ratio / ((1.0 + poisson_ratio) * (1.0 - 2.0 * poisson_ratio));
}

double Material::LameMuKpa() const {
  return youngs_modulus_pa * kPaToInternalStress / (2.0 * (1.0 + poisson_ratio));
}

double Material::DensityKgPerMm3() const { return density_kg_per_m3 * kKgPerM3ToInternalDensity; }

RotationMethod ParseRotationMethod(const std::string& name) {
  return ParseName(kRotationMethodNames, name, "", "rotation method");
}

const char* RotationMethodName(RotationMethod method) {
  return NameOf(kRotationMethodNames, method);
}

bool ComputeTetRestData(const Eigen::Vector3d& x0, const Eigen::Vector3d& x1,
                        const Eigen::Vector3d& x2, const Eigen::Vector3d& x3,
                        const Material& material, TetRestData* out) {
  Eigen::Matrix3d dm;  // columns: rest edge vectors from vertex 0
  dm.col(0) = x1 - x0;
  dm.col(1) = x2 - x0;
  dm.col(2) = x3 - x0;
  const double det = dm.determinant();
  out->volume_mm3 = det / 6.0;
  if (!(det > 0.0)) return false;
  // Rows of Dm^{-1} are grad N_1..3; grad N_0 = -(sum of the others).
  const Eigen::Matrix3d dm_inv = dm.inverse();
  out->shape_gradients.bottomRows<3>() = dm_inv;
  out->shape_gradients.row(0) = -dm_inv.colwise().sum();
  out->lambda_kpa = material.LameLambdaKpa();
  out->mu_kpa = material.LameMuKpa();
  out->mass_kg = material.DensityKgPerMm3() * out->volume_mm3;
  return true;
}

Eigen::Matrix3d DeformationGradient(const TetRestData& rest, const Eigen::Matrix<double, 4, 3>& x) {
  return x.transpose() * rest.shape_gradients;
}

namespace {

void PolarSvd(const Eigen::Matrix3d& F, Eigen::Matrix3d* rotation) {
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(F, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d U = svd.matrixU();
  const Eigen::Matrix3d& V = svd.matrixV();
  // Keep a proper rotation for inverted elements: flip the axis of the
  // smallest singular value (Irving et al. 2004).
  if ((U * V.transpose()).determinant() < 0.0) U.col(2) *= -1.0;
  *rotation = U * V.transpose();
}

// The iterate of PolarRotation for one element.
struct PolarIterate {
  Eigen::Quaterniond q;
  Eigen::Matrix3d r;
  int iteration = 0;
  bool done = false, converged = false;
};

// One iteration of the polar rotation by Newton's method on the rotation: with G = R^T F, the
// polar R makes G symmetric; linearising R <- R exp(hat(w)) gives
// (tr(G) I - sym(G)) w = axial(G - G^T). The rotation is kept as a unit
// quaternion and updated by the quaternion (1, w/2) normalised - a rotation by
// 2 atan(|w|/2) = |w| + O(|w|^3) about w, so the iteration stays quadratic,
// needs no trigonometry and R stays orthonormal over any number of
// warm-started calls. Far from the answer (the matrix is not positive
// definite) the step falls back to the gradient-like step of Mueller et al.
// 2016, w = axial(G - G^T) / |tr G|, and steps are capped at 1 rad.
inline void PolarStep(const Eigen::Matrix3d& F, double tolerance, PolarIterate* s) {
  const Eigen::Matrix3d G = s->r.transpose() * F;
  const double t0 = G(2, 1) - G(1, 2), t1 = G(0, 2) - G(2, 0), t2 = G(1, 0) - G(0, 1);
  const double tr = G(0, 0) + G(1, 1) + G(2, 2);
  // M = tr(G) I - sym(G) (symmetric); w = M^-1 t by cofactors.
  const double m00 = tr - G(0, 0), m11 = tr - G(1, 1), m22 = tr - G(2, 2);
  const double m01 = -0.5 * (G(0, 1) + G(1, 0)), m02 = -0.5 * (G(0, 2) + G(2, 0)),
               m12 = -0.5 * (G(1, 2) + G(2, 1));
  const double c00 = m11 * m22 - m12 * m12, c01 = m02 * m12 - m01 * m22,
               c02 = m01 * m12 - m02 * m11;
  const double det = m00 * c00 + m01 * c01 + m02 * c02;
  double w0, w1, w2;
  const bool newton =
      tr > 0.0 && det > 1e-6 * tr * tr * tr && m00 > 0.0 && m00 * m11 - m01 * m01 > 0.0;
  if (newton) {
    const double c11 = m00 * m22 - m02 * m02, c12 = m01 * m02 - m00 * m12,
                 c22 = m00 * m11 - m01 * m01;
    const double inv = 1.0 / det;
    w0 = inv * (c00 * t0 + c01 * t1 + c02 * t2);
    w1 = inv * (c01 * t0 + c11 * t1 + c12 * t2);
    w2 = inv * (c02 * t0 + c12 * t1 + c22 * t2);
  } else {
    const double inv = 1.0 / (std::abs(tr) + 1e-12);
    w0 = inv * t0;
    w1 = inv * t1;
    w2 = inv * t2;
  }
  double angle2 = w0 * w0 + w1 * w1 + w2 * w2;
  if (!(angle2 > tolerance * tolerance)) {  // also stops on NaN input
    s->converged = angle2 <= tolerance * tolerance;
    s->done = true;
    return;
  }
  if (angle2 > 1.0) {
    const double scale = 1.0 / std::sqrt(angle2);
    w0 *= scale;
    w1 *= scale;
    w2 *= scale;
    angle2 = 1.0;
  }
  s->q = s->q * Eigen::Quaterniond(1.0, 0.5 * w0, 0.5 * w1, 0.5 * w2);
  s->q.coeffs() *= 1.0 / s->q.norm();
  s->r = s->q.toRotationMatrix();
  ++s->iteration;
  // Quadratic convergence: the error left after a step of angle |w| is
  // ~C |w|^2 with C ~ 1 for elements that are not nearly flat; stop without
  // a confirming iteration once that is 100x below the tolerance.
  if (newton && angle2 <= 1e-2 * tolerance) s->done = s->converged = true;
}

inline void PolarFinish(const Eigen::Matrix3d& F, PolarIterate* s) {
  if (!s->converged || !s->r.allFinite()) {
    // Not converged (a start far from the answer, or a near-singular F): the
    // SVD answer is exact.
    PolarSvd(F, &s->r);
    s->q = Eigen::Quaterniond(s->r);
  }
}

}  // namespace

int PolarRotation(const Eigen::Matrix3d& F, Eigen::Quaterniond* q, Eigen::Matrix3d* R,
                  int max_iterations, double tolerance) {
  PolarIterate s{*q, q->toRotationMatrix()};
  while (!s.done && s.iteration < max_iterations) PolarStep(F, tolerance, &s);
  PolarFinish(F, &s);
  *q = s.q;
  *R = s.r;
  return s.iteration;
}

int PolarRotations(int count, const Eigen::Matrix3d* F, Eigen::Quaterniond* q, Eigen::Matrix3d* R,
                   int max_iterations, double tolerance) {
  // Four elements in lockstep: each iteration is a long chain of dependent
  // operations, and interleaving independent chains keeps the CPU busy.
  constexpr int kLanes = 4;
  int iterations = 0;
  for (int base = 0; base < count; base += kLanes) {
    const int lanes = std::min(kLanes, count - base);
    PolarIterate s[kLanes];
    for (int k = 0; k < lanes; ++k) {
      s[k].q = q[base + k];
      s[k].r = s[k].q.toRotationMatrix();
    }
    for (bool busy = true; busy;) {
      busy = false;
      for (int k = 0; k < lanes; ++k)
        if (!s[k].done && s[k].iteration < max_iterations) {
          PolarStep(F[base + k], tolerance, &s[k]);
          busy = true;
        }
    }
    for (int k = 0; k < lanes; ++k) {
      PolarFinish(F[base + k], &s[k]);
      q[base + k] = s[k].q;
      R[base + k] = s[k].r;
      iterations += s[k].iteration;
    }
  }
  return iterations;
}

namespace {

void GramSchmidt(const Eigen::Matrix3d& F, Eigen::Matrix3d* rotation) {
  Eigen::Vector3d r0 = F.col(0);
  const double n0 = r0.norm();
  if (!(n0 > 0.0)) {
    rotation->setIdentity();
    return;
  }
  r0 /= n0;
  Eigen::Vector3d r1 = F.col(1) - r0.dot(F.col(1)) * r0;
  double n1 = r1.norm();
  if (!(n1 > 1e-300)) {  // degenerate: any unit vector orthogonal to r0
    r1 = r0.unitOrthogonal();
    n1 = 1.0;
  }
  r1 /= n1;
  rotation->col(0) = r0;
  rotation->col(1) = r1;
  rotation->col(2) = r0.cross(r1);
}

}  // namespace

int ExtractRotation(const Eigen::Matrix3d& F, RotationMethod method, Eigen::Matrix3d* rotation,
                    int max_iterations, double tolerance) {
  switch (method) {
    case RotationMethod::kPolar: {
      Eigen::Quaterniond q(*rotation);
      return PolarRotation(F, &q, rotation, max_iterations, tolerance);
    }
    case RotationMethod::kPolarSvd:
      PolarSvd(F, rotation);
      return 1;
    case RotationMethod::kQr:
      GramSchmidt(F, rotation);
      return 1;
  }
  return 0;
}

namespace {
// Small strain of the unrotated element: eps = sym(R^T F - I).
Eigen::Matrix3d CorotatedStrainOfF(const Eigen::Matrix3d& R, const Eigen::Matrix3d& F) {
  const Eigen::Matrix3d G = R.transpose() * F;
  Eigen::Matrix3d eps = 0.5 * (G + G.transpose());
  eps.diagonal().array() -= 1.0;
  return eps;
}
}  // namespace

VolumeTerm ParseVolumeTerm(const std::string& name) {
  return ParseName(kVolumeTermNames, name, "", "volume term");
}

const char* VolumeTermName(VolumeTerm term) { return NameOf(kVolumeTermNames, term); }

Eigen::Matrix3d Cofactor(const Eigen::Matrix3d& F) {
  Eigen::Matrix3d c;
  c.col(0) = F.col(1).cross(F.col(2));
  c.col(1) = F.col(2).cross(F.col(0));
  c.col(2) = F.col(0).cross(F.col(1));
  return c;
}

double CorotationalEnergyOfF(const TetRestData& rest, const Eigen::Matrix3d& R,
                             const Eigen::Matrix3d& F, VolumeTerm volume) {
  const Eigen::Matrix3d eps = CorotatedStrainOfF(R, F);
  const double tr = volume == VolumeTerm::kJacobian ? F.determinant() - 1.0 : eps.trace();
  return rest.volume_mm3 * (rest.mu_kpa * eps.squaredNorm() + 0.5 * rest.lambda_kpa * tr * tr);
}

double CorotationalEnergy(const TetRestData& rest, const Eigen::Matrix3d& R,
                          const Eigen::Matrix<double, 4, 3>& x, VolumeTerm volume) {
  return CorotationalEnergyOfF(rest, R, DeformationGradient(rest, x), volume);
}

void AddCorotationalGradient(const TetRestData& rest, const Eigen::Matrix3d& R,
                             const Eigen::Matrix<double, 4, 3>& x,
                             Eigen::Matrix<double, 4, 3>* gradient, VolumeTerm volume) {
  const Eigen::Matrix3d F = DeformationGradient(rest, x);
  const Eigen::Matrix3d eps = CorotatedStrainOfF(R, F);
  Eigen::Matrix3d sigma = 2.0 * rest.mu_kpa * eps;
  if (volume == VolumeTerm::kLinear) sigma.diagonal().array() += rest.lambda_kpa * eps.trace();
  // dE/dx_a = V R sigma g_a; as rows: V g_a^T sigma R^T (sigma symmetric).
  Eigen::Matrix3d p = rest.volume_mm3 * (R * sigma).transpose();
  // d/dx_a of V lambda/2 (J - 1)^2 = V lambda (J - 1) cof(F) g_a; as rows g_a^T cof(F)^T.
  if (volume == VolumeTerm::kJacobian)
    p += rest.volume_mm3 * rest.lambda_kpa * (F.determinant() - 1.0) * Cofactor(F).transpose();
  gradient->noalias() += rest.shape_gradients * p;
}

Eigen::Matrix<double, 12, 12> RestStiffnessMatrix(const TetRestData& rest) {
  Eigen::Matrix<double, 12, 12> k;
  for (Eigen::Index a = 0; a < 4; ++a)
    for (Eigen::Index b = 0; b < 4; ++b)
      k.block<3, 3>(3 * a, 3 * b) = WarpedStiffnessBlock(rest, rest.shape_gradients,
                                                         static_cast<int>(a), static_cast<int>(b));
  return k;
}

}  // namespace arreg::mechanics
