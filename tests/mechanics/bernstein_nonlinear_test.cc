// Strain-stiffening Bernstein tetrahedra: the quadrature, the material's stress and
// tangent against differences, the term's gradient and Hessian against differences, the
// linear limit against the closed-form stiffness, and a uniaxial bar under incremental
// Newton against the analytic stress-strain curve.
#include "mechanics/bernstein_nonlinear.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <memory>
#include <random>

#include "core/error.h"
#include "core/mesh_generators.h"
#include "curved_test_util.h"
#include "generalised_fd.h"
#include "mechanics/bernstein_tet.h"
#include "mechanics/generalised_solver.h"

namespace arreg::mechanics {
namespace {

using testing::Gradient;
using testing::Hessian;

StiffeningMaterial Stiffening(double nu, double a) {
  StiffeningMaterial m;
  m.material.youngs_modulus_pa = 3000;
  m.material.poisson_ratio = nu;
  m.nonlinearity = a;
  return m;
}

Eigen::Matrix3d RandomSymmetric(std::mt19937* rng, double scale) {
  std::uniform_real_distribution<double> u(-scale, scale);
  Eigen::Matrix3d m;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) m(i, j) = u(*rng);
  return 0.5 * (m + m.transpose());
}

TEST(TetQuadrature, IntegratesBarycentricMonomialsExactly) {
  for (int degree = 0; degree <= 8; ++degree) {
    std::vector<Eigen::Vector4d> points;
    std::vector<double> weights;
    TetQuadrature(degree, &points, &weights);
    for (const auto& alpha : BernsteinIndices(degree)) {
      double sum = 0;
      for (size_t q = 0; q < points.size(); ++q) {
        double f = weights[q];
        for (int i = 0; i < 4; ++i) f *= std::pow(points[q][i], alpha[i]);
        sum += f;
      }
      EXPECT_NEAR(sum, BarycentricMonomialIntegral(alpha, 1.0), 1e-14) << degree;
    }
  }
}

TEST(StiffeningMaterial, StressAndTangentMatchDifferences) {
  std::mt19937 rng(1);
  const StiffeningMaterial m = Stiffening(0.3, 40);
  for (int s = 0; s < 5; ++s) {
    const Eigen::Matrix3d eps = RandomSymmetric(&rng, 0.15);
    const Eigen::Matrix3d sigma = m.Stress(eps);
    const double h = 1e-7;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {
        Eigen::Matrix3d d = Eigen::Matrix3d::Zero();
        d(i, j) = h;
        const double fd = (m.Energy(eps + d) - m.Energy(eps - d)) / (2 * h);
        EXPECT_NEAR(sigma(i, j), fd, 1e-6 * sigma.norm());
      }
    const Eigen::Matrix3d deps = RandomSymmetric(&rng, 1.0);
    const Eigen::Matrix3d fd = (m.Stress(eps + h * deps) - m.Stress(eps - h * deps)) / (2 * h);
    EXPECT_LT((m.StressIncrement(eps, deps) - fd).norm(), 1e-6 * fd.norm());
  }
  // A = 0 is linear elasticity.
  const StiffeningMaterial linear = Stiffening(0.3, 0);
  const Eigen::Matrix3d eps = RandomSymmetric(&rng, 0.1);
  const double mu = linear.material.LameMuKpa(), lambda = linear.material.LameLambdaKpa();
  EXPECT_LT((linear.Stress(eps) - 2 * mu * eps - lambda * eps.trace() * Eigen::Matrix3d::Identity())
                .norm(),
            1e-14);
}

struct Model {
  HighOrderTetMesh mesh;
  GeneralisedState state;
  std::vector<int> node;
  std::unique_ptr<BernsteinStiffeningTerm> term;
};

std::unique_ptr<Model> MakeModel(const TetMesh& tets, int degree, const StiffeningMaterial& m) {
  auto model = std::make_unique<Model>();
  model->mesh = RaiseTetMesh(tets, degree);
  model->node = AddHighOrderNodes(model->mesh, &model->state);
  model->term = std::make_unique<BernsteinStiffeningTerm>(&model->mesh, model->node, m);
  return model;
}

TEST(BernsteinStiffening, GradientAndHessianMatchDifferences) {
  const TetMesh box = MakeBoxTetMesh(Eigen::Vector3d(10, 8, 6), Eigen::Vector3i(1, 1, 1));
  std::mt19937 rng(2);
  std::uniform_real_distribution<double> u(-0.8, 0.8);
  for (int k = 1; k <= 3; ++k) {
    auto m = MakeModel(box, k, Stiffening(0.3, 40));
    Eigen::VectorXd increment(m->state.num_dofs());
    for (int i = 0; i < increment.size(); ++i) increment[i] = u(rng);  // strains ~ 0.1
    m->state.ApplyIncrement(increment);
    m->term->Update(m->state);
    const Eigen::VectorXd g = Gradient(*m->term, m->state);
    const Eigen::MatrixXd hessian = Hessian(*m->term, m->state);
    const double h = 1e-6;
    const Eigen::VectorXd fd_g = testing::EnergyGradientByDifferences(m->term.get(), m->state, h);
    Eigen::MatrixXd fd_h(g.size(), g.size());
    for (int i = 0; i < g.size(); ++i)
      fd_h.col(i) = (Gradient(*m->term, testing::Perturbed(m->state, i, h)) -
                     Gradient(*m->term, testing::Perturbed(m->state, i, -h))) /
                    (2 * h);
    EXPECT_LT((g - fd_g).norm(), 1e-6 * g.norm()) << "degree " << k;
    EXPECT_LT((hessian - fd_h).norm(), 1e-6 * hessian.norm()) << "degree " << k;
    EXPECT_LT((hessian - hessian.transpose()).norm(), 1e-12 * hessian.norm());
    // The nonlinearity matters at these strains: the Hessian differs from the rest one.
    m->term->Update(m->state);
    auto rest = MakeModel(box, k, Stiffening(0.3, 40));
    EXPECT_GT((hessian - Hessian(*rest->term, rest->state)).norm(), 0.05 * hessian.norm());
  }
}

TEST(BernsteinStiffening, LinearLimitIsTheClosedFormStiffness) {
  const TetMesh box = MakeBoxTetMesh(Eigen::Vector3d(10, 8, 6), Eigen::Vector3i(1, 1, 1));
  for (int k = 1; k <= 3; ++k) {
    auto m = MakeModel(box, k, Stiffening(0.3, 0));
    const Eigen::MatrixXd hessian = Hessian(*m->term, m->state);
    // Assemble the closed-form element stiffness on the same nodes.
    Eigen::MatrixXd closed = Eigen::MatrixXd::Zero(hessian.rows(), hessian.cols());
    const Material& material = Stiffening(0.3, 0).material;
    for (int e = 0; e < m->mesh.num_elements(); ++e) {
      Eigen::Matrix3d d;
      for (int c = 0; c < 3; ++c)
        d.col(c) = (m->mesh.nodes.row(m->mesh.elements(e, c + 1)) -
                    m->mesh.nodes.row(m->mesh.elements(e, 0)))
                       .transpose();
      Eigen::Matrix<double, 4, 3> g;
      g.bottomRows<3>() = d.inverse();
      g.row(0) = -g.bottomRows<3>().colwise().sum();
      const Eigen::MatrixXd ke = BernsteinStiffnessMatrix(
          k, g, d.determinant() / 6, material.LameLambdaKpa(), material.LameMuKpa());
      const int n = static_cast<int>(m->mesh.elements.cols());
      for (int a = 0; a < n; ++a)
        for (int b = 0; b < n; ++b)
          closed.block<3, 3>(m->state.dof_offset(m->node[m->mesh.elements(e, a)]),
                             m->state.dof_offset(m->node[m->mesh.elements(e, b)])) +=
              ke.block<3, 3>(3 * a, 3 * b);
    }
    EXPECT_LT((hessian - closed).norm(), 1e-12 * closed.norm()) << "degree " << k;
  }
}

// sigma = E0 (e + A e^3) solved for e (uniaxial strain, nu = 0).
double AnalyticStrain(double stress_kpa, double e0_kpa, double a) {
  double e = stress_kpa / e0_kpa;
  for (int i = 0; i < 50; ++i)
    e -= (e0_kpa * (e + a * e * e * e) - stress_kpa) / (e0_kpa * (1 + 3 * a * e * e));
  return e;
}

// A 20 x 4 x 4 mm bar (nu = 0, E0 = 3 kPa, A = 10) clamped at x = 0 and pulled by a
// traction on x = 20 in 8 load increments, each solved by Newton from the last: the
// stretch follows sigma = E0 (e + A e^3) (the homogeneous strain is in every degree's
// space, so exactly), 40 % stiffer than linear at the end.
TEST(BernsteinStiffening, UniaxialBarFollowsTheAnalyticCurveUnderIncrementalNewton) {
  const TetMesh bar = MakeBoxTetMesh(Eigen::Vector3d(20, 4, 4), Eigen::Vector3i(5, 1, 1));
  const double a = 10, e0 = 3.0;                     // kPa
  const double max_stress = e0 * (0.2 + a * 0.008);  // e = 0.2 at the end
  std::printf("degree  traction (kPa)  strain  analytic  linear  Newton iterations\n");
  for (int k = 1; k <= 3; ++k) {
    auto m = MakeModel(bar, k, Stiffening(0.0, a));
    for (int i = 0; i < m->mesh.num_nodes(); ++i)
      if (m->mesh.nodes(i, 0) < 1e-9) m->state.SetFixedTranslation(m->node[i], true);
    GeneralisedStaticSolver solver({});
    const int steps = 8;
    for (int s = 1; s <= steps; ++s) {
      const double t = max_stress * s / steps;
      const RowMatX3d loads = UniformTractionLoads(
          m->mesh,
          [](const Eigen::Vector3d& p, const Eigen::Vector3d& q, const Eigen::Vector3d& r) {
            return p.x() > 20 - 1e-9 && q.x() > 20 - 1e-9 && r.x() > 20 - 1e-9;
          },
          Eigen::Vector3d(t, 0, 0));
      RowMatX3d forces = RowMatX3d::Zero(m->state.num_nodes(), 3);
      for (int i = 0; i < m->mesh.num_nodes(); ++i) forces.row(m->node[i]) = loads.row(i);
      NodalForceTerm load(forces);
      const GeneralisedSummary summary = solver.Solve(&m->state, {m->term.get(), &load});
      ASSERT_EQ(summary.status, StepStatus::kConverged) << "degree " << k << " step " << s;
      double strain = 0;
      int count = 0;
      for (int i = 0; i < m->mesh.num_nodes(); ++i)
        if (m->mesh.nodes(i, 0) > 20 - 1e-9) {
          strain += (m->state.position(m->node[i]).x() - 20) / 20;
          ++count;
        }
      strain /= count;
      const double analytic = AnalyticStrain(t, e0, a);
      if (s % 2 == 0)
        std::printf("%6d  %14.4f  %6.4f  %8.4f  %6.4f  %d\n", k, t, strain, analytic, t / e0,
                    summary.newton_iterations);
      EXPECT_NEAR(strain, analytic, 1e-8) << "degree " << k << " step " << s;
    }
    EXPECT_GT(max_stress / e0 / AnalyticStrain(max_stress, e0, a), 1.3);  // far from linear
  }
}

}  // namespace
}  // namespace arreg::mechanics
