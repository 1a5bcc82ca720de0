#include "cutting/quadratic_cutter.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include <cmath>
#include <functional>
#include <random>

#include "core/error.h"
#include "core/mesh_generators.h"
#include "cutting/mesh_checks.h"
#include "cutting/random_cuts.h"
#include "mechanics/curved_tet.h"

namespace arreg::cutting {
namespace {

using mechanics::HighOrderTetMesh;
using Vec3 = Eigen::Vector3d;

// A straight degree-2 beam 60 x 20 x 16 mm of 6 x 2 x 2 cells.
HighOrderTetMesh StraightBeam() {
  return mechanics::RaiseTetMesh(MakeBoxTetMesh(Vec3(60, 20, 16), Eigen::Vector3i(6, 2, 2)), 2);
}

// The beam with its faces bulged outwards by up to 1.5 mm (zero on the box's edges): curved rest
// elements on the boundary, interior control points relaxed.
HighOrderTetMesh CurvedBeam() {
  const Vec3 size(60, 20, 16);
  const TetMesh box = MakeBoxTetMesh(size, Eigen::Vector3i(6, 2, 2));
  HighOrderTetMesh beam = mechanics::RaiseTetMesh(box, 2);
  beam.nodes = BulgedBoxQuadraticNodes(box, size, 1.5);
  return beam;
}

double RestVolume(const HighOrderTetMesh& mesh) { return CheckQuadraticMesh(mesh).volume; }

// Every element's map at a few barycentric points.
std::vector<Eigen::Vector4d> SamplePoints() {
  return {Eigen::Vector4d(0.25, 0.25, 0.25, 0.25), Eigen::Vector4d(0.7, 0.1, 0.1, 0.1),
          Eigen::Vector4d(0.1, 0.6, 0.2, 0.1), Eigen::Vector4d(0.5, 0.5, 0, 0),
          Eigen::Vector4d(0, 0.3, 0.3, 0.4)};
}

// Largest |x_current(L) - f(x_rest(L))| over the elements and SamplePoints (mm).
double FieldError(const HighOrderTetMesh& rest, const RowMatX3d& current,
                  const std::function<Vec3(const Vec3&)>& f) {
  double worst = 0;
  for (int e = 0; e < rest.num_elements(); ++e) {
    const Eigen::MatrixX3d r = mechanics::ElementControlPoints(rest, rest.nodes, e);
    const Eigen::MatrixX3d c = mechanics::ElementControlPoints(rest, current, e);
    for (const Eigen::Vector4d& l : SamplePoints())
      worst = std::max(
          worst,
          (mechanics::BezierTetPoint(2, c, l) - f(mechanics::BezierTetPoint(2, r, l))).norm());
  }
  return worst;
}

// A quadratic deformation (bend, twist and stretch) and a quadratic velocity field.
Vec3 Bend(const Vec3& p) {
  return Vec3(p.x() + 0.002 * p.x() * p.y(), p.y() + 0.004 * p.x() * p.x() - 0.01 * p.z(),
              p.z() + 0.003 * p.x() * p.z() + 0.001 * p.y() * p.y());
}
Vec3 Flow(const Vec3& p) {
  return Vec3(0.1 * p.y() * p.z(), 1 - 0.02 * p.x() * p.x(), 0.3 * p.x());
}

CutSurface Plane(const Vec3& point, const Vec3& normal, double half) {
  return MakePlaneSurface(point, normal, half, half, normal.unitOrthogonal(), 8);
}

void ExpectValid(const QuadraticCuttableMesh& cut, double volume) {
  const MeshInvariants linear = CheckMeshInvariants(cut.skeleton().RestMesh());
  EXPECT_TRUE(linear.ok()) << linear.ToString();
  const HighOrderTetMesh rest = cut.RestMesh();
  const QuadraticMeshInvariants q = CheckQuadraticMesh(rest);
  EXPECT_TRUE(q.ok()) << q.num_edge_mismatches << " edge mismatches, " << q.num_shared_edge_nodes
                      << " shared edge nodes, " << q.num_nonpositive_jacobians
                      << " non-positive Jacobians";
  EXPECT_NEAR(q.volume, volume, 1e-9 * volume);
}

TEST(QuadraticCutter, RestMeshIsTheInputUntilACut) {
  const HighOrderTetMesh beam = CurvedBeam();
  QuadraticCuttableMesh cut(beam);
  EXPECT_TRUE(cut.curved());
  EXPECT_FALSE(QuadraticCuttableMesh(StraightBeam()).curved());
  const HighOrderTetMesh back = cut.RestMesh();
  EXPECT_EQ(back.elements, beam.elements);
  EXPECT_EQ(back.nodes, beam.nodes);
  // A plane beside the body changes nothing.
  const CutSummary s = cut.Cut(Plane(Vec3(0, 0, 40), Vec3(0, 0, 1), 100), CutOptions());
  EXPECT_EQ(s.status, CutStatus::kNoCrossing);
  EXPECT_EQ(cut.RestMesh().nodes, beam.nodes);
}

TEST(QuadraticCutter, RefusesOtherDegrees) {
  const HighOrderTetMesh cubic =
      mechanics::RaiseTetMesh(MakeBoxTetMesh(Vec3(1, 1, 1), {1, 1, 1}), 3);
  EXPECT_THROW(QuadraticCuttableMesh{cubic}, Error);
}

// A plane through the straight beam: the corner mesh is cut as the linear remesher cuts it, the
// edge control points stay shared and straight, the volume is kept and the body falls in two.
TEST(QuadraticCutter, PlaneSeparatesAStraightBeam) {
  const HighOrderTetMesh beam = StraightBeam();
  const double volume = RestVolume(beam);
  QuadraticCuttableMesh cut(beam);
  QuadraticCutChange change;
  const CutSummary s =
      cut.Cut(Plane(Vec3(31.3, 10, 8), Vec3(1, 0.2, 0.1).normalized(), 60), CutOptions(), &change);
  ASSERT_EQ(s.status, CutStatus::kCut) << s.message;
  EXPECT_GT(s.num_crossed_tetrahedra, 0);
  EXPECT_GT(change.num_new_edge_nodes, 0);
  EXPECT_GT(change.corners.duplicated.size(), 0u);
  ExpectValid(cut, volume);
  EXPECT_FALSE(QuadraticCuttableMesh(cut.RestMesh()).curved());
  // Old control points kept by the event keep their position under their new index, but for
  // the corners snapped onto S.
  const HighOrderTetMesh after = cut.RestMesh();
  std::vector<bool> snapped(beam.num_nodes(), false);
  for (const SnappedVertex& v : change.corners.snapped) snapped[v.index] = true;
  EXPECT_GT(change.corners.snapped.size(), 0u);
  for (size_t n = 0; n < change.node_from_old.size(); ++n)
    if (change.node_from_old[n] >= 0 && !snapped[n]) {
      EXPECT_EQ(after.nodes.row(change.node_from_old[n]), beam.nodes.row(n)) << n;
    }
  EXPECT_EQ(static_cast<int>(change.node_from_old.size()), beam.num_nodes());
  EXPECT_EQ(
      after.num_nodes(),
      beam.num_nodes() + change.num_new_edge_nodes - change.num_removed_edge_nodes +
          static_cast<int>(change.corners.new_vertices.size() + change.corners.duplicated.size()));
}

// On a straight mesh a quadratic deformation is one polynomial over the body, and every new
// element (split, flipped or snapped) reproduces it exactly, in positions and velocities.
TEST(QuadraticCutter, QuadraticDeformationIsReproducedByEveryNewElement) {
  const HighOrderTetMesh beam = StraightBeam();
  const RowMatX3d x = mechanics::InterpolateMap(beam, beam.nodes, Bend);
  const RowMatX3d v = mechanics::InterpolateMap(beam, beam.nodes, Flow);
  ASSERT_LT(FieldError(beam, x, Bend), 1e-9);
  QuadraticCuttableMesh cut(beam, x, v);
  const double volume = RestVolume(beam);
  CutOptions snapping;
  snapping.snap_epsilon = 0.3;
  // Planes in the deformed frame, a partial cut, a second cut through the first one's crack.
  const std::vector<std::pair<CutSurface, CutOptions>> events = {
      {Plane(Bend(Vec3(20.7, 10, 8)), Vec3(1, 0.3, -0.2).normalized(), 60), CutOptions()},
      {Plane(Bend(Vec3(30, 9.3, 8)), Vec3(0.1, 1, 0.2).normalized(), 60), snapping},
      {Plane(Bend(Vec3(50, 10, 7.1)), Vec3(0.2, 0.1, 1).normalized(), 12), CutOptions()}};
  int made = 0, flips = 0, snaps = 0;
  for (const auto& [surface, options] : events) {
    const CutSummary s = cut.Cut(surface, options);
    flips += s.num_flipped_faces + s.num_removed_edges;
    snaps += s.num_snapped_vertices;
    EXPECT_EQ(s.status, CutStatus::kCut) << s.message;
    if (s.status != CutStatus::kCut) continue;
    ++made;
    ExpectValid(cut, volume);
    const HighOrderTetMesh rest = cut.RestMesh();
    EXPECT_LT(FieldError(rest, cut.Positions(), Bend), 1e-9);
    EXPECT_LT(FieldError(rest, cut.Velocities(), Flow), 1e-9);
  }
  EXPECT_EQ(made, 3);
  EXPECT_GT(flips, 0);
  EXPECT_GT(snaps, 0);
}

// A curved rest mesh is cut without flips or snapping: every new element lies in one old
// element and is its map restricted, so the rest volume (of the curved elements) is kept and no
// Jacobian turns non-positive.
TEST(QuadraticCutter, CurvedMeshKeepsItsVolumeAndJacobians) {
  const HighOrderTetMesh beam = CurvedBeam();
  const double volume = RestVolume(beam);
  ASSERT_GT(std::abs(volume - 60 * 20 * 16), 50.0);  // the bulge counts
  QuadraticCuttableMesh cut(beam);
  CutOptions flips;
  flips.snap_epsilon = 0.3;
  for (const CutSurface& surface : {Plane(Vec3(20.7, 10, 8), Vec3(1, 0.3, -0.2).normalized(), 60),
                                    Plane(Vec3(30, 9.3, 8), Vec3(0.1, 1, 0.2).normalized(), 60),
                                    Plane(Vec3(45, 10, 7.1), Vec3(0.2, 0.1, 1).normalized(), 60)}) {
    const CutSummary s = cut.Cut(surface, flips);
    ASSERT_EQ(s.status, CutStatus::kCut) << s.message;
    EXPECT_EQ(s.num_flipped_faces + s.num_removed_edges + s.num_snapped_vertices, 0);
    ExpectValid(cut, volume);
    EXPECT_TRUE(cut.curved());
  }
}

// Random cut sequences (planes, spheres, cylinders, bent sheets, partial cuts, cuts through
// crack fronts, grazing cuts) on the straight and the curved beam, checked after every cut (the
// 1,000-cut sweep of random_cuts_sweep_test runs the same checks on larger meshes).
TEST(QuadraticCutter, RandomCutSequencesKeepTheInvariants) {
  int cuts = 0, made = 0;
  for (int sequence = 0; sequence < 32; ++sequence) {
    const bool curved = sequence % 2 == 1;
    const HighOrderTetMesh beam = curved ? CurvedBeam() : StraightBeam();
    const RowMatX3d x = mechanics::InterpolateMap(beam, beam.nodes, Bend);
    QuadraticCuttableMesh cut(beam, curved ? beam.nodes : x, RowMatX3d::Zero(beam.num_nodes(), 3));
    const double volume = RestVolume(beam);
    RandomCutGenerator generator(1000 + sequence);
    for (int i = 0; i < 10 && cut.num_tetrahedra() < 2500; ++i) {
      const RandomCut rc = generator.Next(cut.skeleton());
      const CutSummary s = cut.Cut(rc.surface, rc.options);
      generator.Record(rc, s.status);
      ++cuts;
      if (s.status != CutStatus::kCut) continue;
      ++made;
      SCOPED_TRACE("sequence " + std::to_string(sequence) + " cut " + std::to_string(i) + " (" +
                   RandomCutKindName(rc.kind) + ")");
      ExpectValid(cut, volume);
      if (!curved) {
        EXPECT_LT(FieldError(cut.RestMesh(), cut.Positions(), Bend), 1e-8);
      }
      if (HasFailure()) return;
    }
  }
  EXPECT_GT(made, cuts / 3);
  std::printf("%d cuts drawn, %d made\n", cuts, made);
}

}  // namespace
}  // namespace arreg::cutting
