// Cantilever convergence towards Euler-Bernoulli under mesh refinement (slow:
// the finest mesh has 30,720 tetrahedra).
#include <gtest/gtest.h>

#include <cstdio>

#include "core/mesh_generators.h"
#include "mechanics/integrator.h"
#include "mechanics/spring_energy.h"

namespace arreg::mechanics {
namespace {

// Tip deflection of a clamped 100 x 10 x 10 mm beam (nu = 0) under a small
// end load, against Euler-Bernoulli P L^3 / (3 E I).
double CantileverTipDeflection(int cells_across, double* reference) {
  const double length = 100, side = 10, youngs_pa = 1e6, load_mn = 1.0;
  const int nx = 10 * cells_across;
  MechanicalState state(MakeBoxTetMesh({length, side, side}, {nx, cells_across, cells_across}),
                        Material{youngs_pa, 0.0, 1000});
  PointForceEnergy load;
  std::vector<int> tip;
  for (int v = 0; v < state.num_vertices(); ++v) {
    const Eigen::Vector3d x = state.rest_position(v);
    if (x.x() == 0.0) state.SetFixed(v, true);
    if (x.x() == length) tip.push_back(v);
  }
  // Consistent nodal loads of a uniform shear traction on the bilinear grid of
  // the end face: weight 1 inside, 1/2 on edges, 1/4 at corners.
  double total_weight = 0;
  std::vector<double> weight(tip.size());
  for (size_t i = 0; i < tip.size(); ++i) {
    const Eigen::Vector3d x = state.rest_position(tip[i]);
    weight[i] =
        ((x.y() == 0 || x.y() == side) ? 0.5 : 1.0) * ((x.z() == 0 || x.z() == side) ? 0.5 : 1.0);
    total_weight += weight[i];
  }
  for (size_t i = 0; i < tip.size(); ++i)
    load.AddForce(tip[i], Eigen::Vector3d(0, 0, -load_mn * weight[i] / total_weight));
  CorotationalElasticity elastic;
  StaticSolverOptions options;
  options.tolerance_mm = 1e-10;
  StaticSolver solver(options);
  const StepSummary summary = solver.Solve(&state, &elastic, {&load});
  EXPECT_EQ(summary.status, StepStatus::kConverged);
  double deflection = 0;
  for (int v : tip) deflection += state.rest_position(v).z() - state.position(v).z();
  const double e_kpa = youngs_pa * 1e-3, inertia = side * side * side * side / 12.0;
  *reference = load_mn * length * length * length / (3 * e_kpa * inertia);
  return deflection / tip.size();
}

TEST(Cantilever, TipDeflectionConvergesToEulerBernoulli) {
  double previous_error = 1.0, reference = 0;
  std::printf("cantilever 100x10x10 mm, E = 1 MPa, nu = 0, tip load 1 mN (Kuhn 6-tet split)\n");
  std::printf("%10s %8s %8s %14s %14s %10s\n", "cells", "tets", "dofs", "tip_mm", "euler_mm",
              "ratio");
  for (int n : {1, 2, 4, 6, 8}) {
    const double tip = CantileverTipDeflection(n, &reference);
    const double error = std::abs(tip - reference) / reference;
    std::printf("%4dx%2dx%2d %8d %8d %14.6e %14.6e %10.4f\n", 10 * n, n, n, 60 * n * n * n,
                3 * (10 * n + 1) * (n + 1) * (n + 1), tip, reference, tip / reference);
    EXPECT_LT(tip, reference * 1.02);  // linear tetrahedra are too stiff, never too soft
    EXPECT_LT(error, previous_error);  // monotone convergence
    previous_error = error;
  }
  EXPECT_LT(previous_error, 0.05);
}

}  // namespace
}  // namespace arreg::mechanics
