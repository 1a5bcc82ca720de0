#include "cutting/system_conditioning.h"

#include <Eigen/Dense>
#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>
#include <cmath>
#include <vector>

#include "core/error.h"

namespace arreg::cutting {

void ConditioningOptions::Check() const {
  ARREG_CHECK_INPUT(youngs_modulus_pa > 0, "", "ConditioningOptions.youngs_modulus_pa",
                    "must be > 0");
  ARREG_CHECK_INPUT(poisson_ratio > -1 && poisson_ratio < 0.5, "",
                    "ConditioningOptions.poisson_ratio", "must be in (-1, 0.5)");
  ARREG_CHECK_INPUT(density_kg_per_m3 > 0, "", "ConditioningOptions.density_kg_per_m3",
                    "must be > 0");
  ARREG_CHECK_INPUT(dt_s > 0, "", "ConditioningOptions.dt_s", "must be > 0");
  ARREG_CHECK_INPUT(length_unit_m > 0, "", "ConditioningOptions.length_unit_m", "must be > 0");
  ARREG_CHECK_INPUT(max_iterations > 0, "", "ConditioningOptions.max_iterations", "must be > 0");
  ARREG_CHECK_INPUT(tolerance > 0, "", "ConditioningOptions.tolerance", "must be > 0");
}

ConditioningSummary SystemConditioning(const TetMesh& mesh, const ConditioningOptions& o) {
  o.Check();
  const int nv = mesh.num_vertices(), n = 3 * nv;
  const double E = o.youngs_modulus_pa, nu = o.poisson_ratio;
  const double lambda = E * nu / ((1 + nu) * (1 - 2 * nu)), mu = E / (2 * (1 + nu));
  Eigen::Matrix<double, 6, 6> D = Eigen::Matrix<double, 6, 6>::Zero();
  D.topLeftCorner<3, 3>().setConstant(lambda);
  D.topLeftCorner<3, 3>().diagonal().array() += 2 * mu;
  D.bottomRightCorner<3, 3>().diagonal().setConstant(mu);
  std::vector<Eigen::Triplet<double>> triplets;
  triplets.reserve(mesh.num_tetrahedra() * 144 + n);
  Eigen::VectorXd mass = Eigen::VectorXd::Zero(nv);
  const double dt2 = o.dt_s * o.dt_s;
  for (int t = 0; t < mesh.num_tetrahedra(); ++t) {
    Eigen::Matrix3d X;
    Eigen::Vector3d x0 = mesh.vertices.row(mesh.tetrahedra(t, 0)).transpose() * o.length_unit_m;
    for (int k = 1; k < 4; ++k)
      X.col(k - 1) = mesh.vertices.row(mesh.tetrahedra(t, k)).transpose() * o.length_unit_m - x0;
    const double volume = X.determinant() / 6.0;
    ARREG_CHECK_INPUT(volume > 0, "", "SystemConditioning", "tetrahedron ", t,
                      " has non-positive volume");
    // Shape function gradients (rows: vertices 0..3).
    const Eigen::Matrix3d inv = X.inverse();
    Eigen::Matrix<double, 4, 3> G;
    G.bottomRows<3>() = inv;
    G.row(0) = -inv.colwise().sum();
    Eigen::Matrix<double, 6, 12> B = Eigen::Matrix<double, 6, 12>::Zero();
    for (int a = 0; a < 4; ++a) {
      const double gx = G(a, 0), gy = G(a, 1), gz = G(a, 2);
      B(0, 3 * a) = gx;
      B(1, 3 * a + 1) = gy;
      B(2, 3 * a + 2) = gz;
      B(3, 3 * a) = gy;
      B(3, 3 * a + 1) = gx;
      B(4, 3 * a + 1) = gz;
      B(4, 3 * a + 2) = gy;
      B(5, 3 * a) = gz;
      B(5, 3 * a + 2) = gx;
    }
    const Eigen::Matrix<double, 12, 12> K = volume * B.transpose() * D * B;
    for (int a = 0; a < 4; ++a) {
      mass(mesh.tetrahedra(t, a)) += o.density_kg_per_m3 * volume / 4;
      for (int b = 0; b < 4; ++b)
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < 3; ++j)
            triplets.emplace_back(3 * mesh.tetrahedra(t, a) + i, 3 * mesh.tetrahedra(t, b) + j,
                                  dt2 * K(3 * a + i, 3 * b + j));
    }
  }
  for (int v = 0; v < nv; ++v)
    for (int i = 0; i < 3; ++i) triplets.emplace_back(3 * v + i, 3 * v + i, mass(v));
  Eigen::SparseMatrix<double> A(n, n);
  A.setFromTriplets(triplets.begin(), triplets.end());

  ConditioningSummary s;
  Eigen::VectorXd x = Eigen::VectorXd::Ones(n) + 0.1 * Eigen::VectorXd::LinSpaced(n, 0, 1);
  x.normalize();
  double prev = 0;
  bool max_converged = false, min_converged = false;
  for (int it = 0; it < o.max_iterations; ++it) {
    Eigen::VectorXd y = A * x;
    s.lambda_max = x.dot(y);
    x = y.normalized();
    if (it > 10 && std::abs(s.lambda_max - prev) <= o.tolerance * s.lambda_max) {
      max_converged = true;
      break;
    }
    prev = s.lambda_max;
  }
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt(A);
  if (ldlt.info() != Eigen::Success) return s;
  x = Eigen::VectorXd::Ones(n) - 0.1 * Eigen::VectorXd::LinSpaced(n, 0, 1);
  x.normalize();
  prev = 0;
  double mu_inv = 0;
  for (int it = 0; it < o.max_iterations; ++it) {
    Eigen::VectorXd y = ldlt.solve(x);
    mu_inv = x.dot(y);
    x = y.normalized();
    if (it > 10 && std::abs(mu_inv - prev) <= o.tolerance * mu_inv) {
      min_converged = true;
      break;
    }
    prev = mu_inv;
  }
  s.lambda_min = 1.0 / mu_inv;
  s.condition_number = s.lambda_max / s.lambda_min;
  s.converged = max_converged && min_converged;
  return s;
}

}  // namespace arreg::cutting
