#include "cutting/mechanics_update.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <random>

#include "core/mesh_generators.h"
#include "cutting/tet_cutter.h"

namespace arreg::cutting {
namespace {

// The mechanical state has the cut mesh's elements and rest and current positions.
void ExpectStateMatchesMesh(const mechanics::MechanicalState& state, const CuttableMesh& mesh) {
  ASSERT_EQ(state.num_vertices(), mesh.num_vertices());
  ASSERT_EQ(state.num_tetrahedra(), mesh.num_tetrahedra());
  for (int t = 0; t < mesh.num_tetrahedra(); ++t)
    for (int k = 0; k < 4; ++k) ASSERT_EQ(state.tetrahedra()(t, k), mesh.tetrahedra()[t][k]);
  for (int v = 0; v < mesh.num_vertices(); ++v) {
    ASSERT_LT((state.rest_position(v) - mesh.rest_positions()[v]).norm(), 1e-12);
    ASSERT_LT((state.position(v) - mesh.positions()[v]).norm(), 1e-12);
  }
}

// The mechanical state follows a sequence of cuts exactly (vertices, elements,
// rest data recomputed), and embedded points stay where they were.
TEST(MechanicsUpdate, StateFollowsSuccessiveCuts) {
  const TetMesh box =
      MakeBoxTetMesh(Eigen::Vector3d(30, 20, 10), Eigen::Vector3i(3, 2, 2), BoxTetSplit::kSix);
  mechanics::MechanicalState state(box, mechanics::Material());
  CuttableMesh mesh(box);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1, 1);
  RowMatX3d points(200, 3);
  for (int i = 0; i < points.rows(); ++i)
    points.row(i) << 15 + 14 * u(rng), 10 + 9 * u(rng), 5 + 4.5 * u(rng);
  mechanics::EmbeddedPoints embedded =
      mechanics::EmbeddedPoints::Embed(points, state.rest_positions(), state.tetrahedra());
  CutOptions opt;
  opt.snap_epsilon = 0;  // rest positions of the state cannot move
  // The bookkeeping is under test, not the elements' shape: random planes crossing earlier
  // cuts in this coarse box leave slivers that min_element_quality would refuse.
  opt.min_element_quality = 0;
  for (int c = 0; c < 6; ++c) {
    const Eigen::Vector3d n = Eigen::Vector3d(u(rng), u(rng), u(rng)).normalized();
    const Eigen::Vector3d p(15 + 10 * u(rng), 10 + 6 * u(rng), 5 + 3 * u(rng));
    CutChange change;
    const CutSummary s = mesh.Cut(MakePlaneSurface(p, n, 100, 100, {1, 0, 0}), opt, &change);
    ASSERT_NE(s.status, CutStatus::kRejected);
    if (s.status != CutStatus::kCut) continue;
    const std::vector<int> added = ApplyCutChange(change, &state);
    ASSERT_EQ(static_cast<int>(added.size()), change.new_tetrahedra.rows());
    ReembedAfterCut(change, added, state, points, &embedded);
    ASSERT_NO_FATAL_FAILURE(ExpectStateMatchesMesh(state, mesh));
    const RowMatX3d moved = embedded.Positions(state.rest_positions(), state.tetrahedra());
    EXPECT_LT((moved - points).cwiseAbs().maxCoeff(), 1e-9) << "cut " << c;
  }
}

// Cuts that snap vertices onto S: the state follows the cutter (snapped rest and
// current positions), the elements around snapped vertices get fresh rest data
// (equal to a state built from scratch), the volume is kept, and a deformed
// state cut and snapped with the same weights in both configurations stays
// consistent with the cutter's current positions.
TEST(MechanicsUpdate, StateFollowsCutsWithSnappedVertices) {
  const TetMesh box =
      MakeBoxTetMesh(Eigen::Vector3d(30, 20, 10), Eigen::Vector3i(3, 2, 2), BoxTetSplit::kSix);
  mechanics::MechanicalState state(box, mechanics::Material());
  const double volume_before = [&] {
    double v = 0;
    for (const auto& r : state.rest_data()) v += r.volume_mm3;
    return v;
  }();
  CuttableMesh mesh(box);
  CutOptions opt;
  opt.snap_epsilon = 0.3;
  int snapped = 0;
  const std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> planes = {
      {{10.2, 10, 5}, {1, 0, 0}}, {{15, 9.8, 5}, {0, 1, 0}}, {{20.25, 10, 5}, {1, 0, 0.05}}};
  for (const auto& [p, n] : planes) {
    CutChange change;
    const CutSummary s =
        mesh.Cut(MakePlaneSurface(p, n.normalized(), 100, 100, {0, 0, 1}), opt, &change);
    ASSERT_NE(s.status, CutStatus::kRejected) << s.message;
    if (s.status != CutStatus::kCut) continue;
    snapped += static_cast<int>(change.snapped.size());
    const std::vector<int> added = ApplyCutChange(change, &state);
    ASSERT_EQ(static_cast<int>(added.size()), change.new_tetrahedra.rows());
    ASSERT_NO_FATAL_FAILURE(ExpectStateMatchesMesh(state, mesh));
    const mechanics::MechanicalState fresh(state.RestMesh(), mechanics::Material());
    double volume = 0;
    for (int t = 0; t < state.num_tetrahedra(); ++t) {
      volume += state.rest_data(t).volume_mm3;
      ASSERT_NEAR(state.rest_data(t).volume_mm3, fresh.rest_data(t).volume_mm3, 1e-9)
          << "element " << t;
      ASSERT_LT((state.rest_data(t).shape_gradients - fresh.rest_data(t).shape_gradients)
                    .cwiseAbs()
                    .maxCoeff(),
                1e-9)
          << "element " << t;
    }
    EXPECT_NEAR(volume, volume_before, 1e-9 * volume_before);
  }
  EXPECT_GT(snapped, 0) << "the planes were chosen to snap vertices";
}

// Thesis eq. 7.12: a triangle of an internal structure with an edge across S is deleted.
TEST(MechanicsUpdate, TrianglesCrossingTheSurfaceAreDeleted) {
  RowMatX3d v(5, 3);
  v << 0, 0, 0, 2, 0, 0, 0, 2, 0, 5, 0, 0, 5, 2, 0;
  RowMatX3i f(3, 3);
  f << 0, 1, 2, 1, 3, 4, 0, 1, 4;
  const CutSurface s = MakePlaneSurface({3, 0, 0}, {1, 0, 0}, 10, 10, {0, 1, 0});
  const RowMatX3i kept = RemoveTrianglesCrossing(v, f, s);
  ASSERT_EQ(kept.rows(), 1);
  EXPECT_EQ(kept.row(0), f.row(0));
}

}  // namespace
}  // namespace arreg::cutting
