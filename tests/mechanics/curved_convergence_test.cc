// What curved elements gain in mechanics: a thick hollow sphere against Lame's solution,
// straight against curved Bernstein tetrahedra (label slow, about 6 s CPU).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "curved_test_util.h"
#include "mechanics/bernstein_tet.h"
#include "mechanics/curved_boundary.h"
#include "mechanics/generalised_solver.h"

namespace arreg::mechanics {
namespace {

using testing::kRadius;

// Radii 5 and 10 mm, E = 3 kPa, nu = 0.3 (compressible, so that volumetric locking does
// not mix into the geometric error), the inner surface pushed out radially by 0.01 mm,
// the outer surface free: u_r = A r + B / r^2 with sigma_rr(10) = 0. The inner surface's
// control points interpolate X + u(X) at their lattice points; the error is the largest
// displacement error over the outer surface's tessellation (n = 4). Straight elements
// sit on a faceted sphere and converge at order 2 once the geometry dominates; elements
// raised onto both spheres keep converging faster.
TEST(CurvedConvergence, ThickSphereIsMoreAccurateWithCurvedElements) {
  const double inner = 5.0, push = 0.01, middle = 0.5 * (inner + kRadius);
  Material material;
  material.poisson_ratio = 0.3;
  const double lambda = material.LameLambdaKpa(), mu = material.LameMuKpa();
  const double ratio = (3 * lambda + 2 * mu) * std::pow(kRadius, 3) / (4 * mu);  // B / A
  const double a = push / (inner + ratio / (inner * inner));
  const auto exact = [&](const Eigen::Vector3d& x) -> Eigen::Vector3d {
    const double r = x.norm();
    return (a + a * ratio / (r * r * r)) * x;
  };
  SurfaceRaiseOptions raise;
  raise.project = [&](const Eigen::Vector3d& x) -> Eigen::Vector3d {
    return (x.norm() < middle ? inner : kRadius) * x.normalized();
  };
  std::printf("degree geometry level  tets  max outer error (mm)  rate\n");
  double error[4][2][3] = {};
  for (int k = 2; k <= 3; ++k) {
    const int levels = k == 2 ? 3 : 2;
    for (int curved = 0; curved <= 1; ++curved) {
      for (int level = 0; level < levels; ++level) {
        const TetMesh linear = testing::LinearBall(level, inner);
        const HighOrderTetMesh mesh =
            curved ? RaiseTetMeshOntoSurface(linear, k, raise) : RaiseTetMesh(linear, k);
        GeneralisedState state;
        const std::vector<int> node = AddHighOrderNodes(mesh, &state);
        BernsteinTetOptions options;
        options.material = material;
        BernsteinTetTerm term(&mesh, node, options);
        const RowMatX3d target = InterpolateMap(
            mesh, mesh.nodes,
            [&](const Eigen::Vector3d& x) -> Eigen::Vector3d { return x + exact(x); });
        const auto indices = BernsteinIndices(k);
        for (const HighOrderBoundaryFace& f : HighOrderBoundaryFaces(mesh)) {
          if (mesh.nodes.row(mesh.elements(f.element, (f.opposite + 1) % 4)).norm() > middle)
            continue;  // an outer face
          for (size_t i = 0; i < indices.size(); ++i)
            if (indices[i][f.opposite] == 0) {
              const int n = mesh.elements(f.element, static_cast<int>(i));
              state.SetFixedTranslation(node[n], true);
              state.mutable_positions().row(node[n]) = target.row(n);
            }
        }
        GeneralisedStaticSolver solver({});
        ASSERT_EQ(solver.Solve(&state, {&term}).status, StepStatus::kConverged);
        RowMatX3d deformed(mesh.num_nodes(), 3);
        for (int n = 0; n < mesh.num_nodes(); ++n) deformed.row(n) = state.positions().row(node[n]);
        const CurvedBoundary rest = TessellateBoundary(mesh, mesh.nodes, 4);
        const RowMatX3d moved = rest.vertices.Positions(deformed);
        double e = 0;
        for (int v = 0; v < rest.surface.num_vertices(); ++v) {
          const Eigen::Vector3d x = rest.surface.vertices.row(v).transpose();
          if (x.norm() > middle) e = std::max(e, (moved.row(v).transpose() - x - exact(x)).norm());
        }
        error[k][curved][level] = e;
        std::printf("%6d %8s %5d %5d  %20.3e  %4.2f\n", k, curved ? "curved" : "straight", level,
                    mesh.num_elements(), e,
                    level > 0 ? std::log2(error[k][curved][level - 1] / e) : 0.0);
      }
    }
    const int finest = levels - 1;
    EXPECT_LT(error[k][1][finest], 0.5 * error[k][0][finest]) << "degree " << k;
  }
  // Under the concave inner sphere the relaxation is what keeps the coarse raise valid
  // (at level 1 the elements are small enough against the curvature either way).
  for (int level = 0; level <= 1; ++level) {
    SurfaceRaiseSummary with, without;
    RaiseTetMeshOntoSurface(testing::LinearBall(level, inner), 2, raise, &with);
    SurfaceRaiseOptions no_relaxation = raise;
    no_relaxation.relax_interior = false;
    RaiseTetMeshOntoSurface(testing::LinearBall(level, inner), 2, no_relaxation, &without);
    std::printf("level %d: inverted without / with relaxation %d / %d\n", level,
                without.num_inverted, with.num_inverted);
    if (level == 0) {
      EXPECT_GT(without.num_inverted, 0);
    }
    EXPECT_EQ(with.num_inverted + with.num_undecided, 0);
  }
  // P2: the straight error's rate falls towards 2 (geometry), the curved one stays higher.
  EXPECT_LT(std::log2(error[2][0][1] / error[2][0][2]), 2.5);
  EXPECT_GT(std::log2(error[2][1][1] / error[2][1][2]), 2.5);
}

}  // namespace
}  // namespace arreg::mechanics
