// MechanicalState changes made by cutting: new vertices, replaced elements,
// rest data recomputed only locally, solver state rebuilt.
#include <gtest/gtest.h>

#include <cmath>

#include "core/error.h"
#include "mechanics/integrator.h"
#include "mechanics/units.h"
#include "mechanics_test_util.h"

namespace arreg::mechanics {
namespace {

using testing::SmallBox;

// Splits tetrahedron t at its centroid (1-4 split) and returns the new vertex.
int SplitAtCentroid(MechanicalState* state, int t, std::vector<int>* new_ids) {
  const Eigen::Vector4i tet = state->tetrahedra().row(t).transpose();
  RowMatX3d rest(1, 3), cur(1, 3), vel(1, 3);
  rest.setZero();
  cur.setZero();
  vel.setZero();
  for (int a = 0; a < 4; ++a) {
    rest += 0.25 * state->rest_positions().row(tet[a]);
    cur += 0.25 * state->positions().row(tet[a]);
    vel += 0.25 * state->velocities().row(tet[a]);
  }
  const int p = state->AddVertices(rest, cur, vel)[0];
  RowMatX4i sub(4, 4);
  // Replacing vertex a by p keeps the orientation.
  for (int a = 0; a < 4; ++a) {
    sub.row(a) = tet.transpose();
    sub(a, a) = p;
  }
  *new_ids = state->ReplaceTetrahedra({t}, sub, {state->material(t)});
  return p;
}

TEST(MechanicalState, SplitKeepsVolumeMassAndUntouchedRestData) {
  MechanicalState state(SmallBox(), Material{3000, 0.45, 1000});
  const double volume_before = [&] {
    double v = 0;
    for (int t = 0; t < state.num_tetrahedra(); ++t) v += state.rest_data(t).volume_mm3;
    return v;
  }();
  const double mass_before = state.TotalMassKg();
  const TetRestData untouched = state.rest_data(7);
  const auto version = state.topology_version();
  std::vector<int> ids;
  const int p = SplitAtCentroid(&state, 4, &ids);
  EXPECT_EQ(p, state.num_vertices() - 1);
  ASSERT_EQ(ids.size(), 4u);
  EXPECT_EQ(ids[0], 4);  // the freed slot is reused first
  EXPECT_EQ(state.num_tetrahedra(), 3 * 2 * 2 * 6 + 3);
  double volume_after = 0;
  for (int t = 0; t < state.num_tetrahedra(); ++t) volume_after += state.rest_data(t).volume_mm3;
  EXPECT_NEAR(volume_after, volume_before, 1e-9 * volume_before);
  EXPECT_NEAR(state.TotalMassKg(), mass_before, 1e-12);
  EXPECT_EQ(state.rest_data(7).shape_gradients, untouched.shape_gradients);
  EXPECT_GT(state.topology_version(), version);
}

TEST(MechanicalState, RemovalCompactsAndReportsMovedElements) {
  MechanicalState state(SmallBox({2, 1, 1}), Material{});
  const RowMatX4i before = state.tetrahedra();  // 12 elements
  std::vector<std::pair<int, int>> moved;
  state.ReplaceTetrahedra({1, 11, 5}, RowMatX4i(0, 4), {}, &moved);
  EXPECT_EQ(state.num_tetrahedra(), 9);
  // 11 was last and is simply dropped; 10 and 9 fill holes 1 and 5.
  ASSERT_EQ(moved.size(), 2u);
  for (const auto& [from, to] : moved) EXPECT_EQ(state.tetrahedra().row(to), before.row(from));
}

TEST(MechanicalState, InvalidReplacementThrowsAndLeavesTheStateUnchanged) {
  MechanicalState state(SmallBox({1, 1, 1}), Material{});
  const RowMatX4i before = state.tetrahedra();
  RowMatX4i inverted(1, 4);
  inverted << before(0, 1), before(0, 0), before(0, 2), before(0, 3);
  EXPECT_THROW(state.ReplaceTetrahedra({0}, inverted, {Material{}}), Error);
  EXPECT_THROW(state.ReplaceTetrahedra({0, 0}, RowMatX4i(0, 4), {}), Error);
  EXPECT_THROW(state.ReplaceTetrahedra({99}, RowMatX4i(0, 4), {}), Error);
  EXPECT_EQ(state.tetrahedra(), before);
}

TEST(MechanicalState, SetRestPositionsRecomputesOnlyIncidentElements) {
  const TetMesh box = SmallBox();
  MechanicalState state(box, Material{3000, 0.45, 1000});
  int interior = -1;  // the vertex at (10, 10, 10)
  for (int v = 0; v < state.num_vertices(); ++v)
    if ((state.rest_position(v) - Eigen::Vector3d(10, 10, 10)).norm() < 1e-12) interior = v;
  ASSERT_GE(interior, 0);
  const std::vector<TetRestData> before = state.rest_data();
  const double mass_before = state.TotalMassKg();
  const auto version = state.topology_version();
  RowMatX3d moved(1, 3);
  moved << 11.5, 9.0, 10.7;
  state.SetRestPositions({interior}, moved);
  EXPECT_GT(state.topology_version(), version);
  EXPECT_EQ(state.rest_position(interior), Eigen::Vector3d(11.5, 9.0, 10.7));
  // Moving an interior vertex inside its star keeps the total volume and mass.
  EXPECT_NEAR(state.TotalMassKg(), mass_before, 1e-12 * mass_before);
  // Every element equals a state built from scratch on the moved mesh; only the
  // incident ones changed.
  TetMesh moved_mesh = box;
  moved_mesh.vertices.row(interior) = moved.row(0);
  const MechanicalState fresh(moved_mesh, Material{3000, 0.45, 1000});
  int changed = 0;
  for (int t = 0; t < state.num_tetrahedra(); ++t) {
    const bool incident = (state.tetrahedra().row(t).array() == interior).any();
    EXPECT_NEAR(state.rest_data(t).volume_mm3, fresh.rest_data(t).volume_mm3, 1e-9);
    EXPECT_LT((state.rest_data(t).shape_gradients - fresh.rest_data(t).shape_gradients)
                  .cwiseAbs()
                  .maxCoeff(),
              1e-12);
    if (!incident) {
      EXPECT_EQ(state.rest_data(t).volume_mm3, before[t].volume_mm3);
    } else if (std::abs(state.rest_data(t).volume_mm3 - before[t].volume_mm3) > 1e-9) {
      ++changed;
    }
  }
  EXPECT_GT(changed, 0);
}

TEST(MechanicalState, SetRestPositionsThatInvertAnElementThrowsAndLeavesTheStateUnchanged) {
  MechanicalState state(SmallBox(), Material{});
  int interior = -1;
  for (int v = 0; v < state.num_vertices(); ++v)
    if ((state.rest_position(v) - Eigen::Vector3d(10, 10, 10)).norm() < 1e-12) interior = v;
  ASSERT_GE(interior, 0);
  const RowMatX3d rest_before = state.rest_positions();
  const std::vector<TetRestData> data_before = state.rest_data();
  const auto version = state.topology_version();
  RowMatX3d far(1, 3);
  far << 25.0, 10.0, 10.0;  // beyond the neighbour at (20, 10, 10): inverts elements
  EXPECT_THROW(state.SetRestPositions({interior}, far), Error);
  EXPECT_THROW(state.SetRestPositions({interior, interior}, RowMatX3d::Zero(2, 3)), Error);
  EXPECT_THROW(state.SetRestPositions({-1}, RowMatX3d::Zero(1, 3)), Error);
  EXPECT_THROW(state.SetRestPositions({interior}, RowMatX3d::Zero(2, 3)), Error);
  EXPECT_EQ(state.rest_positions(), rest_before);
  EXPECT_EQ(state.topology_version(), version);
  for (int t = 0; t < state.num_tetrahedra(); ++t)
    EXPECT_EQ(state.rest_data(t).volume_mm3, data_before[t].volume_mm3);
}

TEST(MechanicalState, PatchTestStillHoldsAfterASplitWithStateCarriedOver) {
  MechanicalState state(SmallBox({3, 3, 3}, {30, 30, 30}), Material{3000, 0.3, 1000});
  CorotationalElasticity elastic;
  StaticSolver solver{StaticSolverOptions{}};
  auto on_boundary = [&](int v) {
    const Eigen::Vector3d x = state.rest_position(v);
    return (x.array() == 0.0).any() || (x.array() == 30.0).any();
  };
  for (int v = 0; v < state.num_vertices(); ++v)
    if (on_boundary(v)) state.SetFixed(v, true);
  // A first solve builds the solver's pattern and factorisation for the original mesh.
  ASSERT_EQ(solver.Solve(&state, &elastic, {}).status, StepStatus::kConverged);
  std::vector<int> ids;
  // A tetrahedron of the central cell (13) so that the new vertex is interior.
  const int p = SplitAtCentroid(&state, 13 * 6 + 2, &ids);
  Eigen::Matrix3d A;
  A << 1.05, 0.1, 0.0, 0.0, 0.97, 0.05, 0.02, 0.0, 1.1;
  const Eigen::RowVector3d b(1, 2, 3);
  auto affine = [&](int v) -> Eigen::RowVector3d {
    return state.rest_positions().row(v) * A.transpose() + b;
  };
  for (int v = 0; v < state.num_vertices(); ++v)
    if (state.is_fixed(v)) state.mutable_positions().row(v) = affine(v);
  ASSERT_FALSE(state.is_fixed(p));
  const StepSummary summary = solver.Solve(&state, &elastic, {});
  ASSERT_EQ(summary.status, StepStatus::kConverged) << summary.message;
  for (int v = 0; v < state.num_vertices(); ++v)
    EXPECT_LT((state.positions().row(v) - affine(v)).norm(), 1e-8) << v;
}

}  // namespace
}  // namespace arreg::mechanics
