#include "mechanics/quasi_static_fit.h"

#include <gtest/gtest.h>

#include "core/error.h"
#include "mechanics/elastic_energy.h"
#include "mechanics/embedding.h"
#include "mechanics/integrator.h"
#include "mechanics/spring_energy.h"
#include "mechanics_test_util.h"

namespace arreg::mechanics {
namespace {

using testing::SmallBox;

// A 60 x 20 x 20 mm bar fixed at x = 0, pulled at its far end by springs to
// targets `pull` mm along x (and a little along y) from their anchors.
struct PulledBar {
  MechanicalState state{SmallBox({6, 2, 2}, {60, 20, 20}), Material{5000, 0.3, 1000}};
  SpringEnergy springs;
  PulledBar(double stiffness_n_per_m, double pull_mm) {
    for (int v = 0; v < state.num_vertices(); ++v)
      if (state.rest_position(v).x() == 0.0) state.SetFixed(v, true);
    RowMatX3d anchors(3, 3);
    anchors << 58, 5, 18, 58, 15, 10, 55, 10, 2;
    const EmbeddedPoints embedded =
        EmbeddedPoints::Embed(anchors, state.rest_positions(), state.tetrahedra());
    for (int i = 0; i < anchors.rows(); ++i)
      springs.Add(embedded[i],
                  anchors.row(i).transpose() + Eigen::Vector3d(pull_mm, 0.2 * pull_mm, 0),
                  stiffness_n_per_m);
  }
};

// The anchors' mean distance to their targets at `positions`.
double MeanSpringLength(const PulledBar& bar, const RowMatX3d& positions) {
  double sum = 0;
  for (int id = 0; id < bar.springs.size(); ++id)
    sum += (bar.springs.AnchorPosition(id, bar.state, positions) - bar.springs.spring(id).target_mm)
               .norm();
  return sum / bar.springs.size();
}

// Iterated to convergence: the default volume term's Hessian is approximate (docs/mechanics.md
// "Volume term"), so Newton converges linearly and needs more iterations than with an exact one.
QuasiStaticFitOptions ConvergedFit(double factor) {
  QuasiStaticFitOptions options;
  options.spring_factor = factor;
  options.newton_iterations = 100;
  options.linear_solver.type = LinearSolverType::kCholmod;
  return options;
}

TEST(QuasiStaticFit, ConvergesToTheStaticEquilibriumWithStifferSprings) {
  // The fit, iterated, is the static solve with springs s times stiffer, up to its
  // regularisation (1/h^2 M ~ 1e-5 of the springs' stiffness here).
  const double k = 50.0, s = 5.0;
  PulledBar fitted(k, 3.0);
  QuasiStaticFit fit(ConvergedFit(s));
  ASSERT_NE(fit.Fit(fitted.state, fitted.springs).status, StepStatus::kLinearSolveFailed);

  PulledBar reference(s * k, 3.0);
  CorotationalElasticity elastic;
  StaticSolver solver{StaticSolverOptions{}};
  ASSERT_EQ(solver.Solve(&reference.state, &elastic, {&reference.springs}).status,
            StepStatus::kConverged);
  const double moved =
      (reference.state.positions() - reference.state.rest_positions()).rowwise().norm().maxCoeff();
  ASSERT_GT(moved, 0.5);
  EXPECT_LT((fit.positions() - reference.state.positions()).rowwise().norm().maxCoeff(),
            1e-3 * moved);
}

TEST(QuasiStaticFit, StifferSpringsLagLess) {
  // A stiffer fit follows the targets more closely; the state is left as it was.
  PulledBar bar(50.0, 3.0);
  const RowMatX3d before = bar.state.positions();
  double last = MeanSpringLength(bar, before);
  for (double s : {1.0, 4.0, 16.0}) {
    QuasiStaticFit fit(ConvergedFit(s));
    fit.Fit(bar.state, bar.springs);
    const double length = MeanSpringLength(bar, fit.positions());
    EXPECT_LT(length, last) << "factor " << s;
    last = length;
  }
  EXPECT_EQ(bar.state.positions(), before);
  EXPECT_TRUE(bar.state.velocities().isZero());
  // The springs' stiffness in the caller's energy is untouched.
  for (int id = 0; id < bar.springs.size(); ++id)
    EXPECT_EQ(bar.springs.spring(id).stiffness_n_per_m, 50.0);
}

TEST(QuasiStaticFit, OneStepFromTheDynamicStateRemovesMostOfTheLag) {
  // The pipeline's use: the state after implicit Euler steps towards the targets,
  // then one Newton step of the fit (factor 6, the default) from it.
  PulledBar bar(50.0, 3.0);
  ImplicitEulerOptions io;
  io.rayleigh_stiffness_beta = 0.01;
  ImplicitEulerIntegrator integrator(io);
  CorotationalElasticity elastic;
  for (int i = 0; i < 3; ++i) integrator.Step(&bar.state, &elastic, {&bar.springs});
  QuasiStaticFit one_step{QuasiStaticFitOptions{}};
  ASSERT_EQ(one_step.Fit(bar.state, bar.springs).status, StepStatus::kConverged);
  QuasiStaticFit converged(ConvergedFit(6.0));
  converged.Fit(bar.state, bar.springs);
  const double dynamic = MeanSpringLength(bar, bar.state.positions());
  const double fitted = MeanSpringLength(bar, one_step.positions());
  const double exact = MeanSpringLength(bar, converged.positions());
  EXPECT_LT(fitted, 0.5 * dynamic);
  EXPECT_LT(std::abs(fitted - exact), 0.1 * (dynamic - exact));
}

TEST(QuasiStaticFit, KeepsFixedVerticesAndPiecesWithoutSprings) {
  // Two bars side by side (no shared vertex); springs on the first only, gravity on
  // both. Without springs the second has no equilibrium: it keeps its positions.
  TetMesh a = SmallBox({2, 1, 1}, {20, 10, 10});
  TetMesh mesh = a;
  mesh.vertices.conservativeResize(2 * a.num_vertices(), 3);
  mesh.vertices.bottomRows(a.num_vertices()) = a.vertices.rowwise() + Eigen::RowVector3d(0, 30, 0);
  mesh.tetrahedra.conservativeResize(2 * a.num_tetrahedra(), 4);
  mesh.tetrahedra.bottomRows(a.num_tetrahedra()) = a.tetrahedra.array() + a.num_vertices();
  MechanicalState state(mesh, Material{5000, 0.3, 1000});
  state.SetFixed(0, true);
  SpringEnergy springs;
  RowMatX3d anchor(1, 3);
  anchor << 19, 5, 5;
  const EmbeddedPoints e =
      EmbeddedPoints::Embed(anchor, state.rest_positions(), state.tetrahedra());
  springs.Add(e[0], Eigen::Vector3d(21, 5, 5), 50.0);
  GravityEnergy gravity(Eigen::Vector3d(0, 0, -9810));
  QuasiStaticFit fit{QuasiStaticFitOptions{}};
  ASSERT_EQ(fit.Fit(state, springs, {&gravity}).status, StepStatus::kConverged);
  const int n = a.num_vertices();
  EXPECT_EQ(fit.positions().row(0), state.positions().row(0));
  EXPECT_EQ(fit.positions().bottomRows(n), state.positions().bottomRows(n));
  EXPECT_GT((fit.positions().topRows(n) - state.positions().topRows(n)).norm(), 0.1);
  EXPECT_TRUE(fit.positions().allFinite());
}

TEST(QuasiStaticFit, FollowsAChangeOfMesh) {
  // The same fit object on a second, larger mesh: its pattern and pieces are rebuilt.
  PulledBar small(50.0, 2.0);
  QuasiStaticFit fit(ConvergedFit(4.0));
  fit.Fit(small.state, small.springs);
  EXPECT_EQ(fit.positions().rows(), small.state.num_vertices());

  MechanicalState big(SmallBox({6, 3, 3}, {60, 20, 20}), Material{5000, 0.3, 1000});
  for (int v = 0; v < big.num_vertices(); ++v)
    if (big.rest_position(v).x() == 0.0) big.SetFixed(v, true);
  SpringEnergy springs;
  RowMatX3d anchor(1, 3);
  anchor << 58, 10, 10;
  const EmbeddedPoints e = EmbeddedPoints::Embed(anchor, big.rest_positions(), big.tetrahedra());
  springs.Add(e[0], Eigen::Vector3d(60, 10, 10), 50.0);
  ASSERT_NE(fit.Fit(big, springs).status, StepStatus::kLinearSolveFailed);
  ASSERT_EQ(fit.positions().rows(), big.num_vertices());
  const Eigen::Vector3d p = springs.AnchorPosition(0, big, fit.positions());
  EXPECT_GT(p.x(), 58.5);
  EXPECT_LT(p.x(), 60.0);
}

TEST(QuasiStaticFit, RejectsBadOptions) {
  QuasiStaticFitOptions o;
  o.spring_factor = 0;
  EXPECT_THROW(QuasiStaticFit{o}, Error);
  o = QuasiStaticFitOptions();
  o.regularisation_time_s = -1;
  EXPECT_THROW(QuasiStaticFit{o}, Error);
  o = QuasiStaticFitOptions();
  o.newton_iterations = 0;
  EXPECT_THROW(QuasiStaticFit{o}, Error);
}

}  // namespace
}  // namespace arreg::mechanics
