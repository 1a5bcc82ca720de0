// Element kernels of the linear tetrahedron with corotational linear
// elasticity: rest-state data, rotation extraction, energy, force and stiffness.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <string>

#include "core/enum_names.h"

namespace arreg::mechanics {

// Isotropic linear-elastic material of one element (SI units at the interface).
struct Material {
  double youngs_modulus_pa = 3000.0;  // E in Pa; default 3 kPa (soft tissue)
  double poisson_ratio = 0.45;        // nu in (-1, 0.5); default 0.45
  double density_kg_per_m3 = 1000.0;  // rho in kg/m^3; default 1000 (water)

  // Throws arreg::Error naming the field when a value is out of range.
  void Check() const;
  // Lame parameters in internal stress units (kPa).
  double LameLambdaKpa() const;
  double LameMuKpa() const;
  // Density in kg/mm^3.
  double DensityKgPerMm3() const;
};

// How the element rotation R is extracted from the deformation gradient F.
enum class RotationMethod {
  // Rotation of the polar decomposition F = R S (S symmetric) by a Newton
  // iteration on the rotation warm-started from the previous one (quadratic
  // convergence; Mueller et al. 2016's step when far away; SVD if it fails);
  // always a proper rotation, also for inverted elements.
  kPolar,
  // Polar rotation from a 3x3 SVD (F = U S V^T, R = U diag(1,1,det(UV^T)) V^T);
  // slower reference implementation.
  kPolarSvd,
  // QR variant (Nesme et al.): Gram-Schmidt of the columns of F. Cheaper, but
  // not rotation-invariant in the element's orientation and its force is not
  // the exact gradient of the energy.
  kQr,
};
inline constexpr EnumName<RotationMethod> kRotationMethodNames[] = {
    {RotationMethod::kPolar, "polar"},
    {RotationMethod::kPolarSvd, "polar-svd"},
    {RotationMethod::kQr, "qr"}};
RotationMethod ParseRotationMethod(const std::string& name);

// The volumetric part of the element energy V lambda/2 psi.
enum class VolumeTerm {
  // psi = tr(eps)^2, eps = sym(R^T F - I): corotational linear elasticity. tr(eps) is the
  // volume change only to first order: a stretch s along one axis with tr(eps) = 0 contracts
  // the other two by (s - 1)/2 each, so at s = 1.8 they keep 0.6 of their size and the volume
  // shrinks to 0.65, where an incompressible material keeps 0.75 and the volume.
  kLinear,
  // psi = (J - 1)^2, J = det F: the exact volume ratio ("fixed corotational", Stomakhin et al.
  // 2012); the shear part mu |sym(R^T F) - I|^2 is the same. Equal to kLinear to first order
  // at rest; under large stretch it keeps the volume as the material's nu says.
  kJacobian,
};
inline constexpr EnumName<VolumeTerm> kVolumeTermNames[] = {{VolumeTerm::kJacobian, "jacobian"},
                                                            {VolumeTerm::kLinear, "linear"}};
VolumeTerm ParseVolumeTerm(const std::string& name);
const char* VolumeTermName(VolumeTerm term);
const char* RotationMethodName(RotationMethod method);

// Rest-state data of one linear tetrahedron. The rest element stiffness is
// K_e = V B^T C B (12 x 12); with the constant shape gradients g_a it factors
// into 3x3 blocks K_ab = V (lambda g_a g_b^T + mu g_b g_a^T + mu (g_a . g_b) I),
// which is what is stored: rotating it (R K_ab R^T) then costs four
// matrix-vector products instead of two 12x12 products.
struct TetRestData {
  Eigen::Matrix<double, 4, 3> shape_gradients;  // row a = grad N_a in 1/mm (rest frame)
  double volume_mm3 = 0.0;                      // rest volume (> 0 for a valid element)
  double lambda_kpa = 0.0;                      // Lame lambda
  double mu_kpa = 0.0;                          // Lame mu (shear modulus)
  double mass_kg = 0.0;                         // rho * V
};

// Computes the rest data of the tetrahedron (x0, x1, x2, x3) in mm. Returns
// false (and leaves `out` partly filled) when its signed volume is not positive.
bool ComputeTetRestData(const Eigen::Vector3d& x0, const Eigen::Vector3d& x1,
                        const Eigen::Vector3d& x2, const Eigen::Vector3d& x3,
                        const Material& material, TetRestData* out);

// Deformation gradient F = sum_a x_a g_a^T (3 x 3) of the element at positions x.
Eigen::Matrix3d DeformationGradient(const TetRestData& rest, const Eigen::Matrix<double, 4, 3>& x);

// Rotation of F by `method`. `rotation` holds the warm start on input (used by
// kPolar) and the result on output. Returns the number of iterations used.
int ExtractRotation(const Eigen::Matrix3d& F, RotationMethod method, Eigen::Matrix3d* rotation,
                    int max_iterations = 20, double tolerance = 1e-12);

// RotationMethod::kPolar with the warm start kept as a unit quaternion
// (updated in place; what CorotationalElasticity stores per element) and the
// rotation matrix written to *R. Stops when the Newton update angle (rad) is
// below `tolerance`, or - by the quadratic convergence - right after an update
// whose squared angle is below tolerance / 100; falls back to the SVD when it
// does not converge within max_iterations. Returns the updates made.
int PolarRotation(const Eigen::Matrix3d& F, Eigen::Quaterniond* rotation, Eigen::Matrix3d* R,
                  int max_iterations = 20, double tolerance = 1e-12);
// PolarRotation of `count` elements (arrays of count), the same results; the
// elements are iterated four at a time in lockstep, which overlaps their
// dependency chains. Returns the updates made in total.
int PolarRotations(int count, const Eigen::Matrix3d* F, Eigen::Quaterniond* rotations,
                   Eigen::Matrix3d* R, int max_iterations = 20, double tolerance = 1e-12);

// Corotational energy with the rotation R held fixed:
//   E_e(x) = V (mu eps:eps + lambda/2 tr(eps)^2),  eps = sym(R^T F(x) - I)
// equal to 1/2 u^T K_e u with u = R^T x - X. Units: uJ.
// The same from the element's deformation gradient F.
// With VolumeTerm::kJacobian the volumetric part is V lambda/2 (det F - 1)^2 instead.
double CorotationalEnergyOfF(const TetRestData& rest, const Eigen::Matrix3d& R,
                             const Eigen::Matrix3d& F, VolumeTerm volume = VolumeTerm::kLinear);
double CorotationalEnergy(const TetRestData& rest, const Eigen::Matrix3d& R,
                          const Eigen::Matrix<double, 4, 3>& x,
                          VolumeTerm volume = VolumeTerm::kLinear);

// Adds the gradient dE_e/dx (fixed R) = R K_e (R^T x - X) to `gradient`
// (row a = vertex a, mN). The force is its negative.
// kJacobian: the volumetric part's gradient is V lambda (J - 1) cof(F) g_a instead (exact).
void AddCorotationalGradient(const TetRestData& rest, const Eigen::Matrix3d& R,
                             const Eigen::Matrix<double, 4, 3>& x,
                             Eigen::Matrix<double, 4, 3>* gradient,
                             VolumeTerm volume = VolumeTerm::kLinear);

// Cofactor matrix cof(F) = dJ/dF = det(F) F^-T (also for singular F).
Eigen::Matrix3d Cofactor(const Eigen::Matrix3d& F);

// The 3x3 block (a, b) of the warped stiffness R K_e R^T (stiffness warping:
// dR/dx is neglected), in mN/mm. Symmetric: block(b, a) = block(a, b)^T.
inline Eigen::Matrix3d WarpedStiffnessBlock(const TetRestData& rest,
                                            const Eigen::Matrix<double, 4, 3>& rotated_gradients,
                                            int a, int b) {
  const Eigen::Vector3d ga = rotated_gradients.row(a).transpose();
  const Eigen::Vector3d gb = rotated_gradients.row(b).transpose();
  Eigen::Matrix3d block = rest.lambda_kpa * ga * gb.transpose() + rest.mu_kpa * gb * ga.transpose();
  block.diagonal().array() += rest.mu_kpa * ga.dot(gb);
  return rest.volume_mm3 * block;
}

// The full rest stiffness K_e (12 x 12, vertex-major: dof 3a+i). For tests and
// inspection; the solver never forms it.
Eigen::Matrix<double, 12, 12> RestStiffnessMatrix(const TetRestData& rest);

}  // namespace arreg::mechanics
