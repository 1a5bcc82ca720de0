#include "cutting/system_conditioning.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>

#include "core/mesh_generators.h"

namespace arreg::cutting {
namespace {

// The extreme eigenvalues against values known in closed form (lumped masses)
// and bounds that hold for any stiffness.
TEST(SystemConditioning, MatchesDenseEigenvalues) {
  const TetMesh m =
      MakeBoxTetMesh(Eigen::Vector3d(20, 10, 10), Eigen::Vector3i(2, 1, 1), BoxTetSplit::kSix);
  ConditioningOptions o;
  const ConditioningSummary s = SystemConditioning(m, o);
  ASSERT_TRUE(s.converged);
  // Without stiffness (dt -> 0) the matrix is the lumped mass: eigenvalues are vertex masses.
  o.dt_s = 1e-9;
  const ConditioningSummary mass_only = SystemConditioning(m, o);
  Eigen::VectorXd mass = Eigen::VectorXd::Zero(m.num_vertices());
  for (int t = 0; t < m.num_tetrahedra(); ++t) {
    Eigen::Matrix3d X;
    for (int k = 1; k < 4; ++k)
      X.col(k - 1) =
          (m.vertices.row(m.tetrahedra(t, k)) - m.vertices.row(m.tetrahedra(t, 0))).transpose() *
          1e-3;
    for (int k = 0; k < 4; ++k) mass(m.tetrahedra(t, k)) += 1000.0 * X.determinant() / 6 / 4;
  }
  EXPECT_NEAR(mass_only.lambda_max, mass.maxCoeff(), 1e-9 * mass.maxCoeff());
  EXPECT_NEAR(mass_only.lambda_min, mass.minCoeff(), 1e-9 * mass.minCoeff());
  // Stiffness only adds a positive semi-definite term: no eigenvalue can drop below
  // the mass-only ones (Weyl's inequality).
  EXPECT_GE(s.lambda_max, mass_only.lambda_max * (1 - 1e-9));
  EXPECT_GE(s.lambda_min, mass_only.lambda_min * (1 - 1e-9));
  EXPECT_GT(s.condition_number, 1.0);
}

}  // namespace
}  // namespace arreg::cutting
