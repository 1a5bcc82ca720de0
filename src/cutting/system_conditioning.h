// Condition number of the implicit-Euler system matrix M + dt^2 K of a linear
// elastic tetrahedral mesh: the numerical-quality measure of remeshing (thesis 5.2).
#pragma once

#include "core/mesh.h"

namespace arreg::cutting {

struct ConditioningOptions {
  double youngs_modulus_pa = 3000.0;  // E in Pa; default 3 kPa
  double poisson_ratio = 0.45;        // nu in (-1, 0.5); default 0.45
  double density_kg_per_m3 = 1000.0;  // rho; default 1000
  double dt_s = 0.04;                 // time step in s; default 0.04 (25 fps)
  double length_unit_m = 1e-3;        // metres per mesh unit; default 1e-3 (mm)
  int max_iterations = 2000;          // power / inverse iterations; default 2000
  double tolerance = 1e-10;           // relative change of the eigenvalue estimates; default 1e-10
  void Check() const;
};

struct ConditioningSummary {
  double lambda_min = 0;  // smallest eigenvalue of M + dt^2 K (kg)
  double lambda_max = 0;  // largest eigenvalue (kg)
  double condition_number = 0;
  bool converged = false;
};

// Assembles small-strain linear elasticity (constant-strain tetrahedra) and a
// lumped mass matrix (a quarter of each element's mass per vertex) on the rest
// mesh, with no boundary conditions (the mass keeps the matrix definite), and
// estimates the extreme eigenvalues by power and inverse (LDL^T) iteration.
ConditioningSummary SystemConditioning(const TetMesh& rest_mesh,
                                       const ConditioningOptions& options);

}  // namespace arreg::cutting
